"""highway-env's config dict, as its users write it, read as drivelab's environment options.

``drivelab.make("highway", config=HighwayEnvFast.default_config())`` builds the DriveEnv that
config describes. Each key is accepted where its value is what drivelab does, mapped where
drivelab has the same thing under another name, and refused where drivelab differs:

- ``observation`` (``{"type": …, options}``) → a drivelab sensor: ``Kinematics`` → ``kinematics``
  in highway-env's ``(V, F)`` layout (``flatten=false``) with highway-env's default features
  ``presence, x, y, vx, vy`` unless ``features`` names others; ``vehicles_count``, ``features``,
  ``normalize``, ``clip``, ``flatten`` map to its options, a symmetric ``features_range``
  ``x, y: [-d, d]``, ``vx, vy: [-s, s]`` to ``perception_distance_m=d``, ``speed_scale_mps=s``;
  ``order: sorted``, ``absolute: False``, ``see_behind: True`` and ``include_obstacles`` say what
  drivelab does; features ``cos_d``, ``sin_d`` need ``observe_intentions: true`` (highway-env's are
  zeros without it), and drivelab's own ``accel``, which highway-env lacks, is refused.
  ``LidarObservation`` → ``lidar`` (``cells`` beams, ``maximum_range``), ``TimeToCollision`` → ``ttc_grid``;
- ``action`` → ``DiscreteMetaAction`` → ``meta`` (its ``lateral`` and ``longitudinal`` options;
  ``target_speeds`` equal to the scenario's), ``ContinuousAction`` → ``continuous``,
  ``DiscreteAction`` → ``grid``;
- on the highway (HighwayEnv's reward): ``collision_reward``, ``right_lane_reward``,
  ``high_speed_reward`` → the ``highway`` preset with those weights, normalised over [collision,
  high speed + right lane] as highway-env does (``normalize_reward: False``: not normalised);
  ``reward_speed_range`` [20, 30], what the ``high_speed`` term rewards there;
  ``lane_change_reward``, which HighwayEnv does not read. The other scenarios' highway-env classes
  compute rewards of their own, which drivelab does not reproduce: their reward keys are refused;
- ``duration`` → ``duration_s``; ``offroad_terminal`` (``terminate_off_road`` on the racetrack);
- highway-env's viewer settings (``screen_width``, ``scaling``, …) at the class's defaults;
  ``controlled_vehicles: 1``; ``other_vehicles_type``, ``destination`` and
  ``neighbour_vehicles_connected_lanes`` at the values drivelab reproduces;
- every other key (``lanes_count``, ``vehicles_count``, ``vehicles_density``, ``ego_spacing``,
  ``simulation_frequency``, ``policy_frequency``, …) goes to the scenario's road and traffic as
  highway-env reads it (``backend_options``), where it must be one of the scenario's options.

Everything refused is said in one UsageError line, each key with how drivelab differs and what
to use instead.
"""

from __future__ import annotations

import dataclasses
from typing import Any

from drivelab.errors import UsageError
from drivelab.perception.kinematics import FEATURES, INTENTION_FEATURES
from drivelab.rewards.shapers import PRESETS
from drivelab.scenarios import get_scenario
from drivelab.scenarios.options import unknown_options_message

# highway-env observation type → (drivelab sensor, {highway-env option: drivelab option})
OBSERVATIONS = {
    "Kinematics": ("kinematics", {"vehicles_count": "vehicles_count"}),
    "LidarObservation": ("lidar", {"cells": "beams", "maximum_range": "range_m"}),
    "TimeToCollision": ("ttc_grid", {}),
}
# highway-env's Kinematics: its default features, and the options whose one value says what
# drivelab's kinematics does (option → (the value drivelab has, how drivelab differs otherwise))
KINEMATICS_FEATURES = ("presence", "x", "y", "vx", "vy")
KINEMATICS_SAME = {
    "absolute": (
        False,
        "drivelab's kinematics is in the ego frame (x forward, y right, the ego at the origin); "
        "for world positions use a bird's-eye sensor (topdown, birdeye)",
    ),
    "order": ("sorted", "drivelab's kinematics lists the vehicles nearest first ('sorted')"),
    "see_behind": (True, "drivelab's kinematics sees the vehicles behind the ego too (see_behind: True)"),
}
ACTIONS = {"DiscreteMetaAction": "meta", "ContinuousAction": "continuous", "DiscreteAction": "grid"}
HIGHWAY_ENV_TARGET_SPEEDS = (20.0, 25.0, 30.0)  # MDPVehicle.DEFAULT_TARGET_SPEEDS
REWARD_WEIGHTS = {
    "collision_reward": "collision", "right_lane_reward": "right_lane", "high_speed_reward": "high_speed",
}  # fmt: skip
REWARD_KEYS = (
    *REWARD_WEIGHTS, "lane_change_reward", "normalize_reward", "reward_speed_range", "merging_speed_reward",
    "arrived_reward", "action_reward", "lane_centering_cost", "lane_centering_reward",
)  # fmt: skip
HIGHWAY_SPEED_LIMIT_MPS = 30.0  # the highway's lanes: high_speed rewards 2/3 to 1 of it, [20, 30]
# how each other scenario's highway-env class computes its reward (drivelab's is the highway preset)
OWN_REWARDS = {
    "merge": "MergeEnv adds merging_speed_reward, reads the lane index unnormalised and has no "
    "on-road factor",
    "roundabout": "RoundaboutEnv rewards speed by target-speed index and normalises over [collision, "
    "high speed]",
    "intersection": "IntersectionEnv's arrived_reward replaces the step's reward and its speed range "
    "is its own",
    "racetrack": "RacetrackEnv rewards lane centring and penalises actions",
}
VIEWER_KEYS = (
    "centering_position", "scaling", "screen_width", "screen_height", "show_trajectories", "render_agent",
    "offscreen_rendering", "real_time_rendering", "manual_control",
)  # fmt: skip
# keys a scenario's highway-env class has but does not read: accepted whatever their value
UNREAD = {"racetrack": {"speed_limit"}}  # RacetrackEnvLarge's; RacetrackEnv's road is fixed


