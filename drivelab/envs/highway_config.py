"""highway-env's config dict, as its users write it, read as drivelab's environment options.

``drivelab.make("highway", config={"observation": {"type": "Kinematics"}, "lanes_count": 4,
"collision_reward": -2})`` builds the DriveEnv that config describes:

- ``observation`` (``{"type": …, options}``) → a drivelab sensor: ``Kinematics`` → ``kinematics``
  (``vehicles_count``), ``LidarObservation`` → ``lidar`` (``cells`` beams, ``maximum_range``),
  ``TimeToCollision`` → ``ttc_grid``;
- ``action`` → ``DiscreteMetaAction`` → ``meta`` (its ``lateral`` and ``longitudinal`` options),
  ``ContinuousAction`` → ``continuous``, ``DiscreteAction`` → ``grid``;
- reward weights (``collision_reward``, ``right_lane_reward``, ``high_speed_reward``) → the
  ``highway`` preset with those weights, normalised over [collision, high speed + right lane]
  as highway-env does; ``duration`` → ``duration_s``; ``offroad_terminal``;
- every other key (``lanes_count``, ``vehicles_count``, ``vehicles_density``, ``ego_spacing``,
  ``simulation_frequency``, ``policy_frequency``, …) goes to the scenario's road and traffic as
  highway-env reads it (``backend_options``).

Keys whose highway-env meaning drivelab does not reproduce (other observation types, options of
an observation that drivelab's sensor lacks, a reward speed range other than the lane limit's,
an unnormalised reward, the lane-change reward) are refused with a one-line error naming them,
rather than silently ignored.
"""

from __future__ import annotations

import dataclasses
from typing import Any

from drivelab.errors import UsageError
from drivelab.rewards.shapers import PRESETS

# highway-env observation type → (drivelab sensor, {highway-env option: drivelab option})
OBSERVATIONS = {
    "Kinematics": ("kinematics", {"vehicles_count": "vehicles_count"}),
    "LidarObservation": ("lidar", {"cells": "beams", "maximum_range": "range_m"}),
    "TimeToCollision": ("ttc_grid", {}),
}
# options that only restate drivelab's own behaviour are accepted when they have these values
OBSERVATION_DEFAULTS = {
    "Kinematics": {"features": ["presence", "x", "y", "vx", "vy", "cos_h", "sin_h"], "normalize": True},
}
ACTIONS = {"DiscreteMetaAction": "meta", "ContinuousAction": "continuous", "DiscreteAction": "grid"}
REWARD_WEIGHTS = {
    "collision_reward": "collision", "right_lane_reward": "right_lane", "high_speed_reward": "high_speed",
}  # fmt: skip
# keys drivelab does not reproduce unless they have highway-env's default value
FIXED = {"normalize_reward": True, "lane_change_reward": 0}


def env_kwargs_from_config(config: dict[str, Any], **given: Any) -> dict[str, Any]:
    """DriveEnv keyword arguments from a highway-env config dict; ``given`` (explicit keyword
    arguments) win over the config."""
    if not isinstance(config, dict):
        raise UsageError(f"config must be a dict of highway-env settings, got {config!r}")
    rest = dict(config)
    kwargs: dict[str, Any] = {}
    if "observation" in rest:
        kwargs["obs"] = _observation(rest.pop("observation"))
    if "action" in rest:
        kwargs["action"], options = _action(rest.pop("action"))
        if options:
            kwargs["action_options"] = options
    weights = {term: float(rest.pop(key)) for key, term in REWARD_WEIGHTS.items() if key in rest}
    if weights:  # highway-env normalises by [collision, high speed + right lane] with its weights
        weights = {**PRESETS["highway"].weights, **weights}
        low, high = weights["collision"], weights["high_speed"] + weights["right_lane"]
        kwargs["reward"] = dataclasses.replace(PRESETS["highway"], weights=weights, normalize=(low, high))
    if "duration" in rest:
        kwargs["duration_s"] = rest.pop("duration")
    if "offroad_terminal" in rest:
        kwargs["offroad_terminal"] = rest.pop("offroad_terminal")
    for key, default in FIXED.items():
        if key in rest and rest.pop(key) != default:
            raise UsageError(f"highway-env config key {key!r}: drivelab supports only {default!r}")
    if "reward_speed_range" in rest:
        raise UsageError(
            "highway-env config key 'reward_speed_range': drivelab's high_speed term rewards 2/3 to 1 "
            "of the lane's speed limit (highway-env's [20, 30] on the highway)"
        )
    if rest:
        kwargs["backend_options"] = {**rest, **(given.pop("backend_options", None) or {})}
    return {**kwargs, **given}


def _observation(spec: Any) -> str:
    if not isinstance(spec, dict) or "type" not in spec:
        raise UsageError(f"highway-env 'observation' must be a dict with a 'type', got {spec!r}")
    kind = spec["type"]
    if kind not in OBSERVATIONS:
        raise UsageError(
            f"highway-env observation type {kind!r} has no drivelab sensor (known: "
            f"{', '.join(OBSERVATIONS)}; drivelab's own image sensors are topdown, birdeye and camera)"
        )
    sensor, names = OBSERVATIONS[kind]
    options = []
    for key, value in spec.items():
        if key == "type" or OBSERVATION_DEFAULTS.get(kind, {}).get(key, object()) == value:
            continue
        if key not in names:
            raise UsageError(f"highway-env {kind} option {key!r}: no such option in drivelab's {sensor}")
        options.append(f"{names[key]}={value}")
    return ":".join([sensor, *options])


def _action(spec: Any) -> tuple[str, dict]:
    """The action kind and its options: ``DiscreteMetaAction``'s ``lateral`` and ``longitudinal``."""
    if not isinstance(spec, dict) or spec.get("type") not in ACTIONS:
        raise UsageError(
            f"highway-env 'action' must be a dict with a type of {', '.join(ACTIONS)}, got {spec!r}"
        )
    allowed = {"type", "lateral", "longitudinal"} if spec["type"] == "DiscreteMetaAction" else {"type"}
    if set(spec) - allowed:
        raise UsageError(f"highway-env action options {sorted(set(spec) - allowed)} are not supported")
    return ACTIONS[spec["type"]], {key: value for key, value in spec.items() if key != "type"}
