"""DriveEnv: one world of a driving scenario as a gymnasium ``Env`` — the K = 1 view of
``VectorDriveEnv``, so that one world and K worlds run the same code — and ``make_vec``, the vector
env of each registered id."""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np

from drivelab.envs.highway_config import env_kwargs_from_config
from drivelab.envs.spec import EnvSpec
from drivelab.envs.vector import VectorDriveEnv, autoreset_mode_of, check_reset_options, world_info
from drivelab.scenarios import get_scenario
from drivelab.world.state import WorldState


class DriveEnv(gym.Env):
    """One driving scenario seen through drivelab's sensors and rewarded by its shapers.

    :param scenario: a name of ``drivelab.scenarios.SCENARIOS`` or its gymnasium id.
    :param render_mode: "rgb_array" for ``render()``.
    :param seed: resets the episode at once with this seed.
    :param keywords: the environment's keywords (``obs``, ``action``, ``reward``, ``traffic``,
        ``backend``, ``duration_s``, ``offroad_terminal``, ``action_options``, ``backend_options``:
        :class:`~drivelab.envs.spec.EnvSpec` says each; ``config``: a highway-env config dict as
        its users write it; the scenario's options also at the top level, as MetaDrive's users
        write them), or ``env_spec``, an EnvSpec already built.
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 5}

    def __init__(
        self,
        scenario: str = "highway",
        *,
        render_mode: str | None = None,
        seed: int | None = None,
        **keywords,
    ) -> None:
        super().__init__()
        self.render_mode = render_mode
        self._use(VectorDriveEnv(1, scenario, render_mode=render_mode, **keywords))
        self._configured: VectorDriveEnv | None = None  # configure()'s env, taken at the next reset
        self.episode_over = False  # the last step ended the episode: reset before the next step
        if seed is not None:
            self.reset(seed=seed)

    def _use(self, vector: VectorDriveEnv) -> None:
        """Make ``vector`` (one world) this env's: its scenario, parts and spaces."""
        self.vector = vector
        self.scenario, self.adapter, self.sensors = vector.scenario, vector.adapter, vector.sensors
        self.reward_shaper, self.duration_s = vector.reward_shaper, vector.duration_s
        self.metadata = {**type(self).metadata, "render_fps": vector.metadata["render_fps"]}
        self.action_space = vector.single_action_space
        self.observation_space = vector.single_observation_space

    def configure(self, config: dict) -> None:
        """Change the environment from the next ``reset()`` on, as highway-env's ``configure``:
        ``config`` is a highway-env config dict (its keys read as ``drivelab.make(config=...)``
        reads them), whose settings replace this env's (the scenario's options it gives join the
        others). The parts are built now from the new :class:`~drivelab.envs.spec.EnvSpec`, so a
        refused key is a UsageError here and the current episode runs on unchanged; the next
        ``reset()`` switches to them, with their observation and action spaces."""
        current = (self._configured or self.vector).env_spec
        keywords = current.keywords()
        for key, value in env_kwargs_from_config(config, current.scenario).items():
            if key in ("backend_options", "action_options"):
                value = {**(keywords[key] or {}), **value}
            keywords[key] = value
        spec = EnvSpec.build(**keywords)
        configured = VectorDriveEnv(1, render_mode=self.render_mode, env_spec=spec)
        if self._configured is not None:
            self._configured.close()
        self._configured = configured

    @property
    def simulator(self):
        return self.vector.simulator

    @property
    def backend(self):
        """The reference simulator's one-world backend (highway-env, for tests and notebooks that
        reach into it); on the compiled core, the simulator itself."""
        return getattr(self.simulator, "backends", [self.simulator])[0]

    @property
    def world(self) -> WorldState | None:
        """The current world as a WorldState (None before the first reset)."""
        return None if self.vector.batch is None else self.vector.batch[0]

    @property
    def time_limit_s(self) -> float:
        """This episode's time limit (s); a route's own limit where the scenario sets one."""
        if not self.vector.started:
            raise RuntimeError("the time limit is set by reset(): call reset() before reading time_limit_s")
        return float(self.vector.rules.time_limit_s[0])

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        """Start an episode. ``options={"episode_seed": s}`` plays episode ``s`` (an integer in
        [0, 2**63)) instead of the next one drawn from ``np_random``."""
        check_reset_options(options)
        if self._configured is not None:  # configure()'s env from this episode on
            self.vector.close()
            self._use(self._configured)
            self._configured = None
        super().reset(seed=seed)
        self.vector.world_rngs[0] = self.np_random  # the episode seed is drawn from np_random
        if options and options.get("episode_seed") is not None:  # this episode, not the next drawn
            options = {**options, "episode_seeds": [options["episode_seed"]]}
        observations, infos = self.vector.reset(options=options)
        self.episode_over = False
        return _first(observations), world_info(infos, 0)

    def step(self, action: Any):
        """One step of the episode. After one that returned ``terminated`` or ``truncated`` the
        episode is over and ``reset`` must come first (gymnasium's contract: stepping on would be
        undefined): ``gymnasium.error.ResetNeeded``, as ``OrderEnforcing`` raises before the first
        reset. VectorDriveEnv resets its finished worlds itself (autoreset)."""
        vector = self.vector
        if not vector.started:
            raise RuntimeError("call reset() before step()")
        if self.episode_over:
            raise gym.error.ResetNeeded(
                "the episode is over (terminated or truncated): call reset() before step()"
            )
        if vector._fused is not None and vector._fused.ready():  # the circuits: one compiled call
            result = vector.step_one(action)
        else:
            observations, rewards, terminated, truncated, infos = vector.step(np.asarray(action)[None])
            vector.pending_reset[:] = False  # one world: the caller resets it
            result = (
                _first(observations),
                float(rewards[0]),
                bool(terminated[0]),
                bool(truncated[0]),
                world_info(infos, 0),
            )
        self.episode_over = result[2] or result[3]
        return result

    def traffic_light_label(self) -> str:
        """ "none", "green" or "red_or_yellow": the light ahead within 18 m (RLAD's auxiliary label)."""
        return str(self.vector.traffic_light_labels()[0])

    def render(self) -> np.ndarray | None:
        """The current world's scene, drawn as drivelab's videos draw it (``VectorDriveEnv.render_world``)."""
        if self.vector.batch is None:
            return None
        return self.vector.render_world(0)


def _first(observations):
    if isinstance(observations, dict):
        return {name: value[0] for name, value in observations.items()}
    return observations[0]


def make_vec(scenario: str = "highway", num_envs: int = 8, **env_kwargs: Any) -> gym.vector.VectorEnv:
    """``num_envs`` worlds of ``scenario`` as one gymnasium vector env (each id's
    ``vector_entry_point``): a VectorDriveEnv where the compiled core runs the scenario, else
    (``backend="highway"``, the reference) gymnasium's ``AsyncVectorEnv`` of DriveEnvs, one
    process per world."""
    env_kwargs.pop("max_episode_steps", None)
    backend = env_kwargs.get("backend", "auto")
    compiled = backend == "fast" or (backend == "auto" and get_scenario(scenario).fast_backend)
    if compiled or num_envs == 1:
        return VectorDriveEnv(num_envs, scenario=scenario, **env_kwargs)
    mode = env_kwargs.pop("autoreset_mode", "next_step")
    return gym.vector.AsyncVectorEnv(
        [lambda: DriveEnv(scenario=scenario, **env_kwargs) for _ in range(num_envs)],
        autoreset_mode=autoreset_mode_of(mode),
    )
