"""Sensor registry, the ``name:key=value`` spec syntax, and frame stacking."""

from __future__ import annotations

import inspect
import math

import numpy as np
import yaml
from gymnasium import spaces

from drivelab.errors import UsageError, like_default
from drivelab.perception.affordances import Affordances
from drivelab.perception.base import Sensor
from drivelab.perception.birdeye import BirdEye
from drivelab.perception.camera import Camera
from drivelab.perception.clock import Clock
from drivelab.perception.ego_state import EgoState
from drivelab.perception.kinematics import Kinematics
from drivelab.perception.lane import LaneState
from drivelab.perception.lidar import Lidar
from drivelab.perception.line import LineState
from drivelab.perception.measurements import Measurements
from drivelab.perception.topdown import TopDown
from drivelab.perception.ttc_grid import TTCGrid
from drivelab.perception.waypoints import Waypoints
from drivelab.world.batch import WorldBatch
from drivelab.yaml_io import YamlLoader

# the sensor registry, declared once: names, options (keyword defaults) and help come from the classes
SENSORS: dict[str, type[Sensor]] = {
    cls.name: cls
    for cls in (Kinematics, Lidar, TopDown, BirdEye, EgoState, Waypoints, Measurements, Camera, LineState)
    + (LaneState, TTCGrid, Affordances, Clock)
}
SENSOR_HELP = {name: cls.help for name, cls in SENSORS.items()}  # one line each, from the class

# One world's observation may hold at most this many values (after frame stacking): 64 MiB as float32.
MAX_OBSERVATION_VALUES = 2**24
# The largest value of each size option: far above any use, and under MAX_OBSERVATION_VALUES.
SIZE_LIMITS = {
    "lidar": {"beams": 100_000},  # spinning lidars give ~360-4000 beams a ring; this is 0.0036° apart
    "topdown": {"size": 1024, "history": 10_000},  # 6 × 1024² values; 10 000 past positions: 17 min
    "birdeye": {"size": 2048},  # 2048² RGB
    "camera": {"width": 2048, "height": 2048},  # 2048² RGB
    "kinematics": {"vehicles_count": 10_000},  # a highway scene has tens of vehicles
    "waypoints": {"count": 100_000},  # 200 km of route at the default 2 m spacing
    # the state has (strips + 1)^4 values, the Q-table that many rows: 41^4 = 2.8 M; wider kernels
    # than the 160 × 120 camera frame erase every line
    "line": {"strips": 40, "kernel_px": 120},
}

# The range of each real-valued option, closed: outside it a sensor's every observation is the same
# (or NaN). Distances from a metre to a kilometre; lidar noise in its normalised distances.
VALUE_RANGES = {
    "kinematics": {"perception_distance_m": (1.0, 1000.0), "speed_scale_mps": (1.0, 1000.0)},
    "lidar": {"range_m": (1.0, 1000.0), "noise_std": (0.0, 1.0)},
    "topdown": {"pixels_per_meter": (0.05, 100.0)},
    "birdeye": {"pixels_per_meter": (0.05, 100.0)},
    "ego_state": {"range_m": (1.0, 1000.0)},
    "waypoints": {"spacing_m": (0.1, 100.0)},
    # fov_deg and pitch_deg: the pinhole model's own ranges (world/pinhole.py)
    "camera": {"height_m": (0.1, 100.0), "forward_m": (-100.0, 100.0), "max_range_m": (1.0, 1000.0)},
    "affordances": {"range_m": (1.0, 1000.0)},
    "clock": {"horizon_s": (0.1, 86400.0)},  # a tenth of a second to a day
}


class FrameStack(Sensor):
    """The last ``frames`` observations of ``sensor`` concatenated along its channel axis; the
    history is a ``(K, frames, …)`` array, and a world's first frame fills its whole stack."""

    def __init__(self, sensor: Sensor, frames: int) -> None:
        if frames < 1:
            raise UsageError(f"stack must be >= 1 for sensor {sensor.name!r}")
        self.sensor, self.frames, self.name = sensor, frames, sensor.name
        self.uses_rng = sensor.uses_rng
        # images stack along their channel axis: first for (C, H, W), last for RGB (H, W, 3)
        rgb = len(sensor.space.shape) == 3 and sensor.space.shape[-1] == 3
        self.axis = -1 if rgb else 0
        inner = sensor.space
        repeat = lambda a: np.concatenate([a] * frames, axis=self.axis)  # noqa: E731
        self._space = spaces.Box(repeat(inner.low), repeat(inner.high), dtype=inner.dtype)
        self._allocate(0)

    def _allocate(self, count: int) -> None:
        shape, dtype = self.sensor.space.shape, self.sensor.space.dtype
        self.history = np.zeros((count, self.frames, *shape), dtype)  # (K, frames, *inner shape)
        self.started = np.zeros(count, dtype=bool)  # per world: a frame was seen this episode

    def scenario_problem(self, scenario) -> str | None:
        return self.sensor.scenario_problem(scenario)

    def reset(self, batch, rngs, mask=None) -> None:
        super().reset(batch, rngs, mask)
        self.sensor.reset(batch, rngs, mask)

    def _reset(self, batch: WorldBatch, mask: np.ndarray) -> None:
        if len(self.started) != batch.num_worlds:
            self._allocate(batch.num_worlds)
        self.started[mask] = False

    def _observe(self, batch: WorldBatch, out: np.ndarray) -> None:
        frame = self.sensor.observe(batch)
        rows = batch.rows  # a sub-batch advances only its own worlds' stacks
        history, started = self.history[rows], self.started[rows]
        history[:, :-1] = np.where(started.reshape((-1,) + (1,) * frame.ndim), history[:, 1:], frame[:, None])
        history[:, -1] = frame
        self.history[rows], self.started[rows] = history, True
        out[...] = np.concatenate(np.moveaxis(history, 1, 0), axis=1 if self.axis == 0 else -1)


