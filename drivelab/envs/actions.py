"""Action adapters: the agent's action space → the backend's controls.

Backends take either a meta-action index (highway-env's 5 meta-actions, executed by its
lane-keeping and speed controllers) or a normalised continuous control ``[acceleration,
steering]`` in [-1, 1] (highway-env maps it to ±5 m/s² and ±45°).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from gymnasium import spaces
from numba import njit

from drivelab.errors import UsageError
from drivelab.world.batch import WorldBatch
from drivelab.world.geometry import FULL_ACCELERATION_MPS2, ROACH_MAX_SPEED_MPS
from drivelab.world.scenario import META_ACTIONS
from drivelab.world.state import WorldState


def _indices(actions, size: int) -> np.ndarray:
    """(K,) integer actions of a Discrete(size) space, checked: integers (as gymnasium's
    ``Discrete.contains`` takes them, and a bool not, which is a flag, not an index) in [0, size)."""
    values = np.asarray(actions).reshape(-1)
    if values.dtype.kind not in "iu":  # 2.7 would truncate to 2, True to 1, nan to a huge index
        raise ValueError(
            f"action {values[0].item()!r} of Discrete({size}) is not an integer ({values.dtype} actions)"
        )
    indices = values.astype(np.int64, copy=False)
    wrong = (indices < 0) | (indices >= size)
    if wrong.any():
        raise ValueError(f"action {int(indices[wrong][0])} is outside Discrete({size})")
    return indices


def _non_finite(rows: np.ndarray) -> ValueError:
    """The error for continuous actions (K, 2) of which one is NaN or infinite."""
    row = rows[~np.isfinite(rows).all(axis=1)][0]
    return ValueError(f"continuous action {row.tolist()} is not finite (NaN or infinite)")


class ActionAdapter:
    """Maps the agents' actions of K worlds to backend controls: meta-action indices ``(K,)`` or
    normalised ``[acceleration, steering]`` rows ``(K, 2)``. ``control`` says which kind the
    backend runs. ``to_control`` / ``control_for`` are the one-world forms (tests, notebooks)."""

    name: str = "adapter"
    control: str = "continuous"
    space: spaces.Space

    def to_controls(self, actions) -> np.ndarray:
        """The controls for a batch of actions (K, …) that need no world state."""
        raise NotImplementedError

    def controls_for(self, actions, batch: WorldBatch) -> np.ndarray:
        """The controls for ``actions`` (K, …) in ``batch`` (the worlds before the step). Adapters
        with a feedback loop read the worlds; the others only map the actions."""
        return self.to_controls(actions)

    def to_control(self, action) -> int | np.ndarray:
        """One world's control for one action."""
        return self.to_controls(np.asarray(action)[None])[0]

    def control_for(self, action, world: WorldState) -> int | np.ndarray:
        """One world's control for ``action`` in ``world`` (the state before the step)."""
        return self.controls_for(np.asarray(action)[None], WorldBatch.stack([world]))[0]

    def reset(self, mask: np.ndarray | None = None) -> None:
        """Forget any controller state of the worlds where ``mask`` (default: all) at the start of
        their episode."""

    def describe(self) -> str:
        raise NotImplementedError


class MetaAction(ActionAdapter):
    """highway-env's meta-actions (``DiscreteMetaAction``): change lane left/right, idle, faster, slower.

    As highway-env's, ``lateral=False`` keeps the longitudinal three (slower, idle, faster: its
    intersection's action space) and ``longitudinal=False`` the lateral three (lane left, idle, lane
    right); action ``i`` is ``names[i]``, in highway-env's order for each set.

    :param lateral: the lane changes are actions.
    :param longitudinal: the speed changes are actions.
    """

    name, control = "meta", "meta"

    def __init__(self, lateral: bool = True, longitudinal: bool = True) -> None:
        if not isinstance(lateral, bool) or not isinstance(longitudinal, bool):
            raise UsageError("meta action options lateral and longitudinal take true or false")
        if lateral and longitudinal:
            self.names = META_ACTIONS
        elif longitudinal:
            self.names = ("SLOWER", "IDLE", "FASTER")
        elif lateral:
            self.names = ("LANE_LEFT", "IDLE", "LANE_RIGHT")
        else:
            raise UsageError("meta action needs lateral or longitudinal actions (both are false)")
        self.table = np.array([META_ACTIONS.index(n) for n in self.names], dtype=np.int64)  # → META index
        self.space = spaces.Discrete(len(self.names))

    def to_controls(self, actions) -> np.ndarray:
        return self.table[_indices(actions, len(self.names))]

    def describe(self) -> str:
        if len(self.names) == len(META_ACTIONS):
            return "5 highway-env meta-actions (lane left, idle, lane right, faster, slower)"
        return f"{len(self.names)} highway-env meta-actions ({', '.join(n.lower() for n in self.names)})"


