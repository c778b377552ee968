"""The circuits' whole policy step in one compiled call.

On follow-line and follow-lane the ego drives alone, so a step of the compiled core costs almost
nothing next to the pipeline around it: the WorldBatch export, the rules, each reward term, the
metrics, the sensor and the infos are a dozen Python calls of about a microsecond each, and one
world's step came to ~45 µs of which the simulation is ~1 µs. Like PufferLib's native
environments, :class:`CircuitStep` runs all of it as one compiled call over the K worlds: the
controls, ``advance_worlds`` (the simulator's own step), the scenario's events, the episode rules
(``rules.episode_ends``), every reward term of the circuits' presets (their own kernels:
``segment_columns_into``, ``line_centring_into``, ``lane_keeping_into``), the metrics (``metrics.add_step``)
and the kinematics sensor (``ego_rows_into``). The WorldBatch is made only when something reads it
(``FastSimulator.batch``).

It is the same step as the pipeline's, not a second model of it: the kernels are the pipeline's,
called in its order. Two things differ by rounding only: the cosines and sines of the ego's heading
(numpy's in the pipeline, libm's here; on CPUs where numpy dispatches AVX-512 versions they can
differ in the last bit) and ``steering_power``'s power. The simulation is bit for bit the same, so
events, terminations and episodes are equal; tests/envs/test_fused.py checks both against the
pipeline.

``VectorDriveEnv`` takes it where it applies (:meth:`CircuitStep.of`): a circuit scenario on the
compiled core, the kinematics sensor alone (no frame stack), a reward of the terms below (any
weights, normalised or not, no gate), no rule that needs the history (blocked, off the route), and
at step time the simulator's one-call step (no frame recording, one world or one numba thread).
Elsewhere, and for a step in which a world restarts, ``VectorDriveEnv.step`` runs the stages one by
one.
"""

from __future__ import annotations

import functools
import math

import numpy as np
from numba import njit
from numba.core import types
from numba.experimental import structref

from drivelab.envs.actions import ActionAdapter
from drivelab.envs.metrics import add_step
from drivelab.envs.rules import episode_ends
from drivelab.perception.kinematics import Kinematics, ego_rows_into
from drivelab.rewards.terms import (
    LANE_ROWS,
    LANE_ROWS_PX,
    LINE_ROWS,
    STEERING_BASE,
    lane_keeping_into,
    line_centring_into,
)
from drivelab.sim.core.simulator import (
    ARRIVE_ROUTE_END,
    EX_ARRIVED,
    EX_CRASHED,
    EX_FLOATS,
    EX_HEADING,
    EX_LANE_HEADING,
    EX_LANE_ID,
    EX_ON_ROAD,
    EX_SPEED,
    EX_X,
    EX_Y,
    FastSimulator,
    advance_worlds,
    command_ranges,
    export_vehicle_buffers,
    float_controls,
    set_ego_controls,
)
from drivelab.world.geometry import FULL_LOCK_DEG
from drivelab.world.pinhole import LANE_CAMERA, LINE_CAMERA
from drivelab.world.road_geometry import guide_segment_sets_of, segment_columns_into

# the reward terms the compiled step computes, by code
FUSED_TERMS = ("line_centring", "speed_mps", "steering_power", "lane_keeping")
# the rows of the step's boolean outputs after the export's four flags (EX_ON_ROAD …)
OUT_TERMINATED, OUT_TRUNCATED, OUT_OFF_ROAD, OUT_ARRIVED = 4, 5, 6, 7
# the rows of the step's float outputs after the export's EX_FLOATS: the weighted terms, then the
# rewards, then the clocks, progress and route indices (as floats) for the deferred batch.
# The entries of ``params``:
(P_FRAMES, P_DT, P_DT_POLICY, P_ARRIVAL, P_ARRIVAL_THRESHOLD, P_KEEP_LANE, P_OFFROAD_TERMINAL,
 P_ROWS, P_SPEED_SCALE, P_NORMALIZE, P_LOW, P_HIGH) = range(12)  # fmt: skip
_CAMERA_SIZE = 7  # a pinhole camera's ground_terms


def _cameras() -> np.ndarray:
    """The reward terms' rows and cameras in one array: the line's rows (4), its camera's
    ground_terms (7), the lane's rows (4), their image rows (4), the lane camera's ground_terms."""
    parts = (LINE_ROWS, LINE_CAMERA.ground_terms, LANE_ROWS, LANE_ROWS_PX, LANE_CAMERA.ground_terms)
    return np.concatenate([np.asarray(part, dtype=float) for part in parts])


