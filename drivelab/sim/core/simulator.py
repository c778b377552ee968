"""FastSimulator: K worlds of one scenario stepped, reset and exported as arrays.

Every world's vehicles live in one ``(K, N_max, VEHICLE_COLUMNS)`` buffer with a per-world count
(rows past it are zeros) and the row of its ego. A step applies the K controls, runs
``traffic.simulate_worlds``, the scenario's arrivals and departures, the route projections and
the export into a :class:`~drivelab.world.batch.WorldBatch`, all compiled loops over worlds.

The road (``_Road``: lane arrays, road map, ego routes, shortest paths, the vehicle classes'
constants) is converted once per scenario and configuration and shared by its simulators; every
episode is set up by the scenario's spawner (``Scenario.spawn`` or ``spawn_many``), with the same
draws from the same seed as highway-env's ``_make_vehicles``.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from collections.abc import Callable
from dataclasses import dataclass

import numba
import numpy as np
from highway_env import utils as hw_utils
from highway_env.road.regulation import RegulatedRoad
from highway_env.vehicle.behavior import IDMVehicle
from highway_env.vehicle.controller import ControlledVehicle, MDPVehicle
from highway_env.vehicle.kinematics import Vehicle
from highway_env.vehicle.objects import Obstacle
from numba import njit

from drivelab._numba_cache import compile_notice
from drivelab.errors import UsageError
from drivelab.sim.core import lanes as L
from drivelab.sim.core import traffic as T
from drivelab.sim.core.spawn import LaneGeometry, all_shortest_paths
from drivelab.sim.reference.highway import HighwayBackend, build_road_map, is_idm_class
from drivelab.sim.roads.description import RoadDescription
from drivelab.sim.route import SEARCH_WINDOW_M, WINDOW_PENALTY_M, RouteTracker
from drivelab.world.batch import (
    COLLISION_NONE,
    COLLISION_VEHICLE,
    EgoBatch,
    EventsBatch,
    RouteBatch,
    WorldBatch,
    assemble,
)
from drivelab.world.geometry import FULL_ACCELERATION_MPS2, FULL_LOCK_RAD
from drivelab.world.scenario import Scenario
from drivelab.world.state import RoadMap

LANE_LEFT, IDLE, LANE_RIGHT, FASTER, SLOWER = range(5)
ACCELERATION_RANGE = (-FULL_ACCELERATION_MPS2, FULL_ACCELERATION_MPS2)  # ContinuousAction's
STEERING_RANGE = (-FULL_LOCK_RAD, FULL_LOCK_RAD)

# ``Scenario.arrival`` → (rule, threshold). ARRIVE_PAST_X: the ego's x beyond ``Scenario.arrival_x_m``
# (the merge's end); ARRIVE_EXIT: on an exit lane at least the threshold along it
# (IntersectionEnv.has_arrived); ARRIVE_ROUTE_END: less than the threshold of the ego's route left.
ARRIVE_NEVER, ARRIVE_PAST_X, ARRIVE_EXIT, ARRIVE_ROUTE_END = 0, 1, 2, 3
ARRIVAL_RULES = {
    "none": (ARRIVE_NEVER, 0.0),
    "merge_end": (ARRIVE_PAST_X, None),
    "exit": (ARRIVE_EXIT, 25.0),
    "route_end": (ARRIVE_ROUTE_END, 2.0),
}

# Columns of the export kernel's float, int and flag outputs; the lane's turn over the 2 m around the
# ego as its cosine and sine (highway-env takes the angle of exp(1j * turn)).
(
    EX_X, EX_Y, EX_HEADING, EX_SPEED, EX_STEER, EX_ACCEL, EX_LEN, EX_WID, EX_LANE_WIDTH, EX_LATERAL,
    EX_LANE_HEADING, EX_SPEED_LIMIT, EX_TURN_COS, EX_TURN_SIN,
) = range(14)  # fmt: skip
EX_FLOATS = 14
EX_LANE_ID, EX_LANE_COUNT, EX_TARGET_LANE_ID = range(3)
EX_ON_ROAD, EX_IN_JUNCTION, EX_CRASHED, EX_ARRIVED = range(4)
EXPORTED_COLUMNS = np.array([T.X, T.Y, T.HEADING, T.SPEED, T.LEN, T.WID])  # WorldState.vehicles


def vehicles_to_array(
    vehicles: list, table: L.LaneTable, objects: list = (), town_class: type | None = None
) -> np.ndarray:
    """highway-env vehicles, then its obstacles → rows of ``traffic.VEHICLE_COLUMNS``, in order.

    :param town_class: the reference's town vehicle class (``TownVehicle``): its vehicles become
        KIND ``TOWN`` rows, and every row is ``TOWN_VEHICLE_COLUMNS`` wide (the town's long routes).
    """
    row_of = table.row_of
    columns, max_route = (
        (T.VEHICLE_COLUMNS, T.MAX_ROUTE) if town_class is None else (T.TOWN_VEHICLE_COLUMNS, T.TOWN_MAX_ROUTE)
    )
    array = np.zeros((len(vehicles) + len(objects), columns))
    for i, vehicle in enumerate(vehicles):
        town = town_class is not None and type(vehicle) is town_class
        if isinstance(vehicle, IDMVehicle) and not (town or is_idm_class(type(vehicle))):
            raise NotImplementedError(f"the fast backend has no {type(vehicle).__name__}")
        row = array[i]
        row[T.X], row[T.Y] = vehicle.position
        row[T.HEADING], row[T.SPEED] = vehicle.heading, vehicle.speed
        row[T.STEER] = vehicle.action.get("steering", 0.0)
        row[T.ACCEL] = vehicle.action.get("acceleration", 0.0)
        row[T.LANE] = row_of[vehicle.lane_index]
        row[T.TARGET_LANE] = row_of[getattr(vehicle, "target_lane_index", vehicle.lane_index)]
        row[T.TARGET_SPEED] = getattr(vehicle, "target_speed", 0.0)
        row[T.DELTA] = getattr(vehicle, "DELTA", IDMVehicle.DELTA)
        row[T.TIMER] = getattr(vehicle, "timer", 0.0)
        row[T.CRASHED] = float(vehicle.crashed)
        row[T.CHECK_COLLISIONS] = float(vehicle.check_collisions)
        row[T.LEN], row[T.WID] = vehicle.LENGTH, vehicle.WIDTH
        row[T.WRECKED_S] = getattr(vehicle, "wrecked_s", 0.0)
        row[T.PEDAL] = getattr(vehicle, "pedal_mps2", 0.0)
        if town:
            row[T.KIND] = T.TOWN
        elif isinstance(vehicle, IDMVehicle):
            row[T.KIND] = T.IDM
        elif isinstance(vehicle, ControlledVehicle):
            row[T.KIND] = T.CONTROLLED
        elif isinstance(vehicle, Vehicle):
            row[T.KIND] = T.PLAIN
        route = getattr(vehicle, "route", None)
        row[T.ROUTED] = float(route is not None)
        row[T.YIELDING] = float(getattr(vehicle, "is_yielding", False))
        route = route or []
        if len(route) > max_route:
            raise NotImplementedError(f"the fast backend keeps routes of at most {max_route} roads")
        row[T.ROUTE_END] = len(route)
        for k, (_from, _to, lane_id) in enumerate(route):
            row[T.ROUTE + 2 * k] = table.road_of(_from, _to)
            row[T.ROUTE + 2 * k + 1] = -1 if lane_id is None else lane_id
    for k, obstacle in enumerate(objects, start=len(vehicles)):
        if type(obstacle) is not Obstacle:
            raise NotImplementedError(f"the fast backend has no {type(obstacle).__name__}")
        row = array[k]
        row[T.X], row[T.Y] = obstacle.position
        row[T.HEADING], row[T.SPEED] = obstacle.heading, obstacle.speed
        row[T.LANE] = row[T.TARGET_LANE] = row_of[obstacle.lane_index]
        row[T.CHECK_COLLISIONS] = float(obstacle.check_collisions)
        row[T.LEN], row[T.WID], row[T.KIND] = obstacle.LENGTH, obstacle.WIDTH, T.OBSTACLE
    return array


def idm_parameters(npc_class: type = IDMVehicle) -> np.ndarray:
    """The traffic class's IDM / MOBIL parameters (IDMVehicle's by default) as the kernels read them."""
    return np.array([float(getattr(npc_class, name)) for name in T.IDM_PARAMETERS])


# --- the road, converted once per scenario and configuration ----------------------------------------


@dataclass
class _Road:
    """A scenario's road and timing as arrays, shared by every simulator of that configuration.

    :param routes: ego route (RouteTracker) per start lane row a route can be planned from.
    :param in_junction: (L,) junction lanes; ``exit_lane`` (L,): intersection exits ("il…" → "o…").
    :param geometry: highway-env's lane formulas (the spawners'); ``paths``: ``shortest_path``s.
    :param objects: (M, VEHICLE_COLUMNS) the road's static obstacles, after every vehicle.
    :param idm: the traffic class's IDM / MOBIL parameters; ``npc_*``, ``lane_change_delay``,
        ``idm_delta``: its size, LANE_CHANGE_DELAY and DELTA; ``ego_*``: the ego class's size.
    :param keep_npcs, extra_vehicles: the traffic level's drivelab keys; ``destination``: the
        scenario's (extra vehicles are routed to it).
    :param cache: what a spawner derives from the road at its first use; ``description``: the
        road's description (``Scenario.road``'s), None for highway-env's roads.
    """

    table: L.LaneTable
    road_map: RoadMap
    graph_keys: dict
    config: dict
    target_speeds: np.ndarray
    frames: int
    dt_s: float
    policy_frequency_hz: float
    duration_s: float
    routes: dict
    in_junction: np.ndarray
    exit_lane: np.ndarray
    regulation_period: int
    geometry: LaneGeometry
    paths: dict
    objects: np.ndarray
    idm: np.ndarray
    ego_length: float
    ego_width: float
    npc_length: float
    npc_width: float
    lane_change_delay: float
    idm_delta: float
    keep_npcs: bool
    extra_vehicles: int
    destination: str | None
    cache: dict = dataclasses.field(default_factory=dict)
    description: RoadDescription | None = None


_ROADS: dict[tuple, _Road] = {}


def _new_road(scenario: Scenario, table: L.LaneTable, graph: dict, config: dict, **fields) -> _Road:
    """A _Road of ``table`` and ``graph`` ({from: {to: lanes}}) with the fields every conversion
    derives alike; ``fields``: the rest."""
    npc_class = hw_utils.class_from_path(config["other_vehicles_type"])
    if not is_idm_class(npc_class):  # the traffic class the compiled core knows: an IDMVehicle
        raise NotImplementedError(f"the fast backend has no {npc_class.__name__}")
    graph_keys = {f: list(to) for f, to in graph.items()}
    return _Road(
        table=table,
        graph_keys=graph_keys,
        config=dict(config),
        frames=int(config["simulation_frequency"] // config["policy_frequency"]),
        dt_s=1 / config["simulation_frequency"],
        in_junction=np.array([scenario.in_junction(index) for index in table.indices], dtype=bool),
        exit_lane=np.array([("il" in f and "o" in t) for f, t, _ in table.indices], dtype=bool),
        geometry=LaneGeometry(table),
        paths=all_shortest_paths(graph_keys),
        idm=idm_parameters(npc_class),
        npc_length=float(npc_class.LENGTH),
        npc_width=float(npc_class.WIDTH),
        lane_change_delay=float(npc_class.LANE_CHANGE_DELAY),
        idm_delta=float(npc_class.DELTA),
        destination=scenario.destination,
        **fields,
    )


def _convert_road(builder: HighwayBackend, scenario: Scenario) -> _Road:
    """The road highway-env built in ``builder`` (after a reset) as a _Road, with everything the
    episodes need planned now: the builder is dropped afterwards."""
    env = builder.env
    network = env.road.network
    table = L.LaneTable.from_network(network)
    config = env.config
    routes = {}
    for row, index in enumerate(table.indices):
        lanes = builder._plan_route(index)
        if lanes:  # no route from a lane with no path to the destination: no ego starts there
            routes[row] = builder.route_for(lanes)
    regulated = isinstance(env.road, RegulatedRoad)
    if regulated and RegulatedRoad.YIELD_DURATION != 0:
        raise NotImplementedError("the fast backend assumes RegulatedRoad.YIELD_DURATION = 0")
    dt_s = 1 / config["simulation_frequency"]
    walkers = {id(p) for p in getattr(env.road, "pedestrians", [])}  # the town's: set up per episode
    return _new_road(
        scenario,
        table,
        network.graph,
        config,
        road_map=build_road_map(network),
        target_speeds=np.asarray(getattr(env.action_type, "target_speeds", [0.0]), dtype=float),
        policy_frequency_hz=builder.policy_frequency_hz,
        duration_s=builder.duration_s,
        routes=routes,
        regulation_period=int(1 / dt_s / RegulatedRoad.REGULATION_FREQUENCY) if regulated else 0,
        objects=vehicles_to_array([], table, [o for o in env.road.objects if id(o) not in walkers]),
        ego_length=float(env.vehicle.LENGTH),
        ego_width=float(env.vehicle.WIDTH),
        keep_npcs=builder.keep_npcs,
        extra_vehicles=builder.extra_vehicles,
    )


def described_config(
    scenario: Scenario, traffic: str, control: str, overrides: dict | None
) -> tuple[dict, bool, int]:
    """(config, keep_npcs, extra_vehicles) of a described road: the config as highway-env would
    assemble it (its class's defaults, then HighwayBackend's keys)."""
    given, keep_npcs, extra_vehicles = HighwayBackend.assemble_config(scenario, traffic, control, overrides)
    config = hw_utils.class_from_path(scenario.env_class).default_config()
    config.update(given)
    return config, keep_npcs, extra_vehicles


def _describe_road(scenario: Scenario, traffic: str, control: str, overrides: dict | None) -> _Road:
    """A _Road from the scenario's road description (``Scenario.road``), the config as
    ``described_config`` assembles it: no highway-env object is built."""
    from drivelab.sim.roads.road_map import centre_line, circuit_route, road_map

    config, keep_npcs, extra_vehicles = described_config(scenario, traffic, control, overrides)
    desc = scenario.road(config)
    table = L.LaneTable.from_description(desc)
    routes = {}
    if scenario.circuit:  # every lane's route is one lap of the circuit
        has_goal = bool(scenario.destination) or scenario.arrival == "route_end"
        for row in range(len(table.indices)):
            routes[row] = RouteTracker(centre_line(desc, circuit_route(desc, row)), has_goal=has_goal)
    target_speeds = [0.0]
    if control == "meta":
        target_speeds = config["action"].get("target_speeds", MDPVehicle.DEFAULT_TARGET_SPEEDS)
    return _new_road(
        scenario,
        table,
        desc.graph,
        config,
        road_map=road_map(desc),
        target_speeds=np.asarray(target_speeds, dtype=float),
        policy_frequency_hz=float(config["policy_frequency"]),
        duration_s=float(config["duration"]),
        routes=routes,
        regulation_period=0,
        objects=np.zeros((0, T.VEHICLE_COLUMNS)),
        ego_length=float(Vehicle.LENGTH),  # every ego class of highway-env keeps Vehicle's size
        ego_width=float(Vehicle.WIDTH),
        keep_npcs=keep_npcs,
        extra_vehicles=extra_vehicles,
        description=desc,
    )


# --- compiled kernels over K worlds ---------------------------------------------------------------


@njit(cache=True, inline="always")
def meta_action(w: np.ndarray, e: int, lanes: np.ndarray, action: int, speeds: np.ndarray) -> None:
    """MDPVehicle.act for the ego (row ``e``) of one world's vehicles ``w`` (N, VEHICLE_COLUMNS):
    FASTER / SLOWER step the target speed, the lane changes retarget when reachable."""
    if action == FASTER or action == SLOWER:
        index = T.speed_index(w[e, T.SPEED], speeds) + (1 if action == FASTER else -1)
        w[e, T.TARGET_SPEED] = speeds[min(max(index, 0), speeds.size - 1)]
        return
    T.follow_road(w, lanes, e)
    if action == LANE_LEFT or action == LANE_RIGHT:
        target = int(w[e, T.TARGET_LANE])
        first, lane_count = int(lanes[target, L.FIRST_OF_ROAD]), int(lanes[target, L.LANE_COUNT])
        lane_id = int(lanes[target, L.LANE_ID]) + (1 if action == LANE_RIGHT else -1)
        candidate = first + min(max(lane_id, 0), lane_count - 1)
        if L.is_reachable_from(lanes, candidate, w[e, T.X], w[e, T.Y]):
            w[e, T.TARGET_LANE] = candidate


@njit(cache=True)
def apply_meta(v, count, ego, lanes, actions, speeds) -> None:
    """``meta_action`` of each world's ego ``actions[k]`` (the controls follow in the kernel)."""
    for k in range(v.shape[0]):
        meta_action(v[k, : count[k]], ego[k], lanes, actions[k], speeds)


