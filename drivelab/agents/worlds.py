"""The training env as K worlds (``Worlds``), the one loop of acting shared by drivelab's own
agents: a gymnasium env (K = 1) or an SB3 ``VecEnv`` of K worlds (``drivelab train --n-envs K``)
seen with the VecEnv's shapes, so that the agents' collect loops are written once.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
from gymnasium import spaces
from stable_baselines3.common.vec_env import VecEnv

from drivelab.errors import UsageError


def vector_env_of(env: Any):
    """The ``VectorDriveEnv`` under a training env: itself, a ``DriveEnv``'s (wrapped or not), or
    an SB3 VecEnv's (``SB3VecEnv`` under its wrappers)."""
    from drivelab.envs.vector import VectorDriveEnv

    if isinstance(env, VectorDriveEnv):
        return env
    base = env.unwrapped
    vector = getattr(base, "vector", None) or getattr(base, "vector_env", None)
    if not isinstance(vector, VectorDriveEnv):
        raise UsageError(
            "the rule-based expert and its learners need drivelab's own environment "
            "(DriveEnv, VectorDriveEnv)"
        )
    return vector


def map_obs(fn: Callable[..., Any], obs: Any, *others: Any) -> Any:
    """``fn(obs, *others)``, or for a dict observation ``fn`` of each value and the others' values
    of its key (the same keys)."""
    if isinstance(obs, dict):
        return {key: fn(value, *(other[key] for other in others)) for key, value in obs.items()}
    return fn(obs, *others)


def batch_of_one(obs: Any) -> Any:
    """One observation → a batch of one (dicts key by key)."""
    return map_obs(lambda value: np.asarray(value)[None], obs)