@njit(cache=True)
def _circuit_step(
    controls, out, out_flags, ints, observations,
    command, v, count, ego, lanes, idm, regulation, time_s, route, starts, segments, lengths2, segment_m,
    stations, point_count, closed, progress, in_junction, exit_lane, start_lane_id, route_length,
    route_polyline, truncate_at_s, params, codes, weights, road_index, guide_starts, guide_ends, cameras,
    vehicles, valid, destinations, accelerations, metric_floats, metric_ints, metric_flags, last_position,
    last_progress, last_length,
) -> None:  # fmt: skip
    """One policy step of K circuit worlds (none restarting), as ``VectorDriveEnv.step`` runs it
    through the pipeline: the controls (``FastSimulator.apply_controls``; ``command`` the rows of
    ``command_ranges``), the simulator's step (``advance_worlds``: frames, clocks, routes, the
    export into ``out[:EX_FLOATS].T``, ``ints`` and ``out_flags[:4].T``), the events
    ``_export_arrays`` derives (off the road, or off the starting lane with ``keep_lane``; the
    route's end), the rules (``terminated``, ``truncated``), the reward terms ``codes`` weighted
    by ``weights`` and summed in their order, normalised when asked, the metrics' step, and the
    kinematics observations. Outputs: ``out_flags`` rows OUT_*; ``out`` rows EX_FLOATS … the
    weighted terms, then the rewards, then the clocks, progress and route indices."""
    num_worlds, terms = time_s.size, codes.size
    floats, flags = out[:EX_FLOATS].T, out_flags[:4].T
    terminated, truncated = out_flags[OUT_TERMINATED], out_flags[OUT_TRUNCATED]
    off_road, arrived = out_flags[OUT_OFF_ROAD], out_flags[OUT_ARRIVED]
    values, rewards = out[EX_FLOATS : EX_FLOATS + terms], out[EX_FLOATS + terms]
    state = out[EX_FLOATS + terms + 1 :]
    set_ego_controls(v, ego, controls, command[0], command[1], command[2])
    frames, arrival, threshold = int(params[P_FRAMES]), int(params[P_ARRIVAL]), params[P_ARRIVAL_THRESHOLD]
    dt_policy = params[P_DT_POLICY]
    advance_worlds(
        v, count, ego, lanes, idm, frames, params[P_DT], regulation, time_s, dt_policy, route, starts,
        segments, lengths2, segment_m, stations, point_count, closed, progress, in_junction, exit_lane,
        arrival, threshold, floats, ints, flags, vehicles, valid, destinations, accelerations,
    )  # fmt: skip
    position = floats[:, EX_X : EX_Y + 1]
    speed, collided = floats[:, EX_SPEED], flags[:, EX_CRASHED]
    keep_lane = params[P_KEEP_LANE] != 0.0
    no_event = np.zeros(num_worlds, dtype=np.bool_)
    kind = np.zeros(num_worlds, dtype=np.int8)  # COLLISION_NONE 0, COLLISION_VEHICLE 1
    scratch = np.empty((6, num_worlds))
    cos_h, sin_h, cos_relative, sin_relative, steering_deg, term = scratch
    for k in range(num_worlds):
        off_road[k] = not flags[k, EX_ON_ROAD] or (keep_lane and ints[k, EX_LANE_ID] != start_lane_id[k])
        if arrival == ARRIVE_ROUTE_END:
            arrived[k] = route_length[route[k]] - progress[k] < threshold
        else:
            arrived[k] = flags[k, EX_ARRIVED]
        kind[k] = 1 if collided[k] else 0
        heading = floats[k, EX_HEADING]
        cos_h[k], sin_h[k] = math.cos(heading), math.sin(heading)
        relative = heading - floats[k, EX_LANE_HEADING]
        cos_relative[k], sin_relative[k] = math.cos(relative), math.sin(relative)
        steering_deg[k] = np.float64(controls[k, 1]) * FULL_LOCK_DEG  # _steering_deg
        rewards[k] = 0.0
        state[0, k], state[1, k], state[2, k] = time_s[k], progress[k], route[k]
    episode_ends(
        collided, arrived, no_event, no_event, no_event, off_road, params[P_OFFROAD_TERMINAL] != 0.0, time_s,
        truncate_at_s, terminated, truncated,
    )  # fmt: skip
    line_rows, line_terms, lane = cameras[0:4], cameras[4 : 4 + _CAMERA_SIZE], cameras[4 + _CAMERA_SIZE :]
    lane_rows, lane_rows_px, lane_terms = lane[0:4], lane[4:8], lane[8 : 8 + _CAMERA_SIZE]
    for t in range(terms):  # each term's (K,) values, weighted, summed in the spec's order
        code = codes[t]
        if code == 0:  # line_centring
            columns = np.empty((num_worlds, line_rows.size))
            segment_columns_into(
                guide_starts, guide_ends, road_index, position, cos_h, sin_h, line_rows, line_terms, columns
            )
            line_centring_into(columns, line_terms[0], line_terms[6], term)
        elif code == 1:  # speed_mps
            term[:] = speed
        elif code == 2:  # steering_power
            for k in range(num_worlds):
                term[k] = STEERING_BASE ** abs(steering_deg[k])
        else:  # lane_keeping
            columns = np.empty((num_worlds, lane_rows.size))
            segment_columns_into(
                route_polyline[:, :-1], route_polyline[:, 1:], route, position, cos_h, sin_h, lane_rows,
                lane_terms, columns,
            )  # fmt: skip
            lane_keeping_into(columns, lane_rows_px, lane_terms[0], lane_terms[6], steering_deg, term)
        for k in range(num_worlds):
            values[t, k] = weights[t] * term[k]
            rewards[k] += values[t, k]
    if params[P_NORMALIZE] != 0.0:
        low, high = params[P_LOW], params[P_HIGH]
        for k in range(num_worlds):
            rewards[k] = (rewards[k] - low) / (high - low)
    add_step(
        metric_floats, metric_ints, metric_flags, last_position, rewards, position, speed, collided, kind,
        off_road, no_event, no_event, arrived,
    )  # fmt: skip
    for k in range(num_worlds):
        last_progress[k] = progress[k]
        last_length[k] = route_length[route[k]]
    rows = np.zeros((num_worlds, int(params[P_ROWS]), 7))
    ego_rows_into(rows, speed, cos_relative, sin_relative, params[P_SPEED_SCALE], True, observations)