@njit(cache=True)
def exited(lanes: np.ndarray, exit_lane: np.ndarray, row: np.ndarray, distance_m: float) -> bool:
    """IntersectionEnv.has_arrived for one vehicle row: on an exit lane, ``distance_m`` along it."""
    lane = int(row[T.LANE])
    if not exit_lane[lane]:
        return False
    s, _ = L.local_coordinates(lanes, lane, row[T.X], row[T.Y])
    return s >= distance_m


@njit(cache=True)
def clear_departed(
    v: np.ndarray, count: np.ndarray, ego: np.ndarray, lanes: np.ndarray, exit_lane: np.ndarray
) -> None:
    """IntersectionEnv._clear_vehicles in every world: drop the vehicles at the end of their exit
    (and any without a route), the ego excepted; the kept rows close up in order, the freed rows
    become zeros, ``count`` and ``ego`` follow."""
    for k in range(v.shape[0]):
        kept, new_ego = 0, ego[k]
        for j in range(count[k]):
            row = v[k, j]
            leaving = exited(lanes, exit_lane, row, lanes[int(row[T.LANE]), L.LENGTH] - 4 * row[T.LEN])
            if j == ego[k] or not (leaving or row[T.ROUTED] == 0):
                if j == ego[k]:
                    new_ego = kept
                if kept != j:
                    v[k, kept] = v[k, j]
                kept += 1
        v[k, kept : count[k]] = 0.0
        count[k], ego[k] = kept, new_ego


