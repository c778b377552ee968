"""Procedural block maps on the compiled core: each map's road as arrays, and an episode's set-up.

A ``BlocksMap`` is one generated map (``roads.pg_map.generate_map``) converted once: its LaneTable
(local lane rows; junction and roundabout lanes get right-of-way priorities), its RoadMap, the
ego's route from each spawn lane, the lanes' solid lines (MetaDrive's out-of-road rule), the dead
ends where traffic leaves, the successor roads traffic picks its routes from, and the spots
where traffic is placed. ``spawn_blocks_episode`` sets up one episode on it from a seed: the ego on
the spawn road, IDM/MOBIL traffic along the blocks at MetaDrive's density, each vehicle on a
random route. Everything per vehicle is arrays (the rows are filled by one compiled call).

MetaDrive's rules are paraphrased from its source (``metadrive/manager/traffic_manager.py``,
``metadrive/envs/metadrive_env.py``, ``metadrive/policy/idm_policy.py``); no code is copied.
"""

from __future__ import annotations

import dataclasses
import functools
import re
from dataclasses import dataclass

import numpy as np
from numba import njit

from drivelab.errors import UsageError
from drivelab.scenarios.blocks.pg_map import JUNCTION_LETTERS, MAX_LANES, PGMap, generate_map, parse_spec
from drivelab.sim.core import lanes as L
from drivelab.sim.core import traffic as T
from drivelab.sim.core.spawn import DELTA_RANGE, LaneGeometry, ego_kind, vehicle_row
from drivelab.sim.junctions.rows import LANE_METADATA, TURN_LEFT
from drivelab.sim.roads.description import ARC, LINE_CONTINUOUS, STRAIGHT
from drivelab.sim.roads.road_map import centre_line, road_map
from drivelab.sim.route import RouteTracker

# metadrive/manager/traffic_manager.py: candidate spots every 10 m of a block's spawn lanes, and
# floor(floor(length / 10) * traffic_density) vehicles per block after the spawn road
SPOT_SPACING_M = 10.0
# metadrive/policy/idm_policy.py: IDMPolicy's NORMAL_SPEED, 30 km/h (traffic cruises there)
TRAFFIC_SPEED_MPS = 30.0 / 3.6
# metadrive/envs/metadrive_env.py: the ego starts on road (">", ">>") at s = 5 m, at rest
EGO_SPAWN_S_M = 5.0
EGO_SPAWN_SPEED_MPS = 0.0
# drivelab's time limit of a block episode: the route driven at 5 m/s on average (18 km/h), plus
# 10 s to get going. MetaDrive's horizon (1000 steps of 0.1 s = 100 s) is long for a 3-block route.
ROUTE_PACE_MPS, ROUTE_START_S = 5.0, 10.0
# a vehicle placed within this (along, across) its heading of one placed before it (where lanes
# cross or merge) is dropped: a car length and a metre, a car width and half a metre (vehicles on
# neighbouring lanes, a lane width apart, stay)
SPAWN_CLEARANCE_M = (6.0, 2.5)
# right of way (``traffic.enforce_road_rules``): an intersection's arms 0 and 2 (the road the block
# is entered on, straight through) over arms 1 and 3, a left turn one below its arm (as highway-env's
# IntersectionEnv ranks its lanes); a roundabout's ring over the curves entering it
MAIN_ROAD_PRIORITY, SIDE_ROAD_PRIORITY, RING_PRIORITY = 3, 1, 1
REGULATION_FREQUENCY_HZ = 2  # highway-env's RegulatedRoad.REGULATION_FREQUENCY
_RING_NODE = re.compile(r"^\d+O\d_[23]_$")  # a roundabout's ring nodes (pg_junctions' parts 2, 3)


# a blocks scenario's map options (its config keys) and their defaults: MetaDrive's map=3 random
# blocks, start_seed 0, num_scenarios 1, lane_num 3, lane_width 3.5 (metadrive/envs/metadrive_env.py)
MAP_DEFAULTS = {
    "map": 3,
    "start_seed": 0,
    "num_scenarios": 1,
    "lane_count": 3,
    "lane_width": 3.5,
    "signalised": False,
    "traffic_density": 0.1,
}


