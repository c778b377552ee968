"""A VectorDriveEnv behind stable-baselines3's ``VecEnv`` API, for SB3's agents (and for the own
agents that ``drivelab train`` runs on the same monitored chain, through ``step_arrays``)."""

from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium.vector import AutoresetMode
from stable_baselines3.common.vec_env import VecEnv

from drivelab.agents.worlds import listed_infos
from drivelab.envs.vector import VectorDriveEnv


class SB3VecEnv(VecEnv):
    """A VectorDriveEnv behind stable-baselines3's VecEnv API (dones, list infos with
    ``terminal_observation`` and ``TimeLimit.truncated``); the env autoresets in the same step."""

    def __init__(self, vector_env: VectorDriveEnv) -> None:
        if vector_env.autoreset_mode != AutoresetMode.SAME_STEP:
            raise ValueError("SB3VecEnv needs a VectorDriveEnv with autoreset_mode=SAME_STEP")
        self.vector_env = vector_env
        super().__init__(
            vector_env.num_envs, vector_env.single_observation_space, vector_env.single_action_space
        )
        self.render_mode = "rgb_array"
        self._actions: Any = None
        self._seed: int | None = None

    def reset(self):
        obs, infos = self.vector_env.reset(seed=self._seed)
        self._seed = None
        self.reset_infos = [{"episode_seed": int(seed)} for seed in infos["episode_seed"]]
        return obs

    def step_async(self, actions: np.ndarray) -> None:
        self._actions = actions

    def step_wait(self):
        obs, rewards, terminations, truncations, infos = self.vector_env.step(self._actions)
        dones = terminations | truncations
        listed = listed_infos(infos, self.num_envs)  # SB3's, with terminal_observation
        for k in np.flatnonzero(dones):
            listed[k]["TimeLimit.truncated"] = bool(truncations[k] and not terminations[k])
        return obs, rewards.astype(np.float32), dones, listed

    def step_arrays(self, actions: np.ndarray):
        """``step`` without the per-world info dicts: the VectorDriveEnv's own ``(observations,
        rewards, terminated, truncated, infos)``, arrays of K worlds (finished worlds already
        started again, their last observations in ``infos["final_obs"]``)."""
        return self.vector_env.step(actions)

    def seed(self, seed: int | None = None):
        self._seed = seed
        return [None if seed is None else seed + i for i in range(self.num_envs)]

    def close(self) -> None:
        self.vector_env.close()

    def get_images(self) -> list[np.ndarray]:
        """Each world's bird's-eye frame (SB3's ``VecVideoRecorder`` tiles them)."""
        if self.vector_env.batch is None:
            return [None] * self.num_envs
        return [self.vector_env.render_world(k) for k in range(self.num_envs)]

    def get_attr(self, attr_name: str, indices=None) -> list:
        return [getattr(self.vector_env, attr_name) for _ in self._get_indices(indices)]

    def set_attr(self, attr_name: str, value: Any, indices=None) -> None:
        setattr(self.vector_env, attr_name, value)

    def env_method(self, method_name: str, *method_args, indices=None, **method_kwargs) -> list:
        method = getattr(self.vector_env, method_name)
        return [method(*method_args, **method_kwargs) for _ in self._get_indices(indices)]

    def env_is_wrapped(self, wrapper_class, indices=None) -> list[bool]:
        return [False for _ in self._get_indices(indices)]
