"""The highway: its preset and its episode set-up, for many worlds in one compiled call.

``spawn_highway_worlds`` writes, for each world to reset, the rows ``HighwayEnv._create_vehicles``
would create from that world's seed, with :mod:`pcg64` generators seeded as gymnasium seeds them
and drawn in highway-env's order.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from drivelab.errors import UsageError
from drivelab.scenarios.options import Option, timing_options
from drivelab.sim.core import lanes as L
from drivelab.sim.core import pcg64
from drivelab.sim.core import traffic as T
from drivelab.sim.core.spawn import DELTA_RANGE
from drivelab.world.scenario import Scenario


@njit(cache=True)
def _create_random(
    rng, lanes, to_roads, to_count, decay, speed: float, lane_id: int, spacing: float, front_x: float, row
) -> None:  # fmt: skip
    """Vehicle.create_random into ``row``: a random road (``np_random.choice`` of a sequence draws
    ``integers(0, len)``), ``lane_id`` or a random lane (-1), ``speed`` or a random one within its
    speed limit (NaN), placed ahead of the front-most vehicle (``front_x``, NaN: none yet)."""
    f = pcg64.bounded_int(rng, to_count.size)
    road = to_roads[f, pcg64.bounded_int(rng, to_count[f])]
    count = int(lanes[road, L.LANE_COUNT])
    lane = road + (lane_id if lane_id >= 0 else pcg64.bounded_int(rng, count))
    if np.isnan(speed):
        limit = lanes[lane, L.SPEED_LIMIT]
        speed = pcg64.uniform(rng, 0.7 * limit, 0.8 * limit)
    offset = spacing * (12 + 1.0 * speed) * decay[count]
    x0 = 3 * offset if np.isnan(front_x) else front_x
    x0 += offset * pcg64.uniform(rng, 0.9, 1.1)
    x, y = L.position(lanes, lane, x0, 0.0)
    row[:] = 0.0
    row[T.X], row[T.Y], row[T.HEADING], row[T.SPEED] = x, y, L.heading_at(lanes, lane, x0), speed
    row[T.LANE] = row[T.TARGET_LANE] = L.closest_lane(lanes, x, y, row[T.HEADING])
    row[T.TARGET_SPEED] = speed
    row[T.DELTA] = 4.0
    row[T.LEN], row[T.WID] = T.CAR_LENGTH, T.CAR_WIDTH


@njit(cache=True)
def _spawn_worlds(
    states, v, lanes, to_roads, to_count, decay, ego_lane_id: int, ego_spacing: float, vehicles: int,
    spacing: float, target_speeds
) -> None:  # fmt: skip
    """HighwayEnv._create_vehicles in world m of ``v`` (M, 1 + vehicles, VEHICLE_COLUMNS) from
    generator ``states[m]`` (M, 6), the ego first: an MDPVehicle where ``target_speeds`` is not
    empty (its target speed the nearest allowed one), else a plain vehicle."""
    for m in range(states.shape[0]):
        rng, w = states[m], v[m]
        _create_random(rng, lanes, to_roads, to_count, decay, 25.0, ego_lane_id, ego_spacing, np.nan, w[0])
        w[0, T.CHECK_COLLISIONS] = 1.0
        if target_speeds.size:
            index = T.speed_index(w[0, T.SPEED], target_speeds)
            w[0, T.TARGET_SPEED], w[0, T.KIND] = target_speeds[index], T.CONTROLLED
        else:  # a plain kinematic vehicle has no target speed
            w[0, T.TARGET_SPEED], w[0, T.KIND] = 0.0, T.PLAIN
        # every highway lane starts at x = 0 along +x: a vehicle's longitudinal coordinate is its x
        front_x = w[0, T.X]
        for j in range(1, 1 + vehicles):
            row = w[j]
            _create_random(rng, lanes, to_roads, to_count, decay, np.nan, -1, spacing, front_x, row)
            front_x = max(front_x, row[T.X])
            row[T.KIND] = T.IDM
            row[T.TIMER] = ((row[T.X] + row[T.Y]) * np.pi) % 1.0  # IDMVehicle's initial timer
            row[T.DELTA] = pcg64.uniform(rng, DELTA_RANGE[0], DELTA_RANGE[1])


def highway_spawn_tables(table: L.LaneTable, graph_keys: dict) -> tuple[np.ndarray, ...]:
    """The road's static arrays the set-up draws from: (to_roads, to_count, decay)."""
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