def _integer(config: dict, key: str, low: int) -> int:
    value = config.get(key, MAP_DEFAULTS[key])
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < low:
        raise UsageError(f"{key} must be an integer >= {low}, got {value!r}")
    return int(value)


@dataclass(frozen=True)
class MapSet:
    """The maps a blocks scenario draws from: ``spec`` (a block string or a block count) for
    seeds ``start_seed`` … ``start_seed + num_scenarios − 1`` (MetaDrive's map set).

    :param lane_count: lanes per direction (None: drawn per map from {2, 3}).
    :param lane_width_m: None: drawn per map from U[3, 4.5] (MetaDrive's random_lane_width).
    :param signalised: traffic lights at the intersections.
    """

    spec: str | int
    start_seed: int = 0
    num_scenarios: int = 1
    lane_count: int | None = 3
    lane_width_m: float | None = 3.5
    signalised: bool = False

    @staticmethod
    def from_config(config: dict) -> MapSet:
        """The map set of a scenario config (keys of MAP_DEFAULTS), checked: a UsageError names
        the key of a bad value."""
        spec = config.get("map", MAP_DEFAULTS["map"])
        parse_spec(spec)
        lane_count = config.get("lane_count", MAP_DEFAULTS["lane_count"])
        if lane_count is not None:
            lane_count = _integer(config, "lane_count", 1)
            if lane_count > MAX_LANES:
                raise UsageError(
                    f"lane_count must be 1 to {MAX_LANES} (or null: 2 or 3 per map), got {lane_count}"
                )
        width = config.get("lane_width", MAP_DEFAULTS["lane_width"])
        if width is not None and (
            isinstance(width, bool) or not isinstance(width, (int, float)) or not 2.0 <= width <= 6.0
        ):
            raise UsageError(
                f"lane_width must be metres in [2, 6] (or null: U[3, 4.5] per map), got {width!r}"
            )
        signalised = config.get("signalised", MAP_DEFAULTS["signalised"])
        if not isinstance(signalised, bool):
            raise UsageError(f"signalised must be true or false, got {signalised!r}")
        return MapSet(
            spec if isinstance(spec, str) else int(spec), _integer(config, "start_seed", 0),
            _integer(config, "num_scenarios", 1), lane_count, None if width is None else float(width),
            signalised,
        )  # fmt: skip

    def seed_of(self, episode_seed: int) -> int:
        """The map seed an episode plays: ``start_seed + episode_seed mod num_scenarios``."""
        return self.start_seed + int(episode_seed) % self.num_scenarios

    def generate(self, seed: int) -> PGMap:
        """The map of ``seed`` (generated once per process: ``_generate`` is cached)."""
        return _generate(self.spec, int(seed), self.lane_count, self.lane_width_m, self.signalised)


@functools.lru_cache(maxsize=1024)
def _generate(spec, seed: int, lane_count, lane_width_m, signalised: bool) -> PGMap:
    return generate_map(spec, seed, lane_count=lane_count, lane_width_m=lane_width_m, signalised=signalised)


def traffic_density(config: dict) -> float:
    """The config's ``traffic_density`` (MetaDrive's: vehicles per 10 m of a block's lanes), checked."""
    value = config.get("traffic_density", MAP_DEFAULTS["traffic_density"])
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not 0.0 <= value <= 1.0:
        raise UsageError(f"traffic_density must be a number in [0, 1], got {value!r}")
    return float(value)