def env_kwargs_from_config(
    config: dict[str, Any], scenario: str | None = None, **given: Any
) -> dict[str, Any]:
    """DriveEnv keyword arguments from a highway-env config dict for ``scenario`` (default
    highway); ``given`` (explicit keyword arguments) win over the config."""
    if not isinstance(config, dict):
        raise UsageError(f"config must be a dict of highway-env settings, got {config!r}")
    scene = get_scenario(scenario or "highway")
    rest, problems = dict(config), []
    kwargs: dict[str, Any] = {}
    if "observation" in rest:
        kwargs["obs"] = _observation(rest.pop("observation"), problems)
    if "action" in rest:
        kwargs["action"], options = _action(rest.pop("action"), scene, problems)
        if options:
            kwargs["action_options"] = options
    rewards = {key: rest.pop(key) for key in REWARD_KEYS if key in rest}
    if rewards:
        reward = _reward(rewards, scene.name, problems)
        if reward is not None:
            kwargs["reward"] = reward
    if "duration" in rest:
        kwargs["duration_s"] = rest.pop("duration")
    for key in ("offroad_terminal", "terminate_off_road"):
        if key in rest:
            kwargs["offroad_terminal"] = rest.pop(key)
    _same_as_drivelab(rest, scene, problems)
    declared = {option.name for option in scene.options}
    unknown = [key for key in rest if key not in declared]
    if unknown:
        problems.append(unknown_options_message(scene, unknown))
    if problems:
        raise UsageError(f"highway-env config for {scene.name!r}: {'; '.join(problems)}")
    if rest:
        kwargs["backend_options"] = {**rest, **(given.pop("backend_options", None) or {})}
    return {**kwargs, **given}


def _reward(rewards: dict[str, Any], scenario: str, problems: list[str]) -> Any:
    """The reward of highway-env's reward keys on the highway (HighwayEnv's formula); elsewhere a
    problem, since each highway-env class computes its own."""
    if scenario != "highway":
        own = OWN_REWARDS.get(scenario, "its highway-env class has no reward drivelab reproduces")
        problems.append(
            f"reward keys {', '.join(rewards)}: {own}, and drivelab's reward on {scenario!r} is the "
            f"highway preset (HighwayEnv's formula): drop them, or give reward= (e.g. "
            f"'highway,lane_change=-0.05')"
        )
        return None
    low, high = HIGHWAY_SPEED_LIMIT_MPS * 2 / 3, HIGHWAY_SPEED_LIMIT_MPS
    speed_range = rewards.get("reward_speed_range", (low, high))
    try:
        same_range = [float(value) for value in speed_range] == [low, high]
    except (TypeError, ValueError):
        same_range = False
    if not same_range:
        problems.append(
            f"'reward_speed_range' {speed_range!r}: drivelab's high_speed term rewards 2/3 to 1 of the "
            f"lane's speed limit, [{low:g}, {high:g}] m/s on the highway"
        )
    normalize = rewards.get("normalize_reward", True)
    if not isinstance(normalize, bool):
        problems.append(f"'normalize_reward' must be true or false, got {normalize!r}")
    weights = {term: rewards[key] for key, term in REWARD_WEIGHTS.items() if key in rewards}
    for term, value in weights.items():
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            problems.append(f"'{term}_reward' must be a number, got {value!r}")
    if problems or (not weights and normalize is True):
        return None  # lane_change_reward (HighwayEnv reads none) and the speed range change nothing
    # highway-env normalises by [collision, high speed + right lane] with its weights
    weights = {**PRESETS["highway"].weights, **{term: float(value) for term, value in weights.items()}}
    low, high = weights["collision"], weights["high_speed"] + weights["right_lane"]
    return dataclasses.replace(
        PRESETS["highway"], weights=weights, normalize=(low, high) if normalize else None
    )