def spawn_highway_worlds(road, control: str, seeds: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Highway episodes from ``seeds`` (M,): ``(rows (M, N, VEHICLE_COLUMNS), count (M,), ego row
    (M,))``, the ego first in every world (the ``Scenario.spawn_many`` hook).

    :param road: the simulator's converted road (its LaneTable, graph, config, target speeds;
        the static arrays are kept in ``road.cache``).
    :param control: "meta" (an MDPVehicle ego) or "continuous" (a plain vehicle).
    """
    tables = road.cache.get("highway")
    if tables is None:
        tables = road.cache["highway"] = highway_spawn_tables(road.table, road.graph_keys)
    config = road.config
    lane_id, vehicles = config["initial_lane_id"], int(config["vehicles_count"])
    speeds = np.asarray(road.target_speeds if control == "meta" else (), dtype=float)
    seeds = np.asarray(seeds, dtype=np.int64)
    rows = np.zeros((seeds.size, 1 + vehicles, T.VEHICLE_COLUMNS))
    _spawn_worlds(
        pcg64.seeded_states(seeds), rows, road.table.rows, *tables,
        -1 if lane_id is None else int(lane_id), float(config["ego_spacing"]), vehicles,
        float(1 / config["vehicles_density"]), speeds,
    )  # fmt: skip
    return rows, np.full(seeds.size, 1 + vehicles, dtype=np.int64), np.zeros(seeds.size, dtype=np.int64)


def spawn_highway(seed: int, road, control: str):
    """One world's set-up (``spawn_highway_worlds`` with M = 1), with the uniform spawner
    signature ``(seed, road, control) -> (rows, ego row, regulation, None)``."""
    rows, _, _ = spawn_highway_worlds(road, control, np.array([seed]))
    return rows[0], 0, np.zeros(2), None


# highway-env's HighwayEnvFast keys, as both backends read them (``_create_vehicles``, above)
OPTIONS = (
    Option("lanes_count", int, 3, "lanes of the straight road", minimum=1),
    Option(
        "vehicles_count", int, 20, "vehicles besides the ego, placed ahead of it", minimum=0, traffic=True
    ),
    Option(
        "vehicles_density", float, 1.0,
        "traffic density: the gaps between the vehicles shrink as 1 / vehicles_density",
        minimum=0, exclusive_minimum=True, traffic=True,
    ),
    Option(
        "ego_spacing", float, 1.5, "spacing factor of the ego's place ahead of the road's start",
        minimum=0, exclusive_minimum=True,
    ),
    Option(
        "initial_lane_id", int, None, "the ego's starting lane (0: the leftmost); null: a random lane",
        minimum=0, nullable=True,
    ),
    *timing_options(5, 1, 5),
)  # fmt: skip


def check_highway_options(config: dict) -> None:
    """The ego's starting lane must be one of the road's lanes."""
    lane, lanes = config["initial_lane_id"], config["lanes_count"]
    if lane is not None and lane >= lanes:
        raise UsageError(
            f"option 'initial_lane_id' ({lane}) of scenario 'highway' must be below lanes_count ({lanes})"
        )


SCENARIO = Scenario(
    "highway",
    "highway_env.envs.highway_env.HighwayEnvFast",
    "3-lane straight highway, 30 s (highway-env's highway-fast settings)",
    config={"lanes_count": 3, "duration": 30},
    traffic={
        "empty": {"vehicles_count": 0},
        "regular": {"vehicles_count": 20},
        "dense": {"vehicles_count": 35, "vehicles_density": 1.5},
    },
    spawn=spawn_highway,
    spawn_many=spawn_highway_worlds,
    options=OPTIONS,
    check_options=check_highway_options,
)