@dataclass(frozen=True, eq=False)
class BlocksMap:
    """One procedural map as the compiled core reads it (L lane rows, local to this map).

    :param road: the simulator's converted road of it (``simulator._Road``), shared by every
        episode on the map; ``pg``: the generated map.
    :param spawn_lanes: (n,) lane rows of the spawn road; ``routes``: the ego's RouteTracker from each.
    :param in_junction: (L,) intersection lanes and roundabout curves and ring; ``solid`` (L, 2):
        the lane's left / right line is solid; ``dead_end`` (L,): traffic leaves the map there.
    :param successor_start: (L + 1,) / ``successors`` (E,): CSR of ``_continuations``.
    :param spot_lane: / ``spot_s`` / ``spot_block`` (S,): the candidate traffic spots (``_spots``);
        ``block_spots`` (B,): floor(length / 10) of each block's candidate lanes.
    :param changeable: (L,) ``changeable_lanes``; ``ending`` (L,) ``ending_lanes``.
    :param junction_arrays: the description's LANE_METADATA arrays (int64).
    :param junction_count: J, the map's intersections; ``light_junction``, ``light_arm`` (M,),
        ``light_xyh`` (M, 3): its lights (none unless signalised), one per arm.
    :param signal_xyh: (S, 3) the stop point (x, y, heading) of every lane that ends at a light and
        ``signal_light`` (S,) its light's row: the lights as the batch exports them, one per lane.
    """

    pg: PGMap
    road: object
    spawn_lanes: np.ndarray
    routes: dict
    in_junction: np.ndarray
    solid: np.ndarray
    dead_end: np.ndarray
    successor_start: np.ndarray
    successors: np.ndarray
    spot_lane: np.ndarray
    spot_s: np.ndarray
    spot_block: np.ndarray
    block_spots: np.ndarray
    changeable: np.ndarray
    ending: np.ndarray
    junction_arrays: tuple[np.ndarray, ...]
    junction_count: int
    light_junction: np.ndarray
    light_arm: np.ndarray
    light_xyh: np.ndarray
    signal_xyh: np.ndarray
    signal_light: np.ndarray

    @property
    def table(self) -> L.LaneTable:
        return self.road.table


def _priorities(pg: PGMap, rows: np.ndarray) -> None:
    """Right of way of the junction lanes (see MAIN_ROAD_PRIORITY), into ``rows[:, PRIORITY]``."""
    desc = pg.description
    junction, approach = desc.junction >= 0, desc.end_junction >= 0
    arm = np.where(junction, desc.from_arm, desc.end_arm)
    main = np.where(arm % 2 == 0, MAIN_ROAD_PRIORITY, SIDE_ROAD_PRIORITY)
    priority = np.where(junction | approach, main - (junction & (desc.turn == TURN_LEFT)), 0.0)
    ring = np.array([bool(_RING_NODE.match(f)) and bool(_RING_NODE.match(t)) for f, t, _ in desc.indices])
    rows[:, L.PRIORITY] = np.where(ring, RING_PRIORITY, priority)


def ending_lanes(rows: np.ndarray, changeable: np.ndarray) -> np.ndarray:
    """(L,) the ``changeable`` lanes that lead into a taper merging into a neighbouring lane (the
    in-ramp's acceleration lane, the merge's lane that ends): traffic leaves them for a
    neighbouring lane as soon as that is safe (``blocks_traffic``)."""
    start, successors = _continuations(rows)
    source = np.repeat(np.arange(len(rows)), np.diff(start))
    merging = _merging(rows, start, successors)
    ending = np.zeros(len(rows), dtype=bool)
    ending[source[merging[successors]]] = True
    return ending & changeable


def _merging(rows: np.ndarray, start: np.ndarray, successors: np.ndarray) -> np.ndarray:
    """(L,) the lanes that end by merging into a neighbour: a lane continuing into another lane id
    on a road of fewer lanes, into a lane that continues another lane too; and the arcs of the
    taper leading to it (arc lanes of a road whose other lanes are straight)."""
    road = rows[:, L.FIRST_OF_ROAD].astype(np.int64)
    source = np.repeat(np.arange(len(rows)), np.diff(start))
    joined = np.bincount(successors, minlength=len(rows)) >= 2  # lanes continuing two lanes
    ends = (
        (rows[successors, L.LANE_ID] != rows[source, L.LANE_ID])
        & (rows[successors, L.LANE_COUNT] < rows[source, L.LANE_COUNT])
        & joined[successors]
    )
    merging = np.zeros(len(rows), dtype=bool)
    merging[source[ends]] = True
    kind = rows[:, L.KIND]
    mixed = np.zeros(len(rows), dtype=bool)
    np.logical_or.at(mixed, road, kind != kind[road])
    for _ in range(2):  # a taper is two arcs: the first leads into the second
        leads = merging[successors] & mixed[road[source]] & (kind[source] == L.CIRCLE)
        merging[source[leads]] = True
    return merging


def _ego_route_rows(pg: PGMap, lane_id: int) -> list[int]:
    """Lane rows of the route's roads, keeping ``lane_id`` where a road has that many lanes."""
    return [int(lanes[min(lane_id, len(lanes) - 1)]) for lanes in map(pg.road_rows, pg.route)]


