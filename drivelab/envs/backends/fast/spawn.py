"""Episode set-up without highway-env objects, drawing the same random numbers in the same order.

``spawn_highway`` reproduces ``HighwayEnv._create_vehicles`` (one controlled vehicle) with
``Vehicle.create_random`` and ``IDMVehicle.randomize_behavior``: given the same seed it places
the same vehicles at the same positions and speeds as highway-env does (tested).
"""

from __future__ import annotations

import numpy as np
from gymnasium.utils import seeding
from numba import njit

from drivelab.envs.backends.fast import lanes as L
from drivelab.envs.backends.fast import traffic as T

DELTA_RANGE = (3.5, 4.5)  # IDMVehicle.DELTA_RANGE


@njit(cache=True)
def _create_random(
    rng: np.random.Generator,
    lanes: np.ndarray,
    to_roads: np.ndarray,
    to_count: np.ndarray,
    decay: np.ndarray,
    speed: float,
    lane_id: int,
    spacing: float,
    front_x: float,
) -> np.ndarray:
    """Vehicle.create_random as a vehicle row: a random road (``Generator.choice`` of a sequence
    draws ``integers(0, len)``: the same numbers), ``lane_id`` or a random lane (-1), ``speed`` or
    a random one within its speed limit (NaN), placed ahead of the front-most vehicle
    (``front_x``, NaN: none yet). numba's Generator methods draw numpy's numbers from the same
    bit generator state."""
    f = rng.integers(0, to_count.size)
    road = to_roads[f, rng.integers(0, to_count[f])]
    count = int(lanes[road, L.LANE_COUNT])
    lane = road + (lane_id if lane_id >= 0 else rng.integers(0, count))
    if np.isnan(speed):
        limit = lanes[lane, L.SPEED_LIMIT]
        speed = rng.uniform(0.7 * limit, 0.8 * limit)
    offset = spacing * (12 + 1.0 * speed) * decay[count]
    x0 = 3 * offset if np.isnan(front_x) else front_x
    x0 += offset * rng.uniform(0.9, 1.1)
    x, y = L.position(lanes, lane, x0, 0.0)
    row = np.zeros(T.VEHICLE_COLUMNS)
    row[T.X], row[T.Y], row[T.HEADING], row[T.SPEED] = x, y, L.heading_at(lanes, lane, x0), speed
    row[T.LANE] = row[T.TARGET_LANE] = L.closest_lane(lanes, x, y, row[T.HEADING])
    row[T.TARGET_SPEED] = speed
    row[T.DELTA] = 4.0
    row[T.LEN], row[T.WID] = T.CAR_LENGTH, T.CAR_WIDTH
    return row


@njit(cache=True)
def _spawn_rows(
    rng: np.random.Generator,
    lanes: np.ndarray,
    to_roads: np.ndarray,
    to_count: np.ndarray,
    decay: np.ndarray,
    ego_lane_id: int,
    ego_spacing: float,
    vehicles: int,
    spacing: float,
) -> np.ndarray:
    """HighwayEnv._create_vehicles as (1 + vehicles, VEHICLE_COLUMNS) rows, the ego first (its
    kind and target speed set by the caller)."""
    rows = np.zeros((1 + vehicles, T.VEHICLE_COLUMNS))
    rows[0] = _create_random(rng, lanes, to_roads, to_count, decay, 25.0, ego_lane_id, ego_spacing, np.nan)
    rows[0, T.CHECK_COLLISIONS] = 1.0
    # every highway lane starts at x = 0 along +x: a vehicle's longitudinal coordinate is its x
    front_x = rows[0, T.X]
    for k in range(1, 1 + vehicles):
        row = _create_random(rng, lanes, to_roads, to_count, decay, np.nan, -1, spacing, front_x)
        front_x = max(front_x, row[T.X])
        row[T.KIND] = T.IDM
        row[T.TIMER] = ((row[T.X] + row[T.Y]) * np.pi) % 1.0  # IDMVehicle's initial timer
        row[T.DELTA] = rng.uniform(DELTA_RANGE[0], DELTA_RANGE[1])
        rows[k] = row
    return rows


def highway_spawn_tables(table: L.LaneTable, graph_keys: dict) -> tuple[np.ndarray, ...]:
    """The road's static arrays ``spawn_highway`` draws from: (to_roads, to_count, decay), computed
    once per road by the simulator and handed to every reset."""
    row_of, lanes = table.row_of, table.rows
    froms = list(graph_keys)
    width = max(len(tos) for tos in graph_keys.values())
    to_roads = np.zeros((len(froms), width), dtype=np.int64)
    to_count = np.array([len(graph_keys[f]) for f in froms], dtype=np.int64)
    for k, f in enumerate(froms):
        to_roads[k, : to_count[k]] = [row_of[(f, t, 0)] for t in graph_keys[f]]
    # numpy's exp, as highway-env computes the spacing factor (numba's may round differently)
    decay = np.array([np.exp(-5 / 40 * count) for count in range(int(lanes[:, L.LANE_COUNT].max()) + 1)])
    return to_roads, to_count, decay