def float_controls(controls, num_worlds: int) -> np.ndarray:
    """(K, 2) controls in float32 or float64, the types the compiled arithmetic takes: those
    stay as they are, anything else (ints, float16, long double) becomes float64."""
    controls = np.asarray(controls).reshape(num_worlds, 2)
    return controls if controls.dtype in _COMPILED_FLOATS else controls.astype(np.float64)


_COMPILED_FLOATS = (np.dtype(np.float32), np.dtype(np.float64))


@functools.cache
def command_ranges(dtype: np.dtype) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The (low, span) of [acceleration, steering] and the constants (1, 2) in ``dtype``."""
    low = np.array([ACCELERATION_RANGE[0], STEERING_RANGE[0]], dtype=dtype)
    span = np.array([ACCELERATION_RANGE[1] - ACCELERATION_RANGE[0], STEERING_RANGE[1] - STEERING_RANGE[0]])
    return low, span.astype(dtype), np.array([1, 2], dtype=dtype)


@njit(inline="always")
def _command(control, low, span, constants):
    """``low + (clip(control, -1, 1) + 1) * span / 2`` in the control's float type (numpy's order
    of operations; a nan control stays nan, as under np.minimum / np.maximum)."""
    one, two = constants[0], constants[1]
    if control < -one:
        control = -one
    elif control > one:
        control = one
    return low + (control + one) * span / two


assert (COLLISION_NONE, COLLISION_VEHICLE) == (0, 1)  # a crashed flag as int8 is its collision kind


@njit(cache=True)
def set_ego_controls(vehicles, ego, controls, low, span, constants) -> None:
    """Each world's ego row gets the command of its normalised control (K, 2) (``ContinuousAction``'s
    clip and linear map, ``_command``): acceleration (also the pedal of a pedal ego, the circuits')
    and steering."""
    for k in range(ego.size):
        acceleration = _command(controls[k, 0], low[0], span[0], constants)
        vehicles[k, ego[k], T.ACCEL] = acceleration
        vehicles[k, ego[k], T.PEDAL] = acceleration
        vehicles[k, ego[k], T.STEER] = _command(controls[k, 1], low[1], span[1], constants)


@njit(cache=True)
def project_routes(
    vehicles, ego, route, starts, segments, lengths2, segment_m, stations, point_count, closed, fresh, update,
    progress
) -> None:  # fmt: skip
    """RouteTracker.project for K egos (row ``ego[k]`` of world k) on route ``route[k]`` of the
    padded route table (``FastSimulator._pad_routes``), in place in ``progress`` (K,) for the worlds
    of ``update``: the nearest point where ``fresh[k]``, else the nearest within SEARCH_WINDOW_M of
    the previous progress (unwrapped on a circuit), RouteTracker's arithmetic in its order. The
    segments within reach of the window are searched first, the rest only when none of them scores
    under the window's penalty (the same answer, see ``_window_spans``)."""
    for k in range(route.size):
        if not update[k]:
            continue
        r = route[k]
        n = point_count[r]
        x, y = vehicles[k, ego[k], T.X], vehicles[k, ego[k], T.Y]
        previous, lap, circuit = progress[k], stations[r, n - 1], closed[r]
        best, best_distance = 0.0, np.inf
        if not fresh[k]:  # the segments the window can reach first (see _window_spans)
            spans = _window_spans(stations[r, :n], previous, lap, circuit)
            for first, end in ((spans[0], spans[1]), (spans[2], spans[3])):
                for i in range(first, end):
                    value, distance = _segment_projection(
                        x, y, starts[r, i, 0], starts[r, i, 1], segments[r, i, 0], segments[r, i, 1],
                        lengths2[r, i], stations[r, i], segment_m[r, i], previous, lap, circuit, False,
                    )  # fmt: skip
                    if distance < best_distance:
                        best, best_distance = value, distance
            if best_distance < WINDOW_PENALTY_M:
                progress[k] = best
                continue
            best, best_distance = 0.0, np.inf
        for i in range(n - 1):
            value, distance = _segment_projection(
                x, y, starts[r, i, 0], starts[r, i, 1], segments[r, i, 0], segments[r, i, 1],
                lengths2[r, i], stations[r, i], segment_m[r, i], previous, lap, circuit, fresh[k],
            )  # fmt: skip
            if distance < best_distance:
                best, best_distance = value, distance
        progress[k] = best


WINDOW_SLACK_M = 1.0  # segments this much beyond the window are searched too (rounding)


@njit(inline="always")
def _segment_projection(x, y, sx, sy, gx, gy, length2, station0, length, previous, lap, circuit, fresh):
    """(progress value, distance) of (x, y) projected on the segment from (sx, sy) along (gx, gy),
    RouteTracker.project's arithmetic for one segment (the window's penalty unless ``fresh``)."""
    t = ((x - sx) * gx + (y - sy) * gy) / length2
    t = min(max(t, 0.0), 1.0)
    dx, dy = sx + t * gx - x, sy + t * gy - y
    distance = np.sqrt(dx * dx + dy * dy)
    station = station0 + t * length
    if fresh:
        return station, distance
    gap = station - previous
    if circuit:
        gap = (gap + lap / 2) % lap - lap / 2
    return previous + gap, distance + WINDOW_PENALTY_M * (np.abs(gap) > SEARCH_WINDOW_M)


@njit(inline="always")
def _window_spans(stations, previous, lap, circuit):
    """Index spans [a0, a1) and [b0, b1), in ascending order, of the segments of a route with
    point ``stations`` whose arc lengths come within SEARCH_WINDOW_M (plus a slack) of
    ``previous`` (round the lap on a circuit). Every other segment is outside the window, so it
    scores WINDOW_PENALTY_M or more: when a searched one scores less, the whole search's answer
    (the first smallest score) is among the searched, found in the same order."""
    count = stations.shape[0] - 1  # segments
    reach = SEARCH_WINDOW_M + WINDOW_SLACK_M
    if not circuit:
        first, end = _span(stations, previous - reach, previous + reach, count)
        return first, end, 0, 0
    if 2 * reach >= lap:
        return 0, count, 0, 0
    centre = previous % lap
    low, high = centre - reach, centre + reach
    a0, a1 = _span(stations, max(low, 0.0), min(high, lap), count)
    if low < 0:  # the window wraps below the start: its other part is at the end of the lap
        b0, b1 = _span(stations, low + lap, lap, count)
        return a0, a1, b0, b1
    if high > lap:  # ... above the end: its other part is at the start, searched first
        b0, b1 = _span(stations, 0.0, high - lap, count)
        return b0, b1, a0, a1
    return a0, a1, 0, 0


@njit(inline="always")
def _span(stations, low, high, count):
    """[first, last + 1) of the segments i (of ``count``) with stations[i + 1] >= low and
    stations[i] <= high."""
    first = max(np.searchsorted(stations, low, "left") - 1, 0)
    last = min(np.searchsorted(stations, high, "right") - 1, count - 1)
    return first, max(last + 1, first)


@njit(cache=True, inline="always")
def export_world(
    w, e: int, lanes, in_junction, exit_lane, arrival: int, arrival_threshold: float, out, ints, flags,
    vehicles, valid, destinations, accelerations
) -> None:  # fmt: skip
    """What WorldBatch needs of one world (vehicles ``w`` (N, VEHICLE_COLUMNS), ego row ``e``),
    into zeroed outputs: the ego's ``out`` (EX_FLOATS,), ``ints`` (3,) and ``flags`` (4,)
    (columns EX_*), and the other vehicles, obstacles left out as highway-env exports them, in
    ``vehicles`` (N - 1, 6) with ``valid`` (N - 1,), their ``destination``s (N - 1, 2) and
    ``accelerations`` (N - 1,)."""
    row = w[e]
    lane = int(row[T.LANE])
    s, lateral = L.local_coordinates(lanes, lane, row[T.X], row[T.Y])
    target = int(row[T.TARGET_LANE]) if row[T.KIND] != T.PLAIN else lane
    limit = lanes[lane, L.SPEED_LIMIT]
    out[EX_X], out[EX_Y], out[EX_HEADING], out[EX_SPEED] = row[T.X], row[T.Y], row[T.HEADING], row[T.SPEED]
    out[EX_STEER], out[EX_ACCEL] = row[T.STEER], row[T.ACCEL]
    out[EX_LEN], out[EX_WID] = row[T.LEN], row[T.WID]
    out[EX_LANE_WIDTH], out[EX_LATERAL] = lanes[lane, L.WIDTH], lateral
    out[EX_LANE_HEADING] = L.heading_at(lanes, lane, s)
    out[EX_SPEED_LIMIT] = 30.0 if np.isnan(limit) else limit
    turn = L.heading_at(lanes, lane, s + 1.0) - L.heading_at(lanes, lane, s - 1.0)
    # libm's cos and sin, the parts of numpy's exp(1j * turn) (glibc's cexp of an imaginary number)
    out[EX_TURN_COS], out[EX_TURN_SIN] = math.cos(turn), math.sin(turn)
    ints[EX_LANE_ID], ints[EX_LANE_COUNT] = lanes[lane, L.LANE_ID], lanes[lane, L.LANE_COUNT]
    ints[EX_TARGET_LANE_ID] = lanes[target, L.LANE_ID]
    flags[EX_ON_ROAD] = L.on_lane(lanes, lane, s, lateral, 0.0)
    flags[EX_IN_JUNCTION] = in_junction[lane]
    flags[EX_CRASHED] = row[T.CRASHED] > 0
    if arrival == ARRIVE_PAST_X:
        flags[EX_ARRIVED] = row[T.X] > arrival_threshold
    elif arrival == ARRIVE_EXIT:
        flags[EX_ARRIVED] = exited(lanes, exit_lane, row, arrival_threshold)
    n = 0
    for j in range(w.shape[0]):
        if j == e or w[j, T.KIND] == T.OBSTACLE:
            continue
        for c in range(EXPORTED_COLUMNS.size):
            vehicles[n, c] = w[j, EXPORTED_COLUMNS[c]]
        valid[n] = True
        destinations[n, 0], destinations[n, 1] = destination(lanes, w[j])
        accelerations[n] = w[j, T.ACCEL]
        n += 1


@njit(cache=True, inline="always")
def destination(lanes, row) -> tuple[float, float]:
    """highway-env's ``Vehicle.destination`` of a vehicle row: the end of the last lane of its
    planned route still to be driven (lane 0 of that road where the route leaves the lane open),
    its own position where it has no route or has driven all of it."""
    start, stop = int(row[T.ROUTE_START]), int(row[T.ROUTE_END])
    if row[T.ROUTED] == 0 or start >= stop:
        return row[T.X], row[T.Y]
    lane = int(row[T.ROUTE + 2 * (stop - 1)]) + max(int(row[T.ROUTE + 2 * (stop - 1) + 1]), 0)
    return L.position(lanes, lane, lanes[lane, L.LENGTH], 0.0)


@njit(cache=True)
def export_worlds(
    v, count, ego, lanes, in_junction, exit_lane, arrival: int, arrival_threshold: float, floats, ints, flags,
    vehicles, valid, destinations, accelerations
) -> None:  # fmt: skip
    """``export_world`` of K worlds on one road: ``floats`` (K, EX_FLOATS), ``ints`` (K, 3),
    ``flags`` (K, 4), ``vehicles`` (K, N, 6), ``valid`` (K, N), ``destinations`` (K, N, 2),
    ``accelerations`` (K, N)."""
    for k in range(v.shape[0]):
        export_world(
            v[k, : count[k]], ego[k], lanes, in_junction, exit_lane, arrival, arrival_threshold,
            floats[k], ints[k], flags[k], vehicles[k], valid[k], destinations[k], accelerations[k],
        )  # fmt: skip


@njit(cache=True)
def advance_worlds(
    v, count, ego, lanes, idm, frames, dt, regulation, time_s, dt_policy, route, starts, segments,
    lengths2, segment_m, stations, point_count, closed, progress, in_junction, exit_lane, arrival,
    arrival_threshold, floats, ints, flags, vehicles, valid, destinations, accelerations,
) -> None:  # fmt: skip
    """A policy step of all K worlds (none restarting) after their controls are set, in one
    compiled call: the kernels ``FastSimulator.step`` otherwise calls one by one, in its order
    (frames, clocks, ``project_routes``, ``export_worlds``)."""
    every, fresh = np.ones(v.shape[0], dtype=np.bool_), np.zeros(v.shape[0], dtype=np.bool_)
    T._simulate_worlds_serial(v, count, lanes, idm, frames, dt, regulation, every)
    for k in range(time_s.size):
        time_s[k] += dt_policy
    project_routes(
        v, ego, route, starts, segments, lengths2, segment_m, stations, point_count, closed, fresh, every,
        progress,
    )  # fmt: skip
    export_worlds(
        v, count, ego, lanes, in_junction, exit_lane, arrival, arrival_threshold, floats, ints, flags,
        vehicles, valid, destinations, accelerations,
    )  # fmt: skip


def export_vehicle_buffers(num_worlds: int, slots: int) -> tuple[np.ndarray, ...]:
    """Zeroed (vehicles (K, slots, 6), valid (K, slots), destinations (K, slots, 2), accelerations
    (K, slots)) for the export."""
    shape = (num_worlds, slots)
    return np.zeros((*shape, 6)), np.zeros(shape, dtype=bool), np.zeros((*shape, 2)), np.zeros(shape)


# --- the simulator ------------------------------------------------------------------------------


class FastSimulator:
    """K worlds of one scenario on drivelab's compiled traffic model, as arrays.

    :param scenario: a scenario the compiled core runs (``fast_backend``).
    :param traffic: "empty", "regular" or "dense".
    :param control: "meta" or "continuous".
    :param num_worlds: K.
    :param overrides: extra highway-env config keys.
    """

    route_time_limit_s = None  # the town's simulator has one per world (NoCrash's fixed routes)
    # recording (``envs/video.py``): called with the batch after every simulation frame of a step;
    # None (the default): a step runs its frames in one compiled call
    on_frame: Callable[[WorldBatch], None] | None = None

    def __init__(
        self, scenario: Scenario, traffic: str, control: str, num_worlds: int, overrides: dict | None = None
    ) -> None:
        if scenario.simulator not in {f"{c.__module__}.{c.__qualname__}" for c in type(self).__mro__}:
            raise UsageError(
                f"scenario {scenario.name!r} runs on {scenario.simulator} (sim.core.backend.fast_simulator)"
            )
        if not scenario.fast_backend:
            raise UsageError(
                f"backend 'fast' does not run scenario {scenario.name!r} yet; use --backend highway"
            )
        if scenario.arrival not in ARRIVAL_RULES:
            raise UsageError(f"the fast backend has no arrival rule {scenario.arrival!r}")
        if num_worlds < 1:
            raise UsageError(f"num_worlds must be >= 1 (got {num_worlds})")
        if scenario.spawn is None:
            raise UsageError(f"the fast backend has no episode set-up for scenario {scenario.name!r}")
        compile_notice()
        self.scenario, self.control, self.num_worlds = scenario, control, num_worlds
        self._every_world = np.ones(num_worlds, dtype=bool)  # every route projected each step
        road = self._road = self._load_road(scenario, traffic, control, overrides)
        self.table, self.lanes, self.road = road.table, road.table.rows, road.road_map
        self.in_junction, self.exit_lane = road.in_junction, road.exit_lane  # (L,) lane-row flags
        self.roads: tuple[RoadMap, ...] = (self.road,)
        self.policy_frequency_hz, self.duration_s = road.policy_frequency_hz, road.duration_s
        self.dt_policy_s = 1.0 / self.policy_frequency_hz
        self._dt_policy = np.array(self.dt_policy_s)  # 0-d: added to time_s without a scalar's conversion
        self.frames, self.dt_s = road.frames, road.dt_s
        self.idm = road.idm
        self.arrival, self.arrival_threshold = ARRIVAL_RULES[scenario.arrival]
        self.traffic_flow = scenario.traffic_flow
        if self.arrival == ARRIVE_PAST_X:
            self.arrival_threshold = float(scenario.arrival_x_m)
        self.arrivals = scenario.arrivals(road) if self.traffic_flow else None
        k = num_worlds
        self.vehicles = np.zeros((k, 1, T.VEHICLE_COLUMNS))  # grows to the largest world
        self.count = np.zeros(k, dtype=np.int64)
        self.ego = np.zeros(k, dtype=np.int64)
        self.regulation = np.zeros((k, 2))
        self.time_s = np.zeros(k)
        self.progress_m = np.zeros(k)
        self.route_index = np.zeros(k, dtype=np.int64)
        self.start_lane_id = np.zeros(k, dtype=np.int64)  # keep_lane: the lane the episode began on
        self.rngs: list[np.random.Generator | None] = [None] * k
        self._lane_route: np.ndarray | None = None  # route index per lane row (batched set-up)
        # export arrays that never change, shared read-only by every batch
        self._no_event = np.zeros(k, dtype=bool)
        self._empty = {
            "road_index": np.zeros(k, dtype=np.int64),
            "traffic_lights": np.zeros((k, 0, 4)),
            "light_valid": np.zeros((k, 0), dtype=bool),
            "pedestrians": np.zeros((k, 0, 6)),
            "pedestrian_valid": np.zeros((k, 0), dtype=bool),
            "max_speed_mps": np.full(k, T.MAX_SPEED),
        }
        for array in (self._no_event, *self._empty.values()):
            array.setflags(write=False)
        # (route_index, RouteBatch arrays, _route_version) of the last batch
        self._route_cache: tuple[np.ndarray, dict, int] | None = None
        self._route_version = 0  # counts route changes that keep route_index (the town's)
        self._route_of: dict = {}  # what ``_route`` registered a route under → its index
        self._trackers: list[RouteTracker] = []
        self._batch: WorldBatch | None = None
        # the last step's export, when its batch is made on first read (``defer_batch``)
        self._deferred: Callable[[], tuple] | None = None

    @property
    def batch(self) -> WorldBatch | None:
        """The WorldBatch of the last reset or step (None before the first reset)."""
        if self._deferred is not None:
            parts, self._deferred = self._deferred, None
            self._batch = self._export_arrays(*parts())
        return self._batch

    @batch.setter
    def batch(self, batch: WorldBatch | None) -> None:
        self._batch, self._deferred = batch, None

    @property
    def started(self) -> bool:
        """A reset has been made (the batch exists or is deferred)."""
        return self._batch is not None or self._deferred is not None

    def defer_batch(self, parts: Callable[[], tuple]) -> None:
        """The step just made leaves its WorldBatch to be made when ``batch`` is read, from
        ``parts()``: ``_export_arrays``' arguments, its ``state`` (the step's own clocks, progress
        and routes) included."""
        self._batch, self._deferred = None, parts

    @staticmethod
    def _load_road(scenario: Scenario, traffic: str, control: str, overrides: dict | None) -> _Road:
        """The scenario's road for this configuration, converted at its first use (``_ROADS``)."""
        key = (repr(scenario), traffic, control, repr(sorted((overrides or {}).items())))
        if key not in _ROADS and scenario.road is not None:  # a described road: no highway-env object
            _ROADS[key] = _describe_road(scenario, traffic, control, overrides)
        elif key not in _ROADS:  # highway-env builds the road once; nothing of it is kept but arrays
            builder = HighwayBackend(scenario, traffic, control, overrides)
            builder.reset(0)
            _ROADS[key] = _convert_road(builder, scenario)
        return _ROADS[key]

    # --- buffers --------------------------------------------------------------------------------
    def _fit(self, rows: int) -> None:
        """Grow the vehicle buffer to at least ``rows`` rows per world (doubling)."""
        capacity = self.vehicles.shape[1]
        if rows <= capacity:
            return
        grown = np.zeros((self.num_worlds, max(rows, 2 * capacity), T.VEHICLE_COLUMNS))
        grown[:, :capacity] = self.vehicles
        self.vehicles = grown

    def _put_rows(self, k: int, rows: np.ndarray, ego: int) -> None:
        """World k's vehicles become ``rows`` (the rest of its buffer zeros), its ego row ``ego``."""
        self._fit(len(rows))
        self.vehicles[k] = 0.0
        self.vehicles[k, : len(rows)] = rows
        self.count[k], self.ego[k] = len(rows), ego

    def _route_for_lane(self, lane: int) -> int:
        """The index of the ego route that starts on lane row ``lane``."""
        return self._route(lane, self._road.routes.get(lane), f"lane {self.table.indices[lane]}")

    def _route(self, key, tracker: RouteTracker | None, where: str) -> int:
        """The index of the ego route ``tracker`` (from ``where``; None: there is none) under
        ``key``, padded at its first use."""
        if key not in self._route_of:
            if tracker is None:
                raise NotImplementedError(f"no ego route from {where}")
            row = self._route_of[key] = len(self._trackers)
            self._trackers.append(tracker)
            if row and row < len(self.r_count) and len(tracker.polyline) <= self.r_polyline.shape[1]:
                self._pad_route(row)  # room for it: one new row, not every route again
                if self.scenario.guide_line:
                    self._guide_roads()
            else:
                self._pad_routes(spare_rows=row)  # room for as many again (procedural maps add many)
        return self._route_of[key]

    def _pad_routes(self, spare_rows: int = 0) -> None:
        """The routes in use as padded arrays (R routes, S segments at most), last point repeated,
        with ``spare_rows`` unused rows after them for routes to come (``_route``)."""
        trackers = self._trackers
        count, points = len(trackers) + spare_rows, max(len(t.polyline) for t in trackers)
        self.r_polyline, self.r_stations = np.zeros((count, points, 2)), np.zeros((count, points))
        self.r_starts, self.r_segments = np.zeros((count, points - 1, 2)), np.zeros((count, points - 1, 2))
        self.r_lengths2, self.r_segment_m = np.zeros((count, points - 1)), np.zeros((count, points - 1))
        self.r_count, self.r_length = np.zeros(count, dtype=np.int64), np.zeros(count)
        self.r_closed = np.zeros(count, dtype=bool)
        for row in range(len(trackers)):
            self._pad_route(row)
        if self.scenario.guide_line:
            self._guide_roads()

    def _guide_roads(self) -> None:
        """A road map per route, with the route painted along it as one whole lap."""
        self.roads = tuple(dataclasses.replace(self.road, guide_lines=(t.polyline,)) for t in self._trackers)

    def _pad_route(self, row: int) -> None:
        """Row ``row`` of the padded route arrays from its tracker, the last point repeated to the
        arrays' width (which must hold it)."""
        tracker = self._trackers[row]
        for array, values in (
            (self.r_polyline, tracker.polyline),
            (self.r_stations, tracker.stations),
            (self.r_starts, tracker._starts),
            (self.r_segments, tracker._segments),
            (self.r_lengths2, tracker._lengths2),
        ):
            array[row, : len(values)] = values
            array[row, len(values) :] = values[-1]
        self.r_segment_m[row] = np.sqrt(self.r_lengths2[row])
        self.r_count[row], self.r_length[row] = len(tracker.polyline), tracker.length_m
        self.r_closed[row] = tracker.closed

    # --- episodes -------------------------------------------------------------------------------
    def _episode(self, seed: int) -> tuple[np.ndarray, int, np.ndarray, np.random.Generator | None]:
        """A new episode's (vehicle rows, ego row, regulation state, generator between steps)."""
        return self.scenario.spawn(int(seed), self._road, self.control)

    def reset_where(self, mask: np.ndarray, seeds: np.ndarray) -> WorldBatch:
        """Start a new episode from ``seeds[k]`` in every world where ``mask[k]`` (K,); the other
        worlds are untouched. Returns the whole batch."""
        mask = np.asarray(mask, dtype=bool)
        self._red_light = np.zeros(self.num_worlds, dtype=bool)  # the lights' rules (town, block maps)
        self._start_episodes(np.flatnonzero(mask), seeds)
        self._project(fresh=mask, update=mask)
        self.batch = self._export()
        return self.batch

    def _start_episodes(self, worlds: np.ndarray, seeds: np.ndarray) -> None:
        """New episodes in ``worlds`` from ``seeds[k]`` (``spawn_many`` where the scenario has it)."""
        if worlds.size == 0:
            return
        if self.scenario.spawn_many is not None:
            self._spawn_many(worlds, seeds)
        else:
            for k in worlds:
                rows, ego, regulation, rng = self._episode(seeds[k])
                self._put_rows(k, rows, ego)
                self.regulation[k], self.rngs[k] = regulation, rng
                self.route_index[k] = self._route_for_lane(int(rows[ego, T.LANE]))
        ego_lane = self.vehicles[worlds, self.ego[worlds], T.LANE].astype(np.int64)
        self.start_lane_id[worlds] = self.lanes[ego_lane, L.LANE_ID]
        self.time_s[worlds] = 0.0

    def _spawn_many(self, worlds: np.ndarray, seeds: np.ndarray) -> None:
        """The scenario's many-world set-up for ``worlds`` (no regulation, no generator between
        steps); every lane's route is registered at the first call."""
        if self._lane_route is None:
            lanes = range(len(self.table.indices))
            self._lane_route = np.array([self._route_for_lane(lane) for lane in lanes])
        rows, count, ego = self.scenario.spawn_many(self._road, self.control, seeds[worlds])
        self._fit(rows.shape[1])
        self.vehicles[worlds] = 0.0
        self.vehicles[worlds, : rows.shape[1]] = rows
        self.count[worlds], self.ego[worlds], self.regulation[worlds] = count, ego, 0.0
        ego_lane = rows[np.arange(len(worlds)), ego, T.LANE].astype(np.int64)
        self.route_index[worlds] = self._lane_route[ego_lane]

    def step(
        self, controls: np.ndarray, restart: np.ndarray | None = None, seeds: np.ndarray | None = None
    ) -> WorldBatch:
        """One policy step of every world: the egos' controls, the clocks (and lights), ``frames``
        simulation frames, the scenario's rules after the frames, the episodes that restart, the
        routes' progress, the export (one compiled call where nothing in between needs Python,
        ``one_call``). A scenario's simulator fills in the hooks.

        :param controls: meta: (K,) int meta-actions; continuous: (K, 2) [acceleration, steering]
            normalised in [-1, 1] (highway-env's order).
        :param restart: (K,) bool: these worlds start a new episode from ``seeds[k]`` instead of
            stepping (gymnasium's NEXT_STEP autoreset), as ``reset_where`` would start it.
        """
        if not self.started:
            raise UsageError(f"{type(self).__name__}.step before reset_where")
        if restart is None:
            restart = np.zeros(self.num_worlds, dtype=bool)
        restart = np.asarray(restart, dtype=bool)
        restarting = np.count_nonzero(restart)
        if self.one_call and not restarting:
            self.apply_controls(controls)
            self.batch = self._advance()
            return self.batch
        active = ~restart
        before = self._before_frames()
        self.apply_controls(controls)
        np.add(self.time_s, self._dt_policy, out=self.time_s)  # the lights read the step's end time
        self._update_lights(active)
        self.run_frames(lambda frames: self._simulate(frames, active))
        self._after_frames(active, before)
        if restarting:
            self._start_episodes(np.flatnonzero(restart), seeds)
        self._project(fresh=restart, update=self._projected(restart))
        self.batch = self._export()
        return self.batch

    # the step's hooks (``step``)
    def _before_frames(self):
        """What ``_after_frames`` needs from before the controls (the town's: the egos' lanes)."""
        return None

    def _update_lights(self, active: np.ndarray) -> None:
        """The traffic lights of the ``active`` worlds at their clocks (none here)."""

    def _simulate(self, frames: int, active: np.ndarray) -> None:
        """``frames`` simulation frames of the ``active`` worlds (one compiled call)."""
        T.simulate_worlds(
            self.vehicles, self.count, self.lanes, self.idm, frames, self.dt_s, self.regulation, active
        )

    def _after_frames(self, active: np.ndarray, before) -> None:
        """The scenario's rules after the frames: here IntersectionEnv.step's traffic (clear the
        vehicles that left, then maybe spawn one)."""
        if self.traffic_flow:
            clear_departed(self.vehicles, self.count, self.ego, self.lanes, self.exit_lane)
            self._spawn_arrivals()

    def _projected(self, restart: np.ndarray) -> np.ndarray:
        """The worlds whose route progress the step projects after the restarts (every world)."""
        return self._every_world

    # whether ``step`` can be ``advance_worlds``: this class's hooks and no others
    _whole_step_kernel = True

    @property
    def one_call(self) -> bool:
        """The step is one compiled call (``advance_worlds``): this class's hooks, not recording
        frames, no traffic arriving between steps, and the worlds simulated one after another
        (one world, or one numba thread)."""
        serial = self.num_worlds == 1 or numba.get_num_threads() == 1
        return self._whole_step_kernel and self.on_frame is None and not self.traffic_flow and serial

    def _advance(self) -> WorldBatch:
        """``advance_worlds`` then the WorldBatch of its export (see ``step``)."""
        buffers = self._export_buffers()
        advance_worlds(
            self.vehicles, self.count, self.ego, self.lanes, self.idm, self.frames, self.dt_s,
            self.regulation, self.time_s, self.dt_policy_s, self.route_index, self.r_starts,
            self.r_segments, self.r_lengths2, self.r_segment_m, self.r_stations, self.r_count,
            self.r_closed, self.progress_m, self.in_junction, self.exit_lane, self.arrival,
            self.arrival_threshold, *buffers,
        )  # fmt: skip
        return self._export_arrays(*buffers)

    def run_frames(self, simulate: Callable[[int], None]) -> None:
        """The step's simulation frames: one compiled call ``simulate(frames)``; while recording
        (``on_frame`` set), ``frames`` calls of ``simulate(1)``, ``on_frame`` shown the batch after
        each (the same frames, bit for bit; the recorded batches skip the route projection)."""
        if self.on_frame is None:
            simulate(self.frames)
            return
        for _ in range(self.frames):
            simulate(1)
            self.on_frame(self._export())

    def apply_controls(self, controls: np.ndarray) -> None:
        """Set every ego's meta-action targets or continuous controls (before simulating)."""
        if self.control == "meta":
            actions = np.asarray(controls).reshape(self.num_worlds).astype(np.int64)
            apply_meta(self.vehicles, self.count, self.ego, self.lanes, actions, self._road.target_speeds)
            return
        controls = float_controls(controls, self.num_worlds)
        set_ego_controls(self.vehicles, self.ego, controls, *command_ranges(controls.dtype))

    def _spawn_arrivals(self) -> None:
        """IntersectionEnv._spawn_vehicle in each world, from its own generator."""
        probability = self._road.config["spawn_probability"]
        for k in range(self.num_worlds):
            n = int(self.count[k])
            row = self.arrivals.spawn(self.vehicles[k, :n], self.rngs[k], probability)
            if row is not None:
                self._fit(n + 1)
                self.vehicles[k, n] = row
                self.count[k] = n + 1

    def _project(self, fresh: np.ndarray, update: np.ndarray) -> None:
        project_routes(
            self.vehicles, self.ego, self.route_index, self.r_starts, self.r_segments, self.r_lengths2,
            self.r_segment_m, self.r_stations, self.r_count, self.r_closed, fresh, update, self.progress_m,
        )  # fmt: skip

    def _export_buffers(self) -> tuple[np.ndarray, ...]:
        """Zeroed (floats, ints, flags, vehicles, valid, destinations, accelerations) arrays the
        export kernels fill; the first three column-major, so that each column (one WorldBatch
        field) is contiguous."""
        k, slots = self.num_worlds, max(self.vehicles.shape[1] - 1, 0)
        floats, ints = np.zeros((EX_FLOATS, k)).T, np.zeros((3, k), dtype=np.int64).T
        flags = np.zeros((4, k), dtype=bool).T
        return floats, ints, flags, *export_vehicle_buffers(k, slots)

    def _export(self) -> WorldBatch:
        buffers = self._export_buffers()
        export_worlds(
            self.vehicles, self.count, self.ego, self.lanes, self.in_junction, self.exit_lane,
            self.arrival, self.arrival_threshold, *buffers,
        )  # fmt: skip
        return self._export_arrays(*buffers)

    def _export_arrays(
        self,
        floats: np.ndarray,
        ints: np.ndarray,
        flags: np.ndarray,
        vehicles: np.ndarray,
        valid: np.ndarray,
        destinations: np.ndarray,
        accelerations: np.ndarray,
        state: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
    ) -> WorldBatch:
        """The WorldBatch of ``export_worlds``' outputs (``_export_buffers``' column-major arrays;
        the town adds its lights and pedestrians). ``state``: copies of the clocks, progress and
        route indices of the step that filled them (``defer_batch``); default the current ones."""
        if state is None:
            state = (self.time_s.copy(), self.progress_m.copy(), self.route_index)
        time_s, progress_m, route_index = state
        (
            _, _, heading, speed, steering, acceleration, length, width, lane_width, lateral,
            lane_heading, speed_limit, turn_cos, turn_sin,
        ) = floats.T  # fmt: skip
        lane_id, lane_count, target_lane_id = ints.T
        on_road, in_junction, collided, arrived = flags.T
        # highway-env's export: angle(exp(1j * turn)) / 2, numpy's arctan2 of the kernel's parts
        curvature = np.arctan2(turn_sin, turn_cos)
        curvature *= 0.5
        position = np.ascontiguousarray(floats[:, EX_X : EX_Y + 1])  # (K, 2): a view for K = 1
        ego = assemble(
            EgoBatch, position=position, heading=heading, speed_mps=speed, steering=steering,
            acceleration_mps2=acceleration, length_m=length, width_m=width, lane_id=lane_id,
            lane_count=lane_count, target_lane_id=target_lane_id, lane_width_m=lane_width,
            lateral_offset_m=lateral, lane_heading=lane_heading, lane_curvature=curvature, on_road=on_road,
            in_intersection=in_junction,
        )  # fmt: skip
        no_event = self._no_event
        off_road = ~on_road
        if self.scenario.keep_lane:  # follow-lane: leaving the starting lane is leaving the road
            off_road |= lane_id != self.start_lane_id
        if self.arrival == ARRIVE_ROUTE_END:
            arrived = self._route_ended(route_index, progress_m)
        events = assemble(
            EventsBatch,
            collided=collided,
            collision_kind=collided.view(np.int8),  # COLLISION_NONE 0, COLLISION_VEHICLE 1
            off_road=off_road,
            arrived=arrived,
            red_light_crossed=no_event,  # the rules add blocked and off_route; no lights here
            blocked=no_event,
            off_route=no_event,
        )
        route = assemble(RouteBatch, progress_m=progress_m, **self._routes(route_index))
        extra = (
            self._empty if not self.scenario.guide_line else {**self._empty, "road_index": route_index.copy()}
        )
        return assemble(
            WorldBatch, time_s=time_s, dt_s=self.dt_policy_s, ego=ego, vehicles=vehicles, vehicle_valid=valid,
            vehicle_destinations=destinations, vehicle_accelerations=accelerations, roads=self.roads,
            route=route, events=events, speed_limit_mps=speed_limit, **extra,
        )  # fmt: skip

    def _route_ended(
        self, route_index: np.ndarray | None = None, progress_m: np.ndarray | None = None
    ) -> np.ndarray:
        """(K,) less than the arrival threshold of the ego's route is left (default: now)."""
        route_index = self.route_index if route_index is None else route_index
        progress_m = self.progress_m if progress_m is None else progress_m
        return self.r_length[route_index] - progress_m < self.arrival_threshold

    def _routes(self, route_index: np.ndarray) -> dict[str, np.ndarray]:
        """Every world's route arrays for RouteBatch of the route indices ``route_index`` (K,),
        remade only when a world's route changed (read-only: consecutive batches share them)."""
        if self._routes_stale(route_index):
            r = route_index.copy()
            arrays = {
                "polyline": self.r_polyline[r],
                "stations_m": self.r_stations[r],
                "count": self.r_count[r],
                "length_m": self.r_length[r],
                "closed": self.r_closed[r],
            }
            for array in arrays.values():
                array.setflags(write=False)
            self._route_cache = (r, arrays, self._route_version)
        return self._route_cache[1]

    def _routes_stale(self, route_index: np.ndarray) -> bool:
        """A world's route changed since the route arrays were last made."""
        return self._route_cache is None or self._route_cache[0].tobytes() != route_index.tobytes()
