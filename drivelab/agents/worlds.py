"""The training env as K worlds, the one loop of acting shared by drivelab's own agents.

An agent trains on one gymnasium env (K = 1) or on an SB3 ``VecEnv`` of K worlds (``drivelab
train --n-envs K``: a VectorDriveEnv that resets a finished world in the step that ended it).
``Worlds`` gives both the VecEnv's shape: observations batched (K, ...), rewards and flags (K,),
the final observation of every world whose episode ended, and the returns of the episodes that
ended, so the agents' collect loops are written once, for K worlds. ``Worlds.batch`` is the
``WorldBatch`` behind the observations last returned (the imitation teacher reads it).
"""

from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium import spaces
from stable_baselines3.common.vec_env import VecEnv

from drivelab.agents.base import batch_of_one
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


class Worlds:
    """The training env as K worlds: a gymnasium env (K = 1, reset here when its episode ends) or
    an SB3 ``VecEnv`` (K = ``num_envs``, resetting a finished world itself). Observations come and
    go batched (K, ...), dicts key by key; a finished world has started again when ``step`` returns,
    so ``batch`` always holds the state of the observations last returned."""

    def __init__(self, env) -> None:
        self.env = env
        self.vector = isinstance(env, VecEnv)
        self.count = env.num_envs if self.vector else 1
        self.infos: list[dict] = [{} for _ in range(self.count)]  # the last step's, one per world
        self.reset_infos: list[dict] = [{} for _ in range(self.count)]  # the latest reset's (see step)

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
        the episodes that ended). ``infos`` then holds the step's info of every world (of the
        step that ended it, for a finished world); with one world, ``reset_infos`` the reset's when
        it started again (a VecEnv's ``reset_infos`` are its last ``reset``'s: SB3VecEnv does not
        give the infos of the resets inside ``step``)."""
        if self.vector:
            new_obs, rewards, dones, infos = self.env.step(actions)
            self.infos = infos
            truncated = np.array([bool(info.get("TimeLimit.truncated", False)) for info in infos])
            terminated = np.asarray(dones, dtype=bool) & ~truncated
            final = None
            if dones.any():
                final = _copy(new_obs)
                for k in np.flatnonzero(dones):
                    _set_row(final, k, infos[k]["terminal_observation"])
            returns = [float(info["episode"]["r"]) for info in infos if "episode" in info]
            return new_obs, np.asarray(rewards, dtype=np.float64), terminated, truncated, final, returns
        new_obs, reward, terminated, truncated, info = self.env.step(actions[0])
        self.infos = [info]
        final = batch_of_one(new_obs)
        returns = [float(info["episode"]["r"])] if "episode" in info else []
        if terminated or truncated:
            new_obs, reset_info = self.env.reset()
            self.reset_infos = [reset_info]
        return (
            batch_of_one(new_obs), np.array([float(reward)]), np.array([terminated]), np.array([truncated]),
            final, returns,
        )  # fmt: skip


def row(batch: Any, k: int) -> Any:
    """World ``k``'s observation of a batch (K, ...) (a view; dicts key by key)."""
    return {key: value[k] for key, value in batch.items()} if isinstance(batch, dict) else batch[k]


def is_batched(obs: Any, space: spaces.Space) -> bool:
    if isinstance(space, spaces.Dict):
        key = next(iter(space.spaces))
        return is_batched(obs[key], space.spaces[key])
    return np.ndim(obs) == len(space.shape) + 1


def _copy(batch: Any) -> Any:
    return {key: value.copy() for key, value in batch.items()} if isinstance(batch, dict) else batch.copy()


def _set_row(batch: Any, k: int, row: Any) -> None:
    if isinstance(batch, dict):
        for key in batch:
            batch[key][k] = row[key]
    else:
        batch[k] = row