@dataclass(frozen=True)
class GridAction(ActionAdapter):
    """A discretised (steering × acceleration) grid, 6 × 3 = 18 actions by default (the MetaDrive study).

    Steering levels are ``sign(u)·u²`` for ``u`` evenly spaced in [-1, 1] so that the grid holds
    fine near-straight corrections (±1.8° at the default) and full lock (±45°) alike; the seed
    does not state its levels, this choice is ours. Action ``i`` is steering level ``i // accel``
    and acceleration level ``i % accel``.
    """

    steer_levels: int = 6
    accel_levels: int = 3
    name: str = "grid"
    control: str = "continuous"

    def __post_init__(self) -> None:
        if self.steer_levels < 2 or self.accel_levels < 1:
            raise UsageError("grid action needs steer_levels >= 2 and accel_levels >= 1")
        u = np.linspace(-1.0, 1.0, self.steer_levels)
        steer = np.sign(u) * u**2
        accel = np.linspace(-1.0, 1.0, self.accel_levels) if self.accel_levels > 1 else np.zeros(1)
        grid = np.array([[a, s] for s in steer for a in accel], dtype=np.float32)
        object.__setattr__(self, "table", grid)  # rows: [acceleration, steering]
        object.__setattr__(self, "space", spaces.Discrete(len(grid)))

    def to_controls(self, actions) -> np.ndarray:
        return self.table[_indices(actions, len(self.table))]

    def describe(self) -> str:
        return f"{len(self.table)} (steering x acceleration) pairs, {self.steer_levels} x {self.accel_levels}"


class ContinuousAction(ActionAdapter):
    """Continuous ``[steering, acceleration]`` in [-1, 1] (the order the seeds use)."""

    name, control = "continuous", "continuous"

    def __init__(self) -> None:
        self.space = spaces.Box(-1.0, 1.0, shape=(2,), dtype=np.float32)

    def to_controls(self, actions) -> np.ndarray:
        rows = np.asarray(actions, dtype=np.float32).reshape(-1, 2)
        controls = np.empty_like(rows)
        if not _clipped_swapped(rows, controls):
            raise _non_finite(rows)
        return controls

    def describe(self) -> str:
        return "continuous [steering, acceleration] in [-1, 1] (±45°, ±5 m/s²)"


@njit(cache=True)
def _clipped_swapped(rows, out) -> bool:
    """``[steering, acceleration]`` rows (K, 2) clipped to [-1, 1] and swapped into ``out`` as
    ``[acceleration, steering]``, highway-env's order; False when a value is NaN or infinite (an
    infinity would clip to a valid control, hiding a broken policy), checked in the same pass."""
    finite = True
    for k in range(rows.shape[0]):
        for column in range(2):
            value = rows[k, column]
            finite &= np.isfinite(value)
            if value < -1.0:
                value = -1.0
            elif value > 1.0:
                value = 1.0
            out[k, 1 - column] = value
    return finite


@njit(cache=True)
def _all_finite(rows) -> bool:
    """Whether no value of ``rows`` (K, 2) is NaN or infinite (a third of np.isfinite(...).all()'s
    cost per step, which is mostly its Python wrappers)."""
    for k in range(rows.shape[0]):
        for column in range(rows.shape[1]):
            if not np.isfinite(rows[k, column]):
                return False
    return True