def parse_sensor_spec(spec: str | dict) -> tuple[str, dict]:
    """``"lidar:beams=120:stack=3"`` or ``{"name": "lidar", "beams": 120}`` → (name, options)."""
    if isinstance(spec, dict):
        options = dict(spec)
        name = options.pop("name", None)
        if name is None:
            raise UsageError(f"sensor entry {spec!r} has no 'name'")
        return str(name), options
    name, *pairs = str(spec).strip().split(":")
    options = {}
    for pair in pairs:
        key, sep, value = pair.partition("=")
        if not sep:
            raise UsageError(f"sensor option {pair!r} of {name!r} must look like key=value")
        if key.strip() in options:
            raise UsageError(f"sensor {name!r} gives option {key.strip()!r} twice")
        try:
            options[key.strip()] = yaml.load(value, Loader=YamlLoader)
        except yaml.YAMLError:
            raise UsageError(f"sensor option {pair!r} of {name!r}: the value is not valid YAML") from None
    return name.strip(), options


def check_sensor_options(name: str, options: dict) -> tuple[int, dict]:
    """(stack, the sensor's keyword options) with every value of the type the sensor declares;
    an unknown option, a wrong type, a size over ``SIZE_LIMITS``, a value outside ``VALUE_RANGES``
    or ``stack`` < 1 is a UsageError."""
    # each value takes its default's type (a None default: a string, the weights' path): the sensors
    # check ranges, and would fail on a string with an unreadable comparison error
    defaults = {
        key: "" if parameter.default is None else parameter.default
        for key, parameter in inspect.signature(SENSORS[name].__init__).parameters.items()
        if parameter.kind is inspect.Parameter.KEYWORD_ONLY
    }
    checked = {}
    for key, value in options.items():
        if key not in defaults and key != "stack":
            known = ", ".join([*defaults, "stack"])
            raise UsageError(f"unknown option {key!r} for sensor {name!r} (known: {known})")
        checked[key] = like_default(value, defaults.get(key, 1), f"sensor option {key!r} of {name!r}")
    for key, limit in SIZE_LIMITS.get(name, {}).items():
        if key in checked and checked[key] > limit:
            raise UsageError(f"sensor option {key!r} of {name!r} must be <= {limit}, got {checked[key]}")
    for key, (low, high) in VALUE_RANGES.get(name, {}).items():
        if key in checked and not low <= checked[key] <= high:
            raise UsageError(
                f"sensor option {key!r} of {name!r} must lie in [{low:g}, {high:g}], got {checked[key]!r}"
            )
    stack = checked.pop("stack", 1)
    if stack < 1:
        raise UsageError(f"sensor option 'stack' of {name!r} must be >= 1, got {stack}")
    if stack > MAX_OBSERVATION_VALUES:  # the whole stack is checked once the sensor is built
        raise UsageError(
            f"sensor option 'stack' of {name!r} must be <= {MAX_OBSERVATION_VALUES}, got {stack}"
        )
    return stack, checked


def make_sensor(spec: str | dict) -> Sensor:
    """Build one sensor (frame-stacked when ``stack`` > 1) from a spec."""
    name, options = parse_sensor_spec(spec)
    if name not in SENSORS:
        raise UsageError(f"unknown sensor {name!r} (choose from {', '.join(SENSORS)})")
    stack, options = check_sensor_options(name, options)
    try:
        sensor = SENSORS[name](**options)
    except (TypeError, ValueError) as exc:
        raise UsageError(f"bad option for sensor {name!r}: {exc}") from None
    if stack > 1 and not isinstance(sensor.space, spaces.Box):
        raise UsageError(f"sensor {name!r} gives a discrete state, which cannot be frame-stacked")
    values = stack * math.prod(sensor.space.shape)
    if values > MAX_OBSERVATION_VALUES:
        raise UsageError(
            f"sensor {name!r} with stack={stack} gives {values} values per observation, more than "
            f"{MAX_OBSERVATION_VALUES} (fewer frames or a smaller sensor)"
        )
    return FrameStack(sensor, stack) if stack > 1 else sensor


def check_sensors_for(scenario, sensors: list[Sensor]) -> None:
    """Fail when one of ``sensors`` cannot observe ``scenario`` (a ``Scenario``): it would give a
    constant or meaningless observation (``Sensor.scenario_problem``)."""
    for sensor in sensors:
        problem = sensor.scenario_problem(scenario)
        if problem is not None:
            raise UsageError(f"sensor {sensor.name!r} cannot observe scenario {scenario.name!r}: {problem}")


def split_sensor_list(obs: str | list | tuple) -> list:
    """``"lidar,topdown"`` → ["lidar", "topdown"]; lists pass through."""
    items = [s.strip() for s in obs.split(",") if s.strip()] if isinstance(obs, str) else list(obs)
    if not items:
        raise UsageError("no sensor given (--obs)")
    return items