def _same_as_drivelab(rest: dict[str, Any], scene, problems: list[str]) -> None:
    """Pop the keys whose value says what drivelab does (the viewer's at the class's defaults,
    one controlled vehicle, the traffic model and destination drivelab reproduces); a problem for
    each that differs."""
    from highway_env import utils

    defaults = utils.class_from_path(scene.env_class).default_config()
    viewer = {key: rest.pop(key) for key in VIEWER_KEYS if key in rest}
    changed = [key for key, value in viewer.items() if value != defaults.get(key)]
    if changed:
        problems.append(
            f"highway-env's viewer settings {', '.join(changed)}: drivelab's env.render() draws with its "
            f"own renderer and has no manual control; leave them at highway-env's defaults or out"
        )
    for key in UNREAD.get(scene.name, ()):
        rest.pop(key, None)
    same = {
        "controlled_vehicles": (1, "drivelab drives one ego vehicle"),
        "other_vehicles_type": (
            defaults.get("other_vehicles_type"),
            "each scenario's traffic model is fixed (highway-env's IDM/MOBIL)",
        ),
        "neighbour_vehicles_connected_lanes": (False, "drivelab's traffic looks at the lane's own vehicles"),
        "destination": (
            scene.destination,
            f"drivelab's {scene.name} routes the ego to {scene.destination!r}",
        ),
    }
    for key, (value, why) in same.items():
        if key in rest and (key != "destination" or scene.destination is not None):
            given = rest.pop(key)
            if given != value:
                problems.append(f"{key!r} {given!r}: {why}")


def _observation(spec: Any, problems: list[str]) -> str | None:
    if not isinstance(spec, dict) or "type" not in spec:
        raise UsageError(f"highway-env 'observation' must be a dict with a 'type', got {spec!r}")
    kind = spec["type"]
    if kind not in OBSERVATIONS:
        nearest = (
            ": the nearest are topdown (a bird's-eye raster of the road and the traffic), ttc_grid "
            "(time to collision per lane) and lidar"
            if kind == "OccupancyGrid"
            else f" (known: {', '.join(OBSERVATIONS)}; drivelab's own image sensors are topdown, birdeye "
            f"and camera)"
        )
        problems.append(f"observation type {kind!r} has no drivelab sensor{nearest}")
        return None
    if kind == "Kinematics":
        return _kinematics(spec, problems)
    sensor, names = OBSERVATIONS[kind]
    unknown = [key for key in spec if key != "type" and key not in names]
    problems.extend(f"{kind} option {key!r}: no such option in drivelab's {sensor}" for key in unknown)
    options = [f"{names[key]}={value}" for key, value in spec.items() if key in names]
    return ":".join([sensor, *options])


# the features of highway-env's Kinematics that drivelab reads, which a highway-env config may name
# (drivelab's kinematics has these and its own ``accel``)
HIGHWAY_ENV_FEATURES = FEATURES + INTENTION_FEATURES


def _kinematics(spec: dict, problems: list[str]) -> str:
    """drivelab's kinematics spec of highway-env's Kinematics options (see the module docstring)."""
    options = {key: spec[key] for key in ("vehicles_count",) if key in spec}
    features = spec.get("features", KINEMATICS_FEATURES)
    listed = isinstance(features, (list, tuple))
    others = [name for name in features if name not in HIGHWAY_ENV_FEATURES] if listed else 0
    intentions = spec.get("observe_intentions", False)
    if not isinstance(intentions, bool):
        problems.append(f"Kinematics 'observe_intentions' must be true or false, got {intentions!r}")
    elif listed and not intentions and set(features) & set(INTENTION_FEATURES):
        problems.append(
            "Kinematics features cos_d, sin_d without observe_intentions: highway-env writes zeros there, "
            "drivelab's are each vehicle's destination: set observe_intentions: true"
        )
    if others != []:
        own = " (accel is drivelab's own: name it in the sensor spec)" if "accel" in (others or []) else ""
        problems.append(
            f"Kinematics features {features!r}: drivelab reads highway-env's "
            f"{', '.join(HIGHWAY_ENV_FEATURES)}"
            + (f", not {', '.join(map(repr, others))}" if others else "")
            + own
        )
    else:
        options["features"] = "+".join(features)
    normalize, clip = spec.get("normalize", True), spec.get("clip", True)
    for key, value in (("normalize", normalize), ("clip", clip), ("flatten", spec.get("flatten", False))):
        if not isinstance(value, bool):
            problems.append(f"Kinematics {key!r} must be true or false, got {value!r}")
        if value is not True or key == "flatten":  # drivelab's default: true (flatten: highway-env's false)
            options[key] = value
    if spec.get("features_range") is not None and normalize is True:
        options.update(_features_range(spec["features_range"], features, problems))
    for key, (value, why) in KINEMATICS_SAME.items():
        if key in spec and spec[key] != value:
            problems.append(f"Kinematics {key!r} {spec[key]!r}: {why}")
    known = {"type", "features", "normalize", "clip", "flatten", "features_range", "include_obstacles",
             "observe_intentions"}  # fmt: skip
    for key in spec:
        if key not in known | set(KINEMATICS_SAME) | {"vehicles_count"}:
            problems.append(f"Kinematics option {key!r}: no such option in drivelab's kinematics")
    return ":".join(["kinematics", *(f"{key}={_text(value)}" for key, value in options.items())])


