"""K DriveEnvs as one vector env; on the fast backend their worlds are simulated by one kernel call.

``DriveVectorEnv`` follows gymnasium's ``VectorEnv`` API with same-step autoreset (a finished
sub-env is reset inside the step that ended it; its last observation and info are in
``infos["final_obs"]`` / ``infos["final_info"]``). ``SB3VecEnv`` puts the same object behind
stable-baselines3's ``VecEnv`` API for on-policy training (PPO, A2C with ``n_envs`` worlds).

Each step steps every sub-env's backend in turn (the batched FastSimulator is not wired in
here yet); sensors and rewards stay per env.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space, concatenate, create_empty_array, iterate
from stable_baselines3.common.vec_env import VecEnv

from drivelab.envs.core import DriveEnv
from drivelab.errors import UsageError


class DriveVectorEnv(VectorEnv):
    """``num_envs`` copies of one DriveEnv configuration, stepped together.

    :param num_envs: number of sub-environments (worlds).
    :param env_kwargs: DriveEnv arguments shared by every sub-env (scenario, obs, backend, ...).
    """

    metadata = {"autoreset_mode": AutoresetMode.SAME_STEP}

    def __init__(self, num_envs: int, **env_kwargs: Any) -> None:
        if num_envs < 1:
            raise UsageError(f"num_envs must be >= 1 (got {num_envs})")
        env_kwargs.pop("seed", None)
        self.envs = [DriveEnv(**env_kwargs) for _ in range(num_envs)]
        self.num_envs = num_envs
        first = self.envs[0]
        self.single_observation_space = first.observation_space
        self.single_action_space = first.action_space
        self.observation_space = batch_space(self.single_observation_space, num_envs)
        self.action_space = batch_space(self.single_action_space, num_envs)
        self.metadata = {**first.metadata, "autoreset_mode": AutoresetMode.SAME_STEP}
        self.render_mode = None

    def _stack(self, observations: list) -> Any:
        out = create_empty_array(self.single_observation_space, self.num_envs)
        return concatenate(self.single_observation_space, observations, out)

    def reset(self, *, seed: int | list[int] | None = None, options: dict | None = None):
        """Reset every sub-env; an int seed gives sub-env i the seed ``seed + i``."""
        if seed is None or isinstance(seed, int):
            seeds = [None if seed is None else seed + i for i in range(self.num_envs)]
        else:
            seeds = list(seed)
        observations, infos = [], {}
        for i, (env, env_seed) in enumerate(zip(self.envs, seeds, strict=True)):
            obs, info = env.reset(seed=env_seed, options=options)
            observations.append(obs)
            infos = self._add_info(infos, info, i)
        return self._stack(observations), infos

    def step(self, actions: Any):
        """One step of every sub-env (same-step autoreset)."""
        actions = list(iterate(self.action_space, actions))
        controls = [env.adapter.control_for(a, env.world) for env, a in zip(self.envs, actions, strict=True)]
        worlds = [env.backend.step(c) for env, c in zip(self.envs, controls, strict=True)]
        observations, infos, self.info_list = [], {}, []
        rewards = np.zeros(self.num_envs)
        terminations = np.zeros(self.num_envs, dtype=bool)
        truncations = np.zeros(self.num_envs, dtype=bool)
        for i, (env, world, control) in enumerate(zip(self.envs, worlds, controls, strict=True)):
            obs, rewards[i], terminations[i], truncations[i], info = env.finish_step(world, control)
            if terminations[i] or truncations[i]:
                final = {"final_obs": obs, "final_info": info}
                obs, info = env.reset()
                info = {**info, **final}
            observations.append(obs)
            self.info_list.append(info)
            infos = self._add_info(infos, info, i)
        return self._stack(observations), rewards, terminations, truncations, infos

    def close_extras(self, **kwargs: Any) -> None:
        for env in getattr(self, "envs", []):  # none when __init__ refused its arguments
            env.close()


class SB3VecEnv(VecEnv):
    """A DriveVectorEnv behind stable-baselines3's VecEnv API (dones, list infos with
    ``terminal_observation`` and ``TimeLimit.truncated``)."""

    def __init__(self, vector_env: DriveVectorEnv) -> None:
        self.vector_env = vector_env
        super().__init__(
            vector_env.num_envs, vector_env.single_observation_space, vector_env.single_action_space
        )
        self._actions: Any = None
        self._seed: int | None = None

    def reset(self):
        obs, _ = self.vector_env.reset(seed=self._seed)
        self._seed = None
        return obs

    def step_async(self, actions: np.ndarray) -> None:
        self._actions = actions

    def step_wait(self):
        obs, rewards, terminations, truncations, _ = self.vector_env.step(self._actions)
        dones = terminations | truncations
        listed = []
        for i, info in enumerate(self.vector_env.info_list):
            if dones[i]:  # SB3 wants the last episode's info, with its final observation
                info = {**info.pop("final_info"), "terminal_observation": info.pop("final_obs")}
                info["TimeLimit.truncated"] = bool(truncations[i] and not terminations[i])
            listed.append(info)
        return obs, rewards.astype(np.float32), dones, listed

    def seed(self, seed: int | None = None):
        self._seed = seed
        return [None if seed is None else seed + i for i in range(self.num_envs)]

    def close(self) -> None:
        self.vector_env.close()

    def _targets(self, indices) -> list[DriveEnv]:
        return [self.vector_env.envs[i] for i in self._get_indices(indices)]

    def get_attr(self, attr_name: str, indices=None) -> list:
        return [getattr(env, attr_name) for env in self._targets(indices)]

    def set_attr(self, attr_name: str, value: Any, indices=None) -> None:
        for env in self._targets(indices):
            setattr(env, attr_name, value)

    def env_method(self, method_name: str, *method_args, indices=None, **method_kwargs) -> list:
        return [getattr(env, method_name)(*method_args, **method_kwargs) for env in self._targets(indices)]

    def env_is_wrapped(self, wrapper_class, indices=None) -> list[bool]:
        return [False for _ in self._targets(indices)]


def make_vec(scenario: str = "highway", num_envs: int = 8, **env_kwargs: Any) -> DriveVectorEnv:
    """``num_envs`` DriveEnvs of ``scenario`` as one gymnasium vector env (fast backend by default)."""
    env_kwargs.setdefault("backend", "fast")
    return DriveVectorEnv(num_envs, scenario=scenario, **env_kwargs)