# what circuit_step reads and updates in place besides its per-step arrays: one object, so that a
# call passes a handful of arguments (numba's dispatch costs ~50 ns per argument, and there are 40)
_HELD = (
    "command", "v", "count", "ego", "lanes", "idm", "regulation", "time_s", "route", "starts",
    "segments", "lengths2", "segment_m", "stations", "point_count", "closed", "progress",
    "in_junction", "exit_lane", "start_lane_id", "route_length", "route_polyline", "truncate_at_s",
    "params", "codes", "weights", "road_index", "guide_starts", "guide_ends", "cameras", "vehicles",
    "valid", "destinations", "accelerations", "metric_floats", "metric_ints", "metric_flags",
    "last_position", "last_progress", "last_length",
)  # fmt: skip


@structref.register
class _HeldType(types.StructRef):
    def preprocess_fields(self, fields):
        return tuple((name, types.unliteral(typ)) for name, typ in fields)


class _Held(structref.StructRefProxy):
    """The arrays of ``_HELD`` as one numba object (a StructRef: references, not copies)."""


structref.define_proxy(_Held, _HeldType, list(_HELD))


@njit(cache=True)
def circuit_step(controls, out, out_flags, ints, observations, held) -> None:
    """``_circuit_step`` with the arrays of ``held`` (a ``_Held``)."""
    _circuit_step(
        controls, out, out_flags, ints, observations, held.command, held.v, held.count, held.ego,
        held.lanes, held.idm, held.regulation, held.time_s, held.route, held.starts, held.segments,
        held.lengths2, held.segment_m, held.stations, held.point_count, held.closed, held.progress,
        held.in_junction, held.exit_lane, held.start_lane_id, held.route_length, held.route_polyline,
        held.truncate_at_s, held.params, held.codes, held.weights, held.road_index, held.guide_starts,
        held.guide_ends, held.cameras, held.vehicles, held.valid, held.destinations, held.accelerations,
        held.metric_floats, held.metric_ints, held.metric_flags, held.last_position, held.last_progress,
        held.last_length,
    )  # fmt: skip