def spawn_highway(
    seed: int, table: L.LaneTable, graph_keys: dict, config: dict, control: str, target_speeds, tables=None
):
    """Vehicle rows for a highway episode, the ego first, as highway-env would place them.

    :param graph_keys: ``{from: [to, ...]}`` of the road network, in its order.
    :param config: the highway-env config (vehicles_count, vehicles_density, ego_spacing, initial_lane_id).
    :param tables: ``highway_spawn_tables(table, graph_keys)``, when the caller keeps them.
    """
    rng, _ = seeding.np_random(int(seed))
    to_roads, to_count, decay = tables if tables is not None else highway_spawn_tables(table, graph_keys)
    lane_id = config["initial_lane_id"]
    rows = _spawn_rows(
        rng, table.rows, to_roads, to_count, decay, -1 if lane_id is None else int(lane_id),
        float(config["ego_spacing"]), int(config["vehicles_count"]), float(1 / config["vehicles_density"]),
    )  # fmt: skip
    ego = rows[0]
    if control == "meta":  # MDPVehicle snaps its target speed to the nearest allowed one
        speeds = np.asarray(target_speeds, dtype=float)
        ratio = (ego[T.SPEED] - speeds[0]) / (speeds[-1] - speeds[0])
        ego[T.TARGET_SPEED] = speeds[int(np.clip(np.round(ratio * (speeds.size - 1)), 0, speeds.size - 1))]
        ego[T.KIND] = T.CONTROLLED
    else:  # a plain kinematic vehicle has no target speed
        ego[T.KIND], ego[T.TARGET_SPEED] = T.PLAIN, 0.0
    return rows


class IntersectionTraffic:
    """IntersectionEnv's arrivals between steps on one world's vehicle rows: a new vehicle may
    arrive (``_spawn_vehicle``), drawing from the world's own generator in highway-env's order so
    that episodes stay identical. (Departures, ``_clear_vehicles``, are compiled:
    ``simulator.clear_departed``.)

    :param table: the road's LaneTable.
    :param network: the highway-env road network (its shortest paths, once per entry and exit).
    :param vehicle_class: highway-env's ``other_vehicles_type`` class (its length, width, delay).
    """

    def __init__(self, table: L.LaneTable, network, vehicle_class) -> None:
        self.table, self.network, self.vehicle_class = table, network, vehicle_class
        self.paths: dict[tuple[str, str], list[str]] = {}

    def spawn(
        self,
        vehicles: np.ndarray,
        rng: np.random.Generator,
        spawn_probability: float,
        longitudinal: float = 0.0,
        position_deviation: float = 1.0,
        speed_deviation: float = 1.0,
    ) -> np.ndarray | None:
        """The row of a vehicle arriving at an entry, routed to another exit, or None when none
        arrives (IntersectionEnv._spawn_vehicle).

        :param vehicles: (N, VEHICLE_COLUMNS) the world's rows.
        :param rng: the world's generator (highway-env's ``np_random`` of that episode).
        """
        lanes = self.table.rows
        if rng.uniform() > spawn_probability:
            return None
        entry, exit_ = rng.choice(range(4), size=2, replace=False)
        lane = self.table.row_of[(f"o{entry}", f"ir{entry}", 0)]
        s = longitudinal + 5.0 + rng.normal() * position_deviation
        speed = 8.0 + rng.normal() * speed_deviation
        x, y = L.position(lanes, lane, s, 0.0)
        if len(vehicles) and np.min(np.linalg.norm(vehicles[:, [T.X, T.Y]] - [x, y], axis=1)) < 15:
            return None
        row = np.zeros(T.VEHICLE_COLUMNS)
        row[T.X], row[T.Y], row[T.HEADING], row[T.SPEED] = x, y, L.heading_at(lanes, lane, s), speed
        row[T.LANE] = row[T.TARGET_LANE] = L.closest_lane(lanes, x, y, row[T.HEADING])
        row[T.TARGET_SPEED] = speed
        row[T.TIMER] = (np.sum(np.array([x, y])) * np.pi) % self.vehicle_class.LANE_CHANGE_DELAY
        row[T.CHECK_COLLISIONS], row[T.KIND] = 1.0, T.IDM
        row[T.LEN], row[T.WID] = self.vehicle_class.LENGTH, self.vehicle_class.WIDTH
        start = self.table.indices[int(row[T.LANE])]
        key = (start[1], f"o{exit_}")
        if key not in self.paths:
            self.paths[key] = self.network.shortest_path(*key)
        path = self.paths[key]
        route = [start] + [(path[k], path[k + 1], None) for k in range(len(path) - 1)]
        row[T.ROUTED], row[T.ROUTE_END] = 1.0, len(route)
        for k, (_from, _to, lane_id) in enumerate(route):
            row[T.ROUTE + 2 * k] = self.table.road_of(_from, _to)
            row[T.ROUTE + 2 * k + 1] = -1 if lane_id is None else lane_id
        row[T.DELTA] = rng.uniform(low=DELTA_RANGE[0], high=DELTA_RANGE[1])  # randomize_behavior
        return row
