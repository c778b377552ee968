"""A rule-based driver for the town, the racetrack and the block maps (``--algo expert``), which
also teaches ``bc`` and ``dagger``. It reads the ``waypoints`` and ``affordances`` sensors and acts
through the ``target_speed`` adapter:

- steering: pure pursuit of the route point a speed-dependent distance ahead, on highway-env's
  kinematic bicycle, in the heading's frame or, ``slip_aware``, in the velocity's frame;
- speed: cruise at Roach's 6 m/s, slower in bends (bounded lateral acceleration), and never faster
  than lets it stop before a red (or stoppable yellow) light's stop line, the vehicle ahead, a
  pedestrian, or, for a left turn at a light, the line while an oncoming vehicle comes.

It learns nothing: ``learn`` drives the environment for the requested steps.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from gymnasium import spaces
from stable_baselines3.common.callbacks import BaseCallback

from drivelab.agents.base import OwnAgent
from drivelab.agents.worlds import Worlds, row, vector_env_of
from drivelab.errors import UsageError
from drivelab.perception.affordances import FIELDS
from drivelab.world.geometry import FULL_LOCK_RAD, ROACH_MAX_SPEED_MPS

# the scenarios its rules were written and tested for
SCENARIOS = ("town", "racetrack", "blocks")


@dataclass(frozen=True)
class ExpertConfig:
    """Rules of the expert (``-H key=value``).

    :param cruise_speed_mps: speed on a free straight route (Roach's v_max).
    :param max_speed_mps: the target_speed adapter's speed at action 1 (its ``max_speed_mps``).
    :param brake_mps2: deceleration it plans its stops with.
    :param hard_brake_mps2: deceleration it can still brake at for a light turning yellow.
    :param half_length_m: centre to front bumper.
    :param lateral_accel_mps2: largest lateral acceleration it takes in a bend.
    :param lookahead_m: shortest pure-pursuit distance; it grows by ``lookahead_s`` of travel.
    :param lookahead_s: seconds of travel added to the pursuit distance.
    :param wheelbase_m: of the bicycle model (highway-env: the vehicle's 5 m length).
    :param light_stop_m: centre of the ego to a stop line when stopped for it.
    :param vehicle_gap_m: centre to centre behind a stopped vehicle.
    :param pedestrian_gap_m: centre of the ego to a pedestrian it stops for.
    :param yield_watch_m: an oncoming vehicle closer than this makes a left turn wait.
    :param slip_aware: pursue in the velocity's frame (``_pursuit``), not the heading's.
    """

    cruise_speed_mps: float = ROACH_MAX_SPEED_MPS
    max_speed_mps: float = ROACH_MAX_SPEED_MPS
    brake_mps2: float = 2.5
    hard_brake_mps2: float = 4.0
    half_length_m: float = 2.5
    lateral_accel_mps2: float = 2.0
    lookahead_m: float = 3.0
    lookahead_s: float = 0.5
    wheelbase_m: float = 5.0
    light_stop_m: float = 3.5
    vehicle_gap_m: float = 8.0
    pedestrian_gap_m: float = 6.0
    yield_watch_m: float = 30.0
    slip_aware: bool = False

    def check(self, algo: str) -> None:
        positive = (self.cruise_speed_mps, self.max_speed_mps, self.brake_mps2, self.lateral_accel_mps2)
        if min(positive) <= 0 or self.lookahead_m <= 0 or self.wheelbase_m <= 0:
            raise UsageError(f"{algo!r} needs positive speeds, accelerations, lookahead_m and wheelbase_m")
        distances = (self.half_length_m, self.lookahead_s, self.light_stop_m, self.vehicle_gap_m,
                     self.pedestrian_gap_m, self.yield_watch_m, self.hard_brake_mps2)  # fmt: skip
        if min(distances) < 0:
            raise UsageError(f"{algo!r} needs non-negative lengths, gaps, lookahead_s and hard_brake_mps2")


def stopping_speed(distance_m: float, brake_mps2: float) -> float:
    """The fastest speed from which braking at ``brake_mps2`` stops within ``distance_m``."""
    return float(np.sqrt(2.0 * brake_mps2 * max(distance_m, 0.0)))


def slip_aware_pursuit(target_x: float, target_y: float, length_m: float) -> tuple[float, float]:
    """(steering command in [-1, 1], path curvature) that brings highway-env's bicycle onto the point
    (``target_x``, ``target_y``) of the ego's heading frame. The bicycle moves its centre along
    heading + β, β = atan(tan δ / 2), and turns that direction at κ = 2 sin β / length. Pursuing in
    the velocity's frame, κ = 2·y_v / L² with y_v = y cos β − x sin β, gives tan β = length·y /
    (L² + length·x) in closed form; pursuing in the heading's frame (β off the path) steers too much
    and cuts bends inside."""
    target = np.array([target_x, target_y], dtype=float)
    distance_sq = max(float(target @ target), 1e-6)
    beta = np.arctan(length_m * target_y / (distance_sq + length_m * target_x))
    steer = np.arctan(2.0 * np.tan(beta)) / FULL_LOCK_RAD
    return float(np.clip(steer, -1.0, 1.0)), float(2.0 * np.sin(beta) / length_m)


def check_expert_env(vector, max_speed_mps: float, algo: str) -> None:
    """UsageError unless ``vector`` (a ``VectorDriveEnv``) is a scenario the expert's rules were written
    for and its target_speed action means the speed the expert's ``max_speed_mps`` says."""
    scenario = vector.scenario.name
    if scenario not in SCENARIOS:
        raise UsageError(
            f"{algo}: the rule-based expert drives only in the {', '.join(SCENARIOS[:-1])} and "
            f"{SCENARIOS[-1]} scenarios (its rules read their lights, junctions, pedestrians and the "
            f"vehicle ahead), not {scenario!r}"
        )
    adapter_max = getattr(vector.adapter, "max_speed_mps", None)
    if adapter_max is not None and not np.isclose(adapter_max, max_speed_mps):
        raise UsageError(
            f"{algo}: the target_speed action's max_speed_mps is {adapter_max:g} but the expert's is "
            f"{max_speed_mps:g}; set both alike (-H max_speed_mps, env_options.action_options)"
        )
    if getattr(vector.adapter, "stop_below", 0.0):
        raise UsageError(
            f"{algo}: the expert's speeds are fractions of max_speed_mps from 0; drive it without the "
            "target_speed action's stop_below"
        )


class RuleBasedExpert(OwnAgent):
    """The rule-based driver (see the module docstring)."""

    config_class = ExpertConfig

    def _build(self) -> None:
        space = self.observation_space
        if not isinstance(space, spaces.Dict) or not {"waypoints", "affordances"} <= set(space.spaces):
            raise UsageError("expert needs --obs waypoints,affordances")
        if space["affordances"].shape != (len(FIELDS),):
            raise UsageError("expert needs the affordances sensor without stacking")
        if not isinstance(self.action_space, spaces.Box) or self.action_space.shape != (2,):
            raise UsageError("expert drives with --action target_speed")
        if self.env is not None:
            check_expert_env(vector_env_of(self.env), self.config.max_speed_mps, "expert")

    def _modules(self) -> dict:
        return {}  # rules only: nothing to save

    # --- acting -----------------------------------------------------------------------------------
    def predict(self, obs, state=None, episode_start=None, deterministic: bool = True):
        """(``[target speed fraction, steering]``, None) for one observation."""
        config = self.config
        waypoints = np.asarray(obs["waypoints"], dtype=float).reshape(-1, 2)
        facts = dict(zip(FIELDS, np.asarray(obs["affordances"], dtype=float), strict=True))
        speed = max(facts["speed_mps"], 0.0)
        steer, curvature = self._pursuit(waypoints, config.lookahead_m + config.lookahead_s * speed)
        target = min(config.cruise_speed_mps, np.sqrt(config.lateral_accel_mps2 / max(abs(curvature), 1e-6)))
        target = min(target, self._bend_ahead(waypoints), *self._hazard_limits(facts, speed))
        action = np.array([np.clip(target / config.max_speed_mps, 0.0, 1.0), steer], dtype=np.float32)
        return action, None

    def _pursuit(self, waypoints: np.ndarray, lookahead_m: float) -> tuple[float, float]:
        """(steering command, path curvature) to reach the route point ``lookahead_m`` ahead."""
        points = np.vstack([[0.0, 0.0], waypoints])
        arc = np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(points, axis=0), axis=1))]
        target = np.array([np.interp(lookahead_m, arc, points[:, axis]) for axis in (0, 1)])
        distance_sq = max(float(target @ target), 1e-6)
        curvature = 2.0 * target[1] / distance_sq  # pure pursuit: κ = 2·y / L²
        if not self.config.slip_aware:
            steer = np.arctan(self.config.wheelbase_m * curvature) / FULL_LOCK_RAD  # 1: full lock
            return float(np.clip(steer, -1.0, 1.0)), curvature
        return slip_aware_pursuit(target[0], target[1], self.config.wheelbase_m)

    def _bend_ahead(self, waypoints: np.ndarray) -> float:
        """Speed that lets it slow down in time for the sharpest bend among the waypoints."""
        config = self.config
        points = np.vstack([[0.0, 0.0], waypoints])
        steps = np.diff(points, axis=0)
        lengths = np.linalg.norm(steps, axis=1)
        moving = lengths > 1e-6
        if moving.sum() < 2:
            return config.cruise_speed_mps
        headings = np.unwrap(np.arctan2(steps[moving, 1], steps[moving, 0]))
        curvature = np.abs(np.diff(headings)) / np.maximum(lengths[moving][1:], 1e-6)
        distance = np.cumsum(lengths[moving])[:-1]
        bend_speed = np.sqrt(config.lateral_accel_mps2 / np.maximum(curvature, 1e-6))
        allowed = np.sqrt(bend_speed**2 + 2.0 * config.brake_mps2 * distance)
        return float(min(allowed.min(), config.cruise_speed_mps))

    def _hazard_limits(self, facts: dict, speed: float) -> list[float]:
        config = self.config
        stop_m = facts["stop_line_m"] - config.light_stop_m
        # a yellow light is crossed only when even hard braking would not stop the front bumper
        # before the line, as a driver would (once braking for it, it can always stop)
        bumper_m = facts["stop_line_m"] - config.half_length_m
        can_stop = speed <= stopping_speed(bumper_m, config.hard_brake_mps2)
        stop_for_yellow = facts["light_yellow"] > 0.5 and can_stop
        must_yield = facts["oncoming_m"] < config.yield_watch_m
        limits = []
        if facts["light_red"] > 0.5 or stop_for_yellow or must_yield:
            limits.append(stopping_speed(stop_m, config.brake_mps2))
        # follow at no less than the gap: match the leader's speed plus what a stop within the room
        # allows; inside the gap, drop 1 m/s below the leader's speed per metre missing
        room = facts["leader_m"] - config.vehicle_gap_m
        leader_speed = max(facts["leader_speed_mps"], 0.0)
        following = stopping_speed(room, config.brake_mps2) if room >= 0 else room
        limits.append(leader_speed + following)
        limits.append(stopping_speed(facts["pedestrian_m"] - config.pedestrian_gap_m, config.brake_mps2))
        return limits

    # --- "training": driving the environment with the rules ---------------------------------------
    def _learn(self, worlds: Worlds, callback: BaseCallback, target: int) -> None:
        """Drive with the rules in each of the K worlds (nothing is learned)."""
        while self.num_timesteps < target:
            actions = np.stack([self.predict(row(self._last_obs, k))[0] for k in range(worlds.count)])
            self._last_obs, rewards, terminated, truncated, _, _ = worlds.step(actions)
            self.num_timesteps += worlds.count
            callback.update_locals(locals())
            if not callback.on_step():
                break
        self._log_progress({})