class CircuitStep:
    """The compiled step of one VectorDriveEnv on a circuit (see the module docstring)."""

    @classmethod
    def of(cls, env) -> CircuitStep | None:
        """The compiled step for ``env`` (a VectorDriveEnv), or None where the pipeline must run."""
        simulator, spec = env.simulator, env.reward_shaper.spec
        fits = (
            type(simulator) is FastSimulator
            and env.scenario.circuit
            and simulator.control == "continuous"
            and type(env.adapter).controls_for is ActionAdapter.controls_for  # no feedback loop
            and len(env.sensors) == 1
            and type(env.sensors[0]) is Kinematics
            and env.sensors[0].plain  # its default layout: every feature, flat, normalised
            and spec.gate is None
            and all(name in FUSED_TERMS for name in spec.weights)
            and env.rules.blocked_after_s is None
            and env.rules.route_deviation_m is None
        )
        return cls(env) if fits else None

    def __init__(self, env) -> None:
        self.env = env
        sim = self.simulator = env.simulator
        spec = env.reward_shaper.spec
        self.names = tuple(spec.weights)
        self.codes = np.array([FUSED_TERMS.index(name) for name in self.names], dtype=np.int64)
        self.weights = np.array([float(spec.weights[name]) for name in self.names])
        self.sensor: Kinematics = env.sensors[0]
        low, high = spec.normalize if spec.normalize is not None else (0.0, 1.0)
        self.params = np.array([
            sim.frames, sim.dt_s, sim.dt_policy_s, sim.arrival, sim.arrival_threshold,
            sim.scenario.keep_lane, env.rules.offroad_terminal, self.sensor.vehicles_count,
            self.sensor.speed_scale_mps,
            spec.normalize is not None, low, high,
        ], dtype=float)  # fmt: skip
        self.cameras = _cameras()
        self._rewards_row = EX_FLOATS + len(self.names)
        self._control_type = np.dtype(np.float32)  # the adapters' controls
        self._num_worlds = sim.num_worlds
        self._observation_shape = (sim.num_worlds, *self.sensor.space.shape)
        self._key: tuple | None = None  # what ``_held``'s arrays were taken from
        self._arrays: tuple = ()
        self._held_object: _Held | None = None

    def __getstate__(self) -> dict:
        """Pickled without the numba object of ``_held`` (it is made again at the next step)."""
        return {**self.__dict__, "_key": None, "_arrays": (), "_held_object": None}

    def ready(self) -> bool:
        """The simulator steps in one call now (not recording frames; one world or one thread)."""
        return self.simulator.one_call

    def _guide_segments(self) -> tuple[np.ndarray, np.ndarray]:
        """The guide lines' segment starts and ends of the simulator's roads (one set per road,
        NaN-padded: ``guide_segment_sets``)."""
        if "line_centring" not in self.names:
            return np.full((1, 1, 2), np.nan), np.full((1, 1, 2), np.nan)
        sets = guide_segment_sets_of(self.simulator.roads)
        return sets[:, :, 0], sets[:, :, 1]

    def _held(self) -> tuple:
        """The arrays ``circuit_step`` reads and updates in place, after its per-step ones. Kept
        while they are the same objects: the simulator replaces its vehicle and route arrays, the
        rules their limits and the metrics their accumulators only when episodes start."""
        sim, env = self.simulator, self.env
        metrics, rules = env.metrics, env.rules
        key = self._key
        if (
            key is not None
            and key[0] is sim.vehicles
            and key[1] is sim.r_polyline
            and key[2] is sim.roads
            and key[3] is rules.truncate_at_s
            and key[4] is metrics.accumulators[0]
        ):
            return self._arrays
        key = (sim.vehicles, sim.r_polyline, sim.roads, rules.truncate_at_s, metrics.accumulators[0])
        # the batch's road_index: each world's route where a guide line is painted along it
        road_index = sim.route_index if sim.scenario.guide_line else np.zeros(sim.num_worlds, dtype=np.int64)
        slots = max(sim.vehicles.shape[1] - 1, 0)  # the export's other vehicles
        if slots:  # (their arrays below are shared by every step's batch: empty ones only)
            raise NotImplementedError("the compiled circuit step drives the ego alone")
        k = sim.num_worlds
        arrays = (
            _command_rows(self._control_type), sim.vehicles, sim.count, sim.ego, sim.lanes, sim.idm,
            sim.regulation, sim.time_s, sim.route_index, sim.r_starts, sim.r_segments, sim.r_lengths2,
            sim.r_segment_m, sim.r_stations, sim.r_count, sim.r_closed, sim.progress_m, sim.in_junction,
            sim.exit_lane, sim.start_lane_id, sim.r_length, sim.r_polyline, rules.truncate_at_s,
            self.params, self.codes, self.weights, road_index, *self._guide_segments(), self.cameras,
            *export_vehicle_buffers(k, slots), *metrics.accumulators,
            metrics.last_position, metrics.last_progress_m, metrics.last_route_length_m,
        )  # fmt: skip
        self._arrays, self._held_object = arrays, _Held(*arrays)
        self._key = key
        return self._arrays

    def step(self, controls: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """One step of every world: ``(observations, out, out_flags)``, ``circuit_step``'s
        outputs (``rewards(out)``, ``terms(out)``; ``out_flags`` rows OUT_*). The simulator's
        batch is left to be made when read."""
        k = self._num_worlds
        if (
            type(controls) is not np.ndarray
            or controls.shape != (k, 2)
            or controls.dtype != self._control_type
        ):
            controls = float_controls(controls, k)
            if controls.dtype != self._control_type:
                self._control_type, self._key = controls.dtype, None
        # every entry of these but the export's flags is written by every step
        out, ints = np.empty((self._rewards_row + 4, k)), np.empty((3, k), dtype=np.int64)
        out_flags, observations = np.zeros((8, k), dtype=bool), np.empty(self._observation_shape, np.float32)
        held = self._held()
        circuit_step(controls, out, out_flags, ints.T, observations, self._held_object)
        vehicles = held[-10:-6]  # vehicles, valid, destinations, accelerations: shared by every batch
        self.simulator.defer_batch(functools.partial(_export_parts, out, ints, out_flags, vehicles))
        return observations, out, out_flags

    def ends(self, out_flags: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """A step's terminated and truncated (K,)."""
        return out_flags[OUT_TERMINATED], out_flags[OUT_TRUNCATED]

    def events(self, out: np.ndarray, out_flags: np.ndarray) -> tuple[np.ndarray, ...]:
        """A step's speed, crashed, off_road and arrived (K,), the infos' own arrays."""
        speed, crashed = out[EX_SPEED].copy(), out_flags[EX_CRASHED].copy()  # (the batch's: copied)
        return speed, crashed, out_flags[OUT_OFF_ROAD], out_flags[OUT_ARRIVED]

    def world_step(self, out: np.ndarray, out_flags: np.ndarray) -> tuple[dict, float, bool, bool]:
        """World 0's ``(info, reward, terminated, truncated)`` as Python values; the info holds
        ``VectorDriveEnv``'s ``reward_terms``, ``speed_mps``, ``crashed``, ``off_road`` and ``arrived``."""
        values = out[EX_FLOATS : self._rewards_row, 0].tolist()
        flags = out_flags[:, 0].tolist()
        info = {
            "reward_terms": dict(zip(self.names, values, strict=True)),
            "speed_mps": out[EX_SPEED, 0].item(),
            "crashed": flags[EX_CRASHED],
            "off_road": flags[OUT_OFF_ROAD],
            "arrived": flags[OUT_ARRIVED],
        }
        return info, out[self._rewards_row, 0].item(), flags[OUT_TERMINATED], flags[OUT_TRUNCATED]

    def rewards(self, out: np.ndarray) -> np.ndarray:
        return out[self._rewards_row]

    def terms(self, out: np.ndarray) -> dict[str, np.ndarray]:
        """The weighted terms (K,) of a step, by name."""
        return dict(zip(self.names, out[EX_FLOATS : self._rewards_row], strict=True))


@functools.cache
def _command_rows(dtype: np.dtype) -> np.ndarray:
    """``command_ranges(dtype)`` as the rows of one (3, 2) array."""
    return np.stack(command_ranges(dtype))


def _export_parts(out, ints, out_flags, vehicles) -> tuple:
    """``FastSimulator._export_arrays``' arguments from ``circuit_step``'s outputs (``vehicles``:
    the export's vehicles, valid, destinations and accelerations)."""
    state = out[-3:]
    route_index = state[2].astype(np.int64)
    return out[:EX_FLOATS].T, ints.T, out_flags[:4].T, *vehicles, (state[0], state[1], route_index)
