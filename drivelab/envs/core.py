"""DriveEnv: the gymnasium environment that assembles backend, sensors, actions and rewards."""

from __future__ import annotations

import dataclasses
import inspect
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from drivelab.envs.actions import ActionAdapter, make_action
from drivelab.envs.metrics import EpisodeMetrics
from drivelab.envs.scenarios import check_traffic, get_scenario
from drivelab.errors import UsageError
from drivelab.perception.birdeye import render_birdeye
from drivelab.perception.sensors import make_sensor, split_sensor_list
from drivelab.rewards.shapers import RewardShaper
from drivelab.world.state import LIGHT_GREEN, LIGHT_RED, LIGHT_YELLOW, WorldState

BACKENDS = ("auto", "fast", "highway")
LIGHT_LABEL_DISTANCE_M = 18.0  # RLAD's auxiliary label: a light within this distance ahead
LIGHT_LABELS = {LIGHT_GREEN: "green", LIGHT_YELLOW: "red_or_yellow", LIGHT_RED: "red_or_yellow"}
BLOCKED_SPEED_MPS = 0.1


RUN_KEYWORDS = ("scenario", "obs", "action", "reward", "traffic", "backend")  # RunConfig fields


def env_option_names() -> tuple[str, ...]:
    """DriveEnv keywords a run's ``env_options`` may set: all but those the run's own fields
    give (scenario, obs, ...) and those training sets itself (render_mode, seed)."""
    parameters = inspect.signature(DriveEnv.__init__).parameters
    taken = (*RUN_KEYWORDS, "self", "render_mode", "seed")
    return tuple(name for name in parameters if name not in taken)


def check_env_options(options: dict) -> None:
    """An unknown ``env_options`` key is a UsageError naming the known ones (values are checked
    by DriveEnv itself)."""
    known = env_option_names()
    for key in options:
        if key not in known:
            raise UsageError(f"unknown env_options key {key!r} (known: {', '.join(known)})")


def _check_keywords(duration_s, offroad_terminal, action_options, backend_options) -> None:
    """The types and ranges of DriveEnv's option keywords, as one-line UsageErrors."""
    if duration_s is not None and (
        isinstance(duration_s, bool)
        or not isinstance(duration_s, (int, float))
        or not 0 < duration_s < float("inf")
    ):
        raise UsageError(f"duration_s must be a number of seconds > 0, got {duration_s!r}")
    if not isinstance(offroad_terminal, bool):
        raise UsageError(f"offroad_terminal must be true or false, got {offroad_terminal!r}")
    for name, value in (("action_options", action_options), ("backend_options", backend_options)):
        if value is not None and not isinstance(value, dict):
            raise UsageError(f"{name} must be a mapping of options, got {value!r}")