def _features_range(ranges: Any, features, problems: list[str]) -> dict[str, float]:
    """``perception_distance_m`` and ``speed_scale_mps`` of a features_range that drivelab's
    scales reproduce: x and y over one symmetric range, vx and vy over another."""
    wanted = {"perception_distance_m": ("x", "y"), "speed_scale_mps": ("vx", "vy")}
    seen = [name for group in wanted.values() for name in group if name in features]
    out: dict[str, float] = {}
    if not isinstance(ranges, dict) or set(ranges) - {"x", "y", "vx", "vy"} or not set(seen) <= set(ranges):
        problems.append(
            f"Kinematics features_range {ranges!r}: drivelab scales x, y by one distance and vx, vy by "
            f"one speed: give x, y: [-d, d] and vx, vy: [-s, s] (d, s in [1, 1000])"
        )
        return out
    for option, group in wanted.items():
        given = [ranges[name] for name in group if name in ranges]
        try:
            pairs = [(float(low), float(high)) for low, high in given]
        except (TypeError, ValueError):
            pairs = [(0.0, 0.0)]
        if not given:
            continue
        low, high = pairs[0]
        if any(pair != pairs[0] for pair in pairs) or low != -high or not 1.0 <= high <= 1000.0:
            problems.append(
                f"Kinematics features_range {', '.join(n for n in group if n in ranges)} {given!r}: drivelab "
                f"scales {' and '.join(group)} by one {option}: give them one range [-d, d], d in "
                f"[1, 1000]"
            )
            continue
        out[option] = high
    return out


def _text(value: Any) -> str:
    """A sensor option's value as the spec syntax reads it (YAML)."""
    return str(value).lower() if isinstance(value, bool) else str(value)


def _action(spec: Any, scene, problems: list[str]) -> tuple[str, dict]:
    """The action kind and its options: ``DiscreteMetaAction``'s ``lateral`` and ``longitudinal``
    (its ``target_speeds`` where they are the scenario's); ``ContinuousAction`` with both
    controls (its ``target_speeds``, which it does not read)."""
    if not isinstance(spec, dict) or spec.get("type") not in ACTIONS:
        raise UsageError(
            f"highway-env 'action' must be a dict with a type of {', '.join(ACTIONS)}, got {spec!r}"
        )
    kind, options = spec["type"], {key: value for key, value in spec.items() if key != "type"}
    speeds = options.pop("target_speeds", None)
    if kind == "DiscreteMetaAction" and speeds is not None:
        own = tuple(scene.meta_target_speeds or HIGHWAY_ENV_TARGET_SPEEDS)
        try:
            same = tuple(float(speed) for speed in speeds) == own
        except (TypeError, ValueError):
            same = False
        if not same:
            problems.append(
                f"DiscreteMetaAction target_speeds {speeds!r}: drivelab's meta-actions step through "
                f"{scene.name}'s speeds {list(own)!r}"
            )
    if kind == "ContinuousAction":
        for key in ("lateral", "longitudinal"):
            if options.pop(key, True) is not True:
                problems.append(
                    f"ContinuousAction {key!r} False: drivelab's continuous action is [acceleration, "
                    f"steering], both controlled: use action 'continuous' (or 'target_speed')"
                )
    allowed = {"lateral", "longitudinal"} if kind == "DiscreteMetaAction" else set()
    if set(options) - allowed:
        problems.append(f"{kind} options {sorted(set(options) - allowed)} are not supported")
    return ACTIONS[kind], {key: value for key, value in options.items() if key in allowed}