class Worlds:
    """The training env as K worlds: a gymnasium env (K = 1, reset here when its episode ends), an
    SB3 ``VecEnv`` (K = ``num_envs``) or a ``VectorDriveEnv`` with ``autoreset_mode="same_step"``.
    Observations come and go batched (K, ...); a finished world has started again when ``step``
    returns. A VectorDriveEnv, and a VecEnv whose whole wrapper chain has ``step_arrays``, are
    stepped as arrays: the info dicts per world are made only when ``infos`` is read."""

    def __init__(self, env) -> None:
        from gymnasium.vector import AutoresetMode

        from drivelab.envs.vector import VectorDriveEnv

        self.env = env
        self.direct = isinstance(env, VectorDriveEnv)
        if self.direct and env.autoreset_mode != AutoresetMode.SAME_STEP:
            raise UsageError("training on a VectorDriveEnv needs autoreset_mode='same_step'")
        self.vector = self.direct or isinstance(env, VecEnv)
        self.arrays = self.direct or _has_step_arrays(env)
        self.count = env.num_envs if self.vector else 1
        self._infos: list[dict] | dict = [{} for _ in range(self.count)]  # the last step's
        self.reset_infos: list[dict] = [{} for _ in range(self.count)]  # the latest reset's (see step)
        self._returns = np.zeros(self.count)  # a VectorDriveEnv's episodes so far (no monitor)

    @property
    def infos(self) -> list[dict]:
        """The last step's info of every world (of the step that ended it, for a finished world)."""
        if isinstance(self._infos, dict):
            self._infos = listed_infos(self._infos, self.count)
        return self._infos

    @property
    def batch(self):
        """The ``WorldBatch`` of the K worlds now (drivelab's own environment only)."""
        return vector_env_of(self.env).batch

    def start(self, last_obs: Any, space: spaces.Space) -> Any:
        """The batched observations (K, ...) a ``learn`` goes on from: the agent's ``last_obs``
        (batched here when a one-world version saved it as one observation), or a reset's when
        it has none."""
        if last_obs is None:
            return self.reset()
        return last_obs if is_batched(last_obs, space) else batch_of_one(last_obs)

    def reset(self) -> Any:
        """Start every world; the batched observations (K, ...)."""
        if self.direct:
            obs, infos = self.env.reset()
            self.reset_infos = listed_infos(infos, self.count)
            self._returns[:] = 0.0
            return obs
        if self.vector:
            obs = self.env.reset()
            self.reset_infos = list(getattr(self.env, "reset_infos", self.reset_infos))
            return obs
        obs, info = self.env.reset()
        self.reset_infos = [info]
        return batch_of_one(obs)

    def step(self, actions: np.ndarray):
        """(observations, rewards (K,), terminated (K,), truncated (K,), the final observations of
        the worlds that ended (batched, rows of the others unspecified) or None, the returns of
        the episodes that ended). ``infos`` then holds the step's info of every world; with one
        world, ``reset_infos`` the reset's when it started again."""
        if self.arrays:
            return self._step_arrays(actions)
        if self.vector:
            new_obs, rewards, dones, infos = self.env.step(actions)
            self._infos = infos
            truncated = np.array([bool(info.get("TimeLimit.truncated", False)) for info in infos])
            terminated = np.asarray(dones, dtype=bool) & ~truncated
            final = None
            if dones.any():
                final = map_obs(np.ndarray.copy, new_obs)
                for k in np.flatnonzero(dones):
                    _set_row(final, k, infos[k]["terminal_observation"])
            returns = [float(info["episode"]["r"]) for info in infos if "episode" in info]
            return new_obs, np.asarray(rewards, dtype=np.float64), terminated, truncated, final, returns
        new_obs, reward, terminated, truncated, info = self.env.step(actions[0])
        self._infos = [info]
        final = batch_of_one(new_obs)
        returns = [float(info["episode"]["r"])] if "episode" in info else []
        if terminated or truncated:
            new_obs, reset_info = self.env.reset()
            self.reset_infos = [reset_info]
        return (
            batch_of_one(new_obs), np.array([float(reward)]), np.array([terminated]), np.array([truncated]),
            final, returns,
        )  # fmt: skip

    def _step_arrays(self, actions: np.ndarray):
        """``step`` through ``step_arrays`` (or a VectorDriveEnv's own step); rewards rounded to
        float32 as SB3's VecEnvs give them, so that both ways of stepping train alike."""
        step = self.env.step if self.direct else self.env.step_arrays
        new_obs, rewards, terminated, truncated, infos = step(actions)
        self._infos = infos
        rewards = rewards.astype(np.float32).astype(np.float64)
        done = terminated | truncated
        final, returns = None, []
        if self.direct:
            self._returns += rewards
        if np.count_nonzero(done):
            final = map_obs(np.ndarray.copy, new_obs)
            finished = np.flatnonzero(done)
            for k in finished:
                _set_row(final, k, infos["final_obs"][k])
            if self.direct:
                returns = [float(self._returns[k]) for k in finished]
                self._returns[finished] = 0.0
            elif "episode" in infos:
                returns = [float(infos["episode"][k]["r"]) for k in finished]
        truncated = truncated & ~terminated
        return new_obs, rewards, terminated, truncated, final, returns


def _has_step_arrays(env) -> bool:
    """Every VecEnv of the chain under ``env`` steps as arrays (``step_arrays``)."""
    while env is not None:
        if not callable(getattr(type(env), "step_arrays", None)):
            return False
        env = getattr(env, "venv", None)
    return True


def listed_infos(infos: dict, count: int) -> list[dict]:
    """Gymnasium-style vector infos (arrays of K) as SB3's list of K dicts, finished worlds' from
    their ``final_info`` with ``terminal_observation`` (and ``episode`` where a monitor gave one)."""
    from drivelab.envs.vector import world_info

    listed = []
    for k in range(count):
        if "_final_info" in infos and infos["_final_info"][k]:
            info = dict(infos["final_info"][k])
            info["terminal_observation"] = infos["final_obs"][k]
        else:
            info = world_info(infos, k)
        if "_episode" in infos and infos["_episode"][k]:
            info["episode"] = infos["episode"][k]
        listed.append(info)
    return listed


def row(batch: Any, k: int) -> Any:
    """World ``k``'s observation of a batch (K, ...) (a view; dicts key by key)."""
    return map_obs(lambda value: value[k], batch)


def is_batched(obs: Any, space: spaces.Space) -> bool:
    if isinstance(space, spaces.Dict):
        key = next(iter(space.spaces))
        return is_batched(obs[key], space.spaces[key])
    return np.ndim(obs) == len(space.shape) + 1


def _set_row(batch: Any, k: int, row: Any) -> None:
    if isinstance(batch, dict):
        for key in batch:
            batch[key][k] = row[key]
    else:
        batch[k] = row