class DriveEnv(gym.Env):
    """One driving scenario seen through drivelab's sensors and rewarded by its shapers.

    :param scenario: a name of ``drivelab.envs.scenarios.SCENARIOS`` (highway, merge, roundabout,
        intersection, racetrack, town, follow-line, follow-lane).
    :param obs: a sensor spec (``"lidar"``, ``"lidar:beams=120:stack=3"``), a comma list, or a
        list of specs. One sensor gives its Box; several give a Dict keyed by sensor name.
    :param action: an action kind (``drivelab.envs.actions.ACTIONS``) or an ActionAdapter; default
        the scenario's first (``meta`` on the highway scenarios, ``seed_line`` on follow-line, …),
        as ``drivelab train`` picks it.
    :param reward: a preset, ``"term=w,…"``, ``"preset,term=w"`` or a dict of weights; default the
        scenario's preset (``roach`` in the town, ``line_follow`` on follow-line, …).
    :param traffic: "empty", "regular" or "dense".
    :param backend: "auto" (fast where it runs the scenario, else highway), "fast" (drivelab's
        compiled port of highway-env's traffic model on highway-env's roads: step for step the
        same episodes, many times faster, see benchmarks/results/backend_speed.md) or "highway"
        (highway-env itself, the reference).
    :param duration_s: episode time limit; default the scenario's (in the town with fixed routes,
        the route's NoCrash limit; a given duration caps it).
    :param offroad_terminal: end the episode when the ego leaves the road.
    :param action_options: keyword options of the action adapter (e.g. ``steer_levels``).
    :param backend_options: extra highway-env config keys.
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 5}

    def __init__(
        self,
        scenario: str = "highway",
        obs: str | list = "kinematics",
        action: str | ActionAdapter | None = None,
        reward: str | dict | None = None,
        traffic: str = "regular",
        backend: str = "auto",
        duration_s: float | None = None,
        offroad_terminal: bool = True,
        action_options: dict | None = None,
        backend_options: dict | None = None,
        render_mode: str | None = None,
        seed: int | None = None,
    ) -> None:
        super().__init__()
        _check_keywords(duration_s, offroad_terminal, action_options, backend_options)
        self.scenario = get_scenario(scenario)
        check_traffic(traffic)
        action = self.scenario.action_kinds[0] if action is None else action
        reward = self.scenario.default_reward if reward is None else reward
        self.adapter = (
            action if isinstance(action, ActionAdapter) else make_action(action, **(action_options or {}))
        )
        if self.adapter.name not in self.scenario.action_kinds:
            raise UsageError(
                f"scenario {scenario!r} cannot take action {self.adapter.name!r} "
                f"(it takes {', '.join(self.scenario.action_kinds)})"
            )
        self.sensors = [make_sensor(spec) for spec in split_sensor_list(obs)]
        names = [s.name for s in self.sensors]
        if len(set(names)) != len(names):
            raise UsageError(f"sensor listed twice in {names}")
        self.reward_shaper = RewardShaper(reward)
        if backend not in BACKENDS:
            raise UsageError(f"unknown backend {backend!r} (choose from {', '.join(BACKENDS)})")
        if backend == "auto":
            backend = "fast" if self.scenario.fast_backend else "highway"
        if backend == "fast":
            from drivelab.envs.backends.fast.backend import FastBackend as backend_class
        else:
            from drivelab.envs.backends.highway import HighwayBackend as backend_class

        self.backend = backend_class(self.scenario, traffic, self.adapter.control, backend_options)
        self.duration_s = float(duration_s or self.backend.duration_s)
        self.duration_given = duration_s is not None
        self.offroad_terminal = offroad_terminal
        self.render_mode = render_mode
        self.metadata = {**self.metadata, "render_fps": self.backend.policy_frequency_hz}
        self.action_space = self.adapter.space
        if len(self.sensors) == 1:
            self.observation_space = self.sensors[0].space
        else:
            self.observation_space = spaces.Dict({s.name: s.space for s in self.sensors})
        self.world: WorldState | None = None
        if seed is not None:
            self.reset(seed=seed)

    def _observe(self) -> np.ndarray | dict[str, np.ndarray]:
        if len(self.sensors) == 1:
            return self.sensors[0].observe(self.world)
        return {s.name: s.observe(self.world) for s in self.sensors}

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        episode_seed = int(self.np_random.integers(2**31 - 1))
        self.world = self.backend.reset(episode_seed)
        self.adapter.reset()
        for index, sensor in enumerate(self.sensors):
            sensor.reset(self.world, np.random.default_rng([episode_seed, index]))
        self.metrics = EpisodeMetrics(self.world)
        self.stopped_s = 0.0
        # an evaluation route brings its own time limit (the town's NoCrash protocol); a duration
        # given to this env still caps it
        route_limit_s = getattr(self.backend, "route_time_limit_s", None)
        self.time_limit_s = self.duration_s
        if route_limit_s is not None:
            self.time_limit_s = min(route_limit_s, self.duration_s) if self.duration_given else route_limit_s
        return self._observe(), {"episode_seed": episode_seed, "traffic_light": self.traffic_light_label()}

    def step(self, action: Any):
        if self.world is None:
            raise RuntimeError("call reset() before step()")
        control = self.adapter.control_for(action, self.world)
        return self.finish_step(self.backend.step(control), control)

    def finish_step(self, world: WorldState, control: Any):
        """Observation, reward, episode end and info once the backend has produced ``world``
        from ``control`` (``step`` without the simulation; batched vector envs simulate apart)."""
        prev, self.world = self.world, self._apply_episode_rules(world)
        reward, terms = self.reward_shaper(prev, self.world, control)
        events = self.world.events
        terminated = bool(
            events.collided
            or events.arrived
            or events.red_light_crossed
            or events.blocked
            or events.off_route
            or (self.offroad_terminal and events.off_road)
        )
        truncated = bool(not terminated and self.world.time_s >= self.time_limit_s - 1e-9)
        self.metrics.update(self.world, reward)
        info = {
            "reward_terms": terms,
            "speed_mps": self.world.ego.speed_mps,
            "crashed": events.collided,
            "off_road": events.off_road,
            "arrived": events.arrived,
            "traffic_light": self.traffic_light_label(),
        }
        if terminated or truncated:
            info["episode_metrics"] = self.metrics.summary(
                has_goal=self.scenario.arrival != "none", timed_out=truncated
            )
        return self._observe(), reward, terminated, truncated, info

    def _apply_episode_rules(self, world: WorldState) -> WorldState:
        """The scenario's blocked and route-deviation rules, as events of ``world``."""
        scenario = self.scenario
        if scenario.blocked_after_s is None and scenario.route_deviation_m is None:
            return world
        moving = world.ego.speed_mps >= BLOCKED_SPEED_MPS
        self.stopped_s = 0.0 if moving else self.stopped_s + world.dt_s
        blocked = scenario.blocked_after_s is not None and self.stopped_s > scenario.blocked_after_s
        off_route = False
        if scenario.route_deviation_m is not None:
            point, _ = world.route.poses_at(world.route.progress_m)
            off_route = float(np.linalg.norm(world.ego.position - point)) > scenario.route_deviation_m
        if not (blocked or off_route):
            return world
        return dataclasses.replace(
            world, events=dataclasses.replace(world.events, blocked=blocked, off_route=off_route)
        )

    def traffic_light_label(self) -> str:
        """ "none", "green" or "red_or_yellow": the light ahead within 18 m (RLAD's auxiliary label)."""
        light = self.world.light_ahead(LIGHT_LABEL_DISTANCE_M)
        return "none" if light is None else LIGHT_LABELS[light[0]]

    def render(self) -> np.ndarray | None:
        """A 256×512 bird's-eye RGB frame of the current world (drivelab's own renderer)."""
        if self.world is None:
            return None
        return render_birdeye(self.world, size_hw=(256, 512), pixels_per_meter=4.0)