def _spots(pg: PGMap, lane_length: np.ndarray) -> tuple[np.ndarray, ...]:
    """The candidate traffic spots of every block after the spawn road (MetaDrive's spawn lanes):
    an intersection's incoming arms; elsewhere the forward lanes, straight ones only on a
    roundabout (its exits) and a ramp or lane-change block (not their curves); every 10 m from
    5 m on (a spot's cell is [s − 5, s + 5))."""
    desc = pg.description
    forward = np.array([not f.startswith("-") for f, _, _ in desc.indices])
    letters = np.array([pg.blocks[b].letter for b in pg.lane_block])
    candidate = np.where(
        np.isin(letters, JUNCTION_LETTERS),
        desc.end_junction >= 0,
        forward & ((desc.kind == STRAIGHT) | (letters == "C")),
    )
    candidate &= pg.lane_block > 0
    # an intersection's arm-0 approach belongs to the block before it (its lanes are that block's)
    candidate &= ~((desc.end_junction >= 0) & ~np.isin(letters, JUNCTION_LETTERS))
    lanes = np.flatnonzero(candidate)
    cells = np.floor(lane_length[lanes] / SPOT_SPACING_M).astype(np.int64)
    spot_lane = np.repeat(lanes, cells)
    first = np.repeat(np.cumsum(cells) - cells, cells)
    spot_s = (np.arange(len(spot_lane)) - first) * SPOT_SPACING_M + SPOT_SPACING_M / 2
    block_length = np.bincount(pg.lane_block[lanes], weights=lane_length[lanes], minlength=len(pg.blocks))
    block_spots = np.floor(block_length / SPOT_SPACING_M).astype(np.int64)
    return spot_lane, spot_s, pg.lane_block[spot_lane], block_spots