class TargetSpeedAction(ActionAdapter):
    """``[target speed, steering]`` in [0, 1] × [-1, 1]: the agent picks a speed (a fraction of
    ``max_speed_mps``) and a steering command; a longitudinal PID turns the speed error into the
    acceleration command, as RLAD does for throttle and brake (the RLAD paper; gains kp 1.0, ki 0.2,
    kd 0.001 per the paper's code). The PID output is the normalised acceleration in [-1, 1]
    (highway-env's ±5 m/s²) where CARLA has throttle (> 0) and brake (< 0).

    :param max_speed_mps: the target speed at action 1 (RLAD / Roach: 6 m/s).
    :param stop_below: a stop zone: a speed action below this fraction stops the ego and holds it
        still (the command brakes just hard enough to stop within the step, never reverses, and
        the PID's memory is cleared), and [stop_below, 1] spans the speeds 0 to ``max_speed_mps``.
        Roach's acceleration action brakes on the lower half of its range (0, the default: no
        zone, the PID's target is ``action · max_speed_mps``).
    """

    name, control = "target_speed", "continuous"

    def __init__(
        self, max_speed_mps: float = ROACH_MAX_SPEED_MPS, kp: float = 1.0, ki: float = 0.2, kd: float = 0.001,
        stop_below: float = 0.0,
    ) -> None:  # fmt: skip
        if max_speed_mps <= 0:
            raise UsageError("target_speed needs max_speed_mps > 0")
        if not 0.0 <= stop_below < 1.0:
            raise UsageError(f"target_speed needs 0 <= stop_below < 1, got {stop_below!r}")
        self.max_speed_mps, self.kp, self.ki, self.kd = float(max_speed_mps), kp, ki, kd
        self.stop_below = float(stop_below)
        self.space = spaces.Box(np.array([0.0, -1.0], np.float32), np.array([1.0, 1.0], np.float32))
        self.reset()

    def reset(self, mask: np.ndarray | None = None) -> None:
        if mask is None or len(mask) != len(self.integral):  # all worlds, or a new number of them
            size = 0 if mask is None else len(mask)
            self.integral, self.previous_error = np.zeros(size), np.full(size, np.nan)
            return
        self.integral[mask], self.previous_error[mask] = 0.0, np.nan

    def pid(self, target_mps: np.ndarray, speed_mps: np.ndarray, dt_s: float) -> np.ndarray:
        """One PID update per world: the normalised accelerations (K,) that drive ``speed_mps``
        to ``target_mps``."""
        target_mps, speed_mps = np.atleast_1d(target_mps), np.atleast_1d(speed_mps)
        if self.integral.shape != speed_mps.shape:  # a new number of worlds: fresh controllers
            self.integral, self.previous_error = np.zeros(speed_mps.shape), np.full(speed_mps.shape, np.nan)
        error = target_mps - speed_mps
        self.integral = self.integral + error * dt_s
        derivative = np.where(np.isnan(self.previous_error), 0.0, (error - self.previous_error) / dt_s)
        self.previous_error = error
        return np.clip(self.kp * error + self.ki * self.integral + self.kd * derivative, -1.0, 1.0)

    def controls_for(self, actions, batch: WorldBatch) -> np.ndarray:
        rows = np.asarray(actions, dtype=np.float32).reshape(-1, 2)
        if not _all_finite(rows):
            raise _non_finite(rows)
        rows = np.clip(rows, [0.0, -1.0], 1.0)
        fraction = rows[:, 0].astype(float)
        if not self.stop_below:
            accel = self.pid(fraction * self.max_speed_mps, batch.ego.speed_mps, batch.dt_s)
            return np.stack([accel, rows[:, 1]], axis=1).astype(np.float32)  # highway-env's order
        stop = fraction < self.stop_below
        target = np.maximum(fraction - self.stop_below, 0.0) / (1.0 - self.stop_below) * self.max_speed_mps
        speed = np.atleast_1d(batch.ego.speed_mps)
        accel = self.pid(target, speed, batch.dt_s)
        if stop.any():  # to a standstill within the step, and held there
            self.integral[stop], self.previous_error[stop] = 0.0, np.nan
            accel[stop] = np.clip(-speed[stop] / (FULL_ACCELERATION_MPS2 * batch.dt_s), -1.0, 1.0)
        return np.stack([accel, rows[:, 1]], axis=1).astype(np.float32)

    def to_controls(self, actions) -> np.ndarray:
        raise UsageError("target_speed actions need the world's speed: call control_for(action, world)")

    def describe(self) -> str:
        zone = f", below {self.stop_below:g}: stop" if self.stop_below else ""
        speeds = f"target speed 0..{self.max_speed_mps:g} m/s through a PID{zone}"
        return f"[{speeds}, steering] in [0, 1] x [-1, 1]"


# the CARLA study's action tables, rows (throttle, steering) in CARLA's normalised units
SEED_LINE_TABLE = ((0.32, -0.2), (0.7, 0.0), (0.32, 0.2), (0.2, -0.4), (0.2, 0.4))
SEED_LANE_TABLE = ((0.35, -0.04), (0.35, 0.04), (0.3, -0.08), (0.6, 0.0), (0.3, 0.08))


class SeedTable(ActionAdapter):
    """One of the CARLA study's two 5-action (throttle, steering) tables.

    Throttle ``t`` becomes the normalised acceleration command ``t`` (a 5·t m/s² pedal; the
    follow-line/lane ego adds a speed drag so that a constant throttle levels off, see
    ``scenarios/circuits/reference_env.py``); steering ``s`` (CARLA's [-1, 1], negative left) becomes the
    normalised steering ``s``, i.e. ``s``·45° at the front wheels (highway-env's full lock).

    :param table: ``"line"`` (follow-line, section 3.2) or ``"lane"`` (follow-lane, section 4.2).
    """

    control = "continuous"

    def __init__(self, table: str) -> None:
        rows = {"line": SEED_LINE_TABLE, "lane": SEED_LANE_TABLE}[table]
        self.name = f"seed_{table}"
        self.table = np.array(rows, dtype=np.float32)
        self.space = spaces.Discrete(len(rows))

    def to_controls(self, actions) -> np.ndarray:
        return self.table[_indices(actions, len(self.table))]  # [acceleration, steering], highway-env's order

    def describe(self) -> str:
        rows = ", ".join(f"({t:g}, {s:+g})" for t, s in self.table.tolist())
        return f"the CARLA study's {self.name[5:]} table of 5 (throttle, steering): {rows}"


ACTIONS = {
    "meta": MetaAction,
    "grid": GridAction,
    "continuous": ContinuousAction,
    "target_speed": TargetSpeedAction,
    "seed_line": lambda: SeedTable("line"),
    "seed_lane": lambda: SeedTable("lane"),
}


def make_action(name: str, **options) -> ActionAdapter:
    """Build the adapter called ``name`` with keyword ``options``."""
    if name not in ACTIONS:
        raise UsageError(f"unknown action kind {name!r} (choose from {', '.join(ACTIONS)})")
    try:
        return ACTIONS[name](**options)
    except TypeError as exc:
        raise UsageError(f"bad option for action {name!r}: {exc}") from None