def blocks_map(pg: PGMap, base_road) -> BlocksMap:
    """``pg`` converted for the compiled core; ``base_road``: a ``simulator._Road`` whose config,
    timing and vehicle constants the map's road keeps (its road fields are replaced)."""
    desc = pg.description
    table = L.LaneTable.from_description(desc)
    _priorities(pg, table.rows)
    graph_keys = {f: list(to) for f, to in desc.graph.items()}
    rows = table.rows
    in_junction = (desc.junction >= 0) | (
        (np.array([pg.blocks[b].letter for b in pg.lane_block]) == "O") & (desc.kind == ARC)
    )
    period = int(base_road.config["simulation_frequency"] // REGULATION_FREQUENCY_HZ)
    road = dataclasses.replace(
        base_road, table=table, road_map=road_map(desc), graph_keys=graph_keys, routes={},
        in_junction=in_junction, exit_lane=np.zeros(len(rows), dtype=bool), regulation_period=period,
        geometry=LaneGeometry(table), paths={}, cache={},
    )  # fmt: skip
    spawn_lanes = pg.spawn_lanes
    routes = {
        int(lane): RouteTracker(
            centre_line(desc, _ego_route_rows(pg, int(desc.lane_id[lane]))), has_goal=True
        )
        for lane in spawn_lanes
    }
    successor_start, successors = _continuations(rows)
    spot_lane, spot_s, spot_block, block_spots = _spots(pg, rows[:, L.LENGTH])
    changeable = changeable_lanes(rows, in_junction)
    signal_lanes = np.flatnonzero(np.asarray(desc.light) >= 0)
    signal_ends = [(r, rows[r, L.LENGTH]) for r in signal_lanes]  # a lane's light stands at its end
    junction_arrays = tuple(
        np.ascontiguousarray(getattr(desc, name), dtype=np.int64) for name in LANE_METADATA
    )
    return BlocksMap(
        pg=pg,
        road=road,
        spawn_lanes=np.asarray(spawn_lanes, dtype=np.int64),
        routes=routes,
        in_junction=in_junction,
        solid=desc.lines == LINE_CONTINUOUS,
        dead_end=np.diff(successor_start) == 0,
        successor_start=successor_start,
        successors=successors,
        spot_lane=spot_lane,
        spot_s=spot_s,
        spot_block=spot_block,
        block_spots=block_spots,
        changeable=changeable,
        ending=ending_lanes(rows, changeable),
        junction_arrays=junction_arrays,
        junction_count=len(desc.junction_centre),
        light_junction=np.asarray(desc.light_junction, dtype=np.int64),
        light_arm=np.asarray(desc.light_arm, dtype=np.int64),
        light_xyh=np.asarray(desc.light_xyh, dtype=float).reshape(-1, 3),
        signal_xyh=np.array(
            [(*L.position(rows, r, end, 0.0), L.heading_at(rows, r, end)) for r, end in signal_ends]
        ).reshape(-1, 3),
        signal_light=np.asarray(desc.light, dtype=np.int64)[signal_lanes],
    )


def changeable_lanes(rows: np.ndarray, in_junction: np.ndarray) -> np.ndarray:
    """(L,) the lanes where traffic may change lanes (MOBIL): those of roads of two lanes or more
    whose lanes are all of one kind (side by side: a straight road, a curve, a ramp's main road
    away from its tapers), outside the intersections and the roundabouts' curves and ring."""
    road = rows[:, L.FIRST_OF_ROAD].astype(np.int64)
    kind = rows[:, L.KIND]
    lowest, highest = np.full(len(rows), np.inf), np.full(len(rows), -np.inf)
    np.minimum.at(lowest, road, kind)
    np.maximum.at(highest, road, kind)
    side_by_side = (rows[:, L.LANE_COUNT] >= 2) & (lowest[road] == highest[road])
    return side_by_side & ~np.asarray(in_junction, dtype=bool)


CONTINUATION_M, CONTINUATION_RAD = 0.05, 0.05  # a lane continues another: it starts where that ends


def _continuations(rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """CSR of the lanes that continue each lane row (L,): those leaving its end node that start
    where it ends, heading on as it heads (``successors[start[r]:start[r + 1]]``, row order)."""
    count = len(rows)
    ends = np.array([L.position(rows, r, rows[r, L.LENGTH], 0.0) for r in range(count)]).reshape(-1, 2)
    starts = np.array([L.position(rows, r, 0.0, 0.0) for r in range(count)]).reshape(-1, 2)
    end_heading = np.array([L.heading_at(rows, r, rows[r, L.LENGTH]) for r in range(count)])
    start_heading = np.array([L.heading_at(rows, r, 0.0) for r in range(count)])
    turn = np.angle(np.exp(1j * (start_heading[None, :] - end_heading[:, None])))
    continues = (
        (rows[None, :, L.FROM_NODE] == rows[:, None, L.TO_NODE])
        & (np.linalg.norm(starts[None, :, :] - ends[:, None, :], axis=-1) < CONTINUATION_M)
        & (np.abs(turn) < CONTINUATION_RAD)
    )  # (L, L): row r, then the lanes continuing it
    start = np.concatenate([[0], np.cumsum(continues.sum(axis=1))]).astype(np.int64)
    return start, np.nonzero(continues)[1].astype(np.int64)


@njit(cache=True)
def _traffic_rows(
    lanes, lane, s, delta, walk, successor_start, successors, speed: float, length: float, width: float,
    lane_change_delay: float, rows
) -> None:  # fmt: skip
    """Traffic vehicle rows (M, VEHICLE_COLUMNS) at ``s`` (M,) on lane rows ``lane`` (M,), heading
    along them at ``speed`` (their target speed), with DELTA ``delta`` (M,) and a route: their lane,
    then a random walk through the lanes that continue it, ``walk`` (M, MAX_ROUTE - 1) uniform draws
    picking each next lane (a dead end stops it). Every route step names its lane, so that MOBIL
    keeps the vehicle in it (``traffic.mobil_side``): traffic keeps its lane."""
    for m in range(lane.size):
        row, k = rows[m], lane[m]
        x, y = L.position(lanes, k, s[m], 0.0)
        heading = L.heading_at(lanes, k, s[m])
        row[:] = 0.0
        row[T.X], row[T.Y], row[T.HEADING], row[T.SPEED] = x, y, heading, speed
        row[T.LANE] = row[T.TARGET_LANE] = L.closest_lane(lanes, x, y, heading, k)
        row[T.TARGET_SPEED], row[T.DELTA] = speed, delta[m]
        row[T.TIMER] = ((x + y) * np.pi) % lane_change_delay  # IDMVehicle's initial timer
        row[T.CHECK_COLLISIONS], row[T.KIND] = 1.0, T.IDM
        row[T.LEN], row[T.WID] = length, width
        current = int(row[T.LANE])
        row[T.ROUTE], row[T.ROUTE + 1] = lanes[current, L.FIRST_OF_ROAD], lanes[current, L.LANE_ID]
        end = 1
        for j in range(walk.shape[1]):
            first, stop = successor_start[current], successor_start[current + 1]
            if stop == first:
                break
            current = successors[first + int(walk[m, j] * (stop - first))]
            row[T.ROUTE + 2 * end] = lanes[current, L.FIRST_OF_ROAD]
            row[T.ROUTE + 2 * end + 1] = lanes[current, L.LANE_ID]
            end += 1
        row[T.ROUTED], row[T.ROUTE_START], row[T.ROUTE_END] = 1.0, 0.0, end


@njit(cache=True)
def _spaced(rows: np.ndarray, along_m: float, across_m: float) -> np.ndarray:
    """(M,) bool: each vehicle row kept unless within ``along_m`` along and ``across_m`` across
    the heading of a kept vehicle before it (sequential: whether a vehicle stays depends on those
    kept before it)."""
    keep = np.ones(rows.shape[0], dtype=np.bool_)
    for m in range(1, rows.shape[0]):
        for j in range(m):
            if not keep[j]:
                continue
            dx, dy = rows[m, T.X] - rows[j, T.X], rows[m, T.Y] - rows[j, T.Y]
            c, s = np.cos(rows[j, T.HEADING]), np.sin(rows[j, T.HEADING])
            if np.abs(dx * c + dy * s) < along_m and np.abs(dy * c - dx * s) < across_m:
                keep[m] = False
                break
    return keep


def spawn_blocks_episode(
    seed: int, bmap: BlocksMap, control: str, density: float
) -> tuple[np.ndarray, int, np.ndarray, np.ndarray]:
    """An episode on ``bmap`` from ``seed``: ``(rows (N, VEHICLE_COLUMNS), ego row, regulation
    [period, 0], light offsets (J,))``. The ego (first row) on a random lane of the spawn road at
    s = 5 m, at rest; per block after the spawn road floor(block spots · ``density``) traffic
    vehicles on distinct random spots (MetaDrive's count), each on a random route, dropped within
    SPAWN_CLEARANCE_M of one placed before; then, with lights, each intersection's cycle offset."""
    rng = np.random.default_rng(int(seed))
    road, table = bmap.road, bmap.table
    lane = int(bmap.spawn_lanes[rng.integers(len(bmap.spawn_lanes))])
    geometry = road.geometry
    ego = vehicle_row(
        road,
        geometry.position(lane, EGO_SPAWN_S_M, 0.0),
        geometry.heading_at(lane, EGO_SPAWN_S_M),
        EGO_SPAWN_SPEED_MPS,
        ego_kind(control),
    )
    quota = np.floor(bmap.block_spots * density).astype(np.int64)
    order = np.lexsort((rng.random(len(bmap.spot_lane)), bmap.spot_block))
    block = bmap.spot_block[order]
    first_of_block = np.searchsorted(block, block)
    chosen = order[np.arange(len(order)) - first_of_block < quota[block]]
    count = len(chosen)
    rows = np.zeros((count, T.VEHICLE_COLUMNS))
    _traffic_rows(
        table.rows, bmap.spot_lane[chosen], bmap.spot_s[chosen], rng.uniform(*DELTA_RANGE, count),
        rng.random((count, T.MAX_ROUTE - 1)), bmap.successor_start, bmap.successors, TRAFFIC_SPEED_MPS,
        road.npc_length, road.npc_width, road.lane_change_delay, rows,
    )  # fmt: skip
    everyone = np.concatenate([ego[None], rows])
    everyone = everyone[_spaced(everyone, *SPAWN_CLEARANCE_M)]
    offsets = np.zeros(0)
    if len(bmap.light_arm):
        offsets = rng.uniform(0.0, bmap.pg.description.timings.cycle_s, size=bmap.junction_count)
    return everyone, 0, np.array([float(road.regulation_period), 0.0]), offsets


def route_time_limit_s(tracker: RouteTracker) -> float:
    """The time limit of an episode on this route (ROUTE_PACE_MPS, ROUTE_START_S)."""
    return ROUTE_START_S + tracker.length_m / ROUTE_PACE_MPS
