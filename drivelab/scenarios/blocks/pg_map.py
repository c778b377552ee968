"""Procedural maps: a chain of blocks from a seed, MetaDrive's way (``metadrive/component/
algorithm/BIG.py``, ``component/map/pg_map.py``), as a ``RoadDescription``.

``generate_map("OSX", seed)`` builds the spawn road ``I`` then a roundabout, a straight and an
intersection; ``generate_map(5, seed)`` draws 5 blocks from MetaDrive's default distribution.
Each block starts at a socket of the block before it (drawn uniformly among its sockets) and is
drawn again with new parameters when its footprint overlaps the map so far, up to 5 times, after
which the block before it is rebuilt (BIG's back-tracking; the spawn road is never rebuilt). The
same seed gives the same map. The route runs from the spawn road to the end of a socket road of
the last block drawn at random (MetaDrive's destination), by fewest roads.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from drivelab.errors import UsageError
from drivelab.scenarios.blocks.pg_blocks import (
    MAX_LANES,
    Block,
    BlockSite,
    curve_block,
    first_block,
    in_ramp_block,
    merge_block,
    out_ramp_block,
    split_block,
    straight_block,
)
from drivelab.scenarios.blocks.pg_blocks import SPACES as ROAD_SPACES
from drivelab.scenarios.blocks.pg_junctions import SPACES as JUNCTION_SPACES
from drivelab.scenarios.blocks.pg_junctions import intersection_block, roundabout_block, t_intersection_block
from drivelab.scenarios.blocks.pg_roads import BlockFailed, reverse_node, sample_parameters
from drivelab.sim.junctions.arrays import shortest_route
from drivelab.sim.roads.description import LINE_CONTINUOUS, RoadDescription, _graph_order

BUILDERS: dict[str, Callable[[BlockSite, dict], Block]] = {
    "S": straight_block, "C": curve_block, "r": in_ramp_block, "R": out_ramp_block, "O": roundabout_block,
    "X": intersection_block, "T": t_intersection_block, "y": merge_block, "Y": split_block,
}  # fmt: skip
SPACES = {**ROAD_SPACES, **JUNCTION_SPACES}
JUNCTION_LETTERS = ("X", "T")
# MetaDrive's default block distribution (``component/algorithm/blocks_prob_dist.py``, v2)
BLOCK_PROBABILITIES = {"C": 0.3, "S": 0.1, "r": 0.1, "R": 0.1, "X": 0.15, "T": 0.15, "O": 0.1}
MAX_TRIALS = 5  # BIG's MAX_TRIAL: builds of one block before the one before it is rebuilt
MAX_BUILDS = 2000  # give up on a map after this many block builds in all
LANE_COUNTS = (2, 3)  # MetaDrive's random_lane_num
LANE_WIDTH_M = 3.5  # MetaDrive's default lane_width; random_lane_width draws U[3, 4.5]
RANDOM_LANE_WIDTH_M = (3.0, 4.5)
SPEED_LIMIT_MPS = 80.0 / 3.6  # MetaDrive's lanes have none; its ego's top speed is 80 km/h
# footprint test (MetaDrive's ``check_lane_on_road``): a road's outer edge is probed 2.6 m out
# (a 2 m sidewalk and a 0.6 m gap) every 1 m; the first metre after the entry socket is skipped
SIDEWALK_GAP_M, PROBE_STEP_M, SOCKET_SKIP_M = 2.6, 1.0, 1.0


# --- footprint test ------------------------------------------------------------------------------
def lane_samples(lane, spacing_m: float, lateral: float | np.ndarray = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """(stations (S,), points (S, 2)): a LaneRecord sampled at most ``spacing_m`` apart at lateral
    offset ``lateral`` (its formulas, vectorised: ``LaneRecord.position``)."""
    length = lane.length
    stations = np.linspace(0.0, length, max(int(np.ceil(length / spacing_m)), 1) + 1)
    lateral = np.broadcast_to(lateral, stations.shape)
    if np.isnan(lane.radius):
        start, end = np.array(lane.start), np.array(lane.end)
        direction = (end - start) / length
        normal = np.array([-direction[1], direction[0]])
        return stations, start + stations[:, None] * direction + lateral[:, None] * normal
    phi = lane.sense * stations / lane.radius + lane.start_phase
    radius = lane.radius - lateral * lane.sense
    return stations, np.array(lane.centre) + radius[:, None] * np.column_stack([np.cos(phi), np.sin(phi)])


@dataclass(frozen=True, eq=False)
class Footprint:
    """The lanes of a block as arrays for point tests: L lanes, straight (``start``, ``direction``
    (L, 2)) or circular (``centre`` (L, 2), ``radius``, ``start_phase``, ``sense`` (L,)),
    ``length`` and ``half_width`` (L,), and ``box`` (4,): min x, min y, max x, max y of them."""

    arc: np.ndarray
    start: np.ndarray
    direction: np.ndarray
    centre: np.ndarray
    radius: np.ndarray
    start_phase: np.ndarray
    sense: np.ndarray
    length: np.ndarray
    half_width: np.ndarray
    box: np.ndarray

    @staticmethod
    def of(block: Block) -> Footprint:
        lanes = block.lanes
        start = np.array([lane.start for lane in lanes], dtype=float)
        end = np.array([lane.end for lane in lanes], dtype=float)
        length = np.array([lane.length for lane in lanes], dtype=float)
        half_width = np.array([lane.width / 2 for lane in lanes], dtype=float)
        footprint = Footprint(
            arc=np.array([not np.isnan(lane.radius) for lane in lanes]),
            start=start,
            direction=(end - start) / length[:, None],
            centre=np.array([lane.centre for lane in lanes], dtype=float),
            radius=np.array([lane.radius for lane in lanes], dtype=float),
            start_phase=np.array([lane.start_phase for lane in lanes], dtype=float),
            sense=np.array([lane.sense for lane in lanes], dtype=float),
            length=length,
            half_width=half_width,
            box=np.zeros(4),
        )
        edges = np.concatenate([footprint.sample(2.0, side * half_width)[2] for side in (-1.0, 1.0)])
        return dataclasses.replace(footprint, box=np.concatenate([edges.min(axis=0), edges.max(axis=0)]))

    def sample(self, spacing_m: float, lateral: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(lane (P,), station (P,), point (P, 2)): every lane sampled at most ``spacing_m`` apart
        from end to end at its ``lateral`` (L,) offset (``LaneRecord.position``, vectorised)."""
        count = np.maximum(np.ceil(self.length / spacing_m).astype(np.int64), 1) + 1
        lane = np.repeat(np.arange(len(count)), count)
        first = np.repeat(np.cumsum(count) - count, count)
        station = (np.arange(len(lane)) - first) / (count[lane] - 1) * self.length[lane]
        lateral = lateral[lane][:, None]
        direction = self.direction[lane]
        normal = np.column_stack([-direction[:, 1], direction[:, 0]])
        line = self.start[lane] + station[:, None] * direction + lateral * normal
        sense = self.sense[lane][:, None]
        phi = sense[:, 0] * station / self.radius[lane] + self.start_phase[lane]
        circle = self.centre[lane] + (self.radius[lane][:, None] - lateral * sense) * np.column_stack(
            [np.cos(phi), np.sin(phi)]
        )
        return lane, station, np.where(self.arc[lane][:, None], circle, line)

    def contains(self, points: np.ndarray) -> np.ndarray:
        """(P,) whether each point (P, 2) lies on a lane: 0 ≤ s ≤ length and |lateral| ≤ w/2, in
        the lane's own coordinates (highway-env's ``local_coordinates``)."""
        d = points[:, None, :] - self.start[None]  # (P, L, 2); NaN on arcs
        s_line = (d * self.direction[None]).sum(-1)
        r_line = d[..., 1] * self.direction[None, :, 0] - d[..., 0] * self.direction[None, :, 1]
        c = points[:, None, :] - self.centre[None]
        phi = np.arctan2(c[..., 1], c[..., 0])
        phi = self.start_phase + (phi - self.start_phase + np.pi) % (2 * np.pi) - np.pi
        s_arc = self.sense * (phi - self.start_phase) * self.radius
        r_arc = self.sense * (self.radius - np.hypot(c[..., 0], c[..., 1]))
        s, r = np.where(self.arc, s_arc, s_line), np.where(self.arc, r_arc, r_line)
        return ((s >= 0.0) & (s <= self.length) & (np.abs(r) <= self.half_width)).any(axis=1)


def probe_points(block: Block, footprint: Footprint) -> np.ndarray:
    """(P, 2) the points MetaDrive-style probing tests: every lane's centre line and, beyond each
    road edge (a solid right line), the sidewalk's far side, every metre; not the first metre
    after the entry socket, where the previous block's lanes end."""
    entry, back = block.entry.node, reverse_node(block.entry.node)
    from_entry = np.array([lane.start_node == entry for lane in block.lanes])
    to_entry = np.array([lane.end_node == back for lane in block.lanes])
    edge = np.array([lane.lines[1] == LINE_CONTINUOUS for lane in block.lanes])
    centre = footprint.sample(PROBE_STEP_M, np.zeros(len(edge)))
    outside = footprint.sample(PROBE_STEP_M, footprint.half_width + SIDEWALK_GAP_M)
    found = []
    for (lane, station, points), wanted in ((centre, np.ones_like(edge)), (outside, edge)):
        keep = wanted[lane] & ~(from_entry[lane] & (station < SOCKET_SKIP_M))
        keep &= ~(to_entry[lane] & (station > footprint.length[lane] - SOCKET_SKIP_M))
        found.append(points[keep])
    return np.concatenate(found)


def overlaps(block: Block, footprints: list[Footprint], own: Footprint | None = None) -> bool:
    """Whether a probe point of ``block`` (whose footprint is ``own``) lies on a lane of the blocks
    before it (``footprints``)."""
    points = probe_points(block, own or Footprint.of(block))
    low, high = points.min(axis=0), points.max(axis=0)
    for footprint in footprints:
        if np.any(high < footprint.box[:2]) or np.any(low > footprint.box[2:]):
            continue
        inside = np.all((points >= footprint.box[:2]) & (points <= footprint.box[2:]), axis=1)
        if inside.any() and footprint.contains(points[inside]).any():
            return True
    return False


# --- BIG -------------------------------------------------------------------------------------------
def parse_spec(spec: str | int) -> tuple[str, ...] | int:
    """The block letters of a map string (after the spawn road ``I``), or a block count."""
    if isinstance(spec, bool) or not isinstance(spec, (str, int, np.integer)):
        raise UsageError(f"map must be a block string such as 'OSX' or a block count, not {spec!r}")
    if isinstance(spec, str):
        unknown = sorted({letter for letter in spec if letter not in BUILDERS})
        if not spec or unknown:
            raise UsageError(
                f"map {spec!r}: unknown block letter(s) {unknown} (known: {''.join(BUILDERS)}; the "
                "spawn road I comes first by itself)"
                if unknown
                else "map '': a block string needs at least one block"
            )
        return tuple(spec)
    if spec < 1:
        raise UsageError(f"map {spec}: a map needs at least 1 block")
    return int(spec)


def build_blocks(
    plan: tuple[str, ...] | int,
    rng: np.random.Generator,
    first: Block,
    speed_limit_mps: float,
    signalised: bool,
) -> list[Block]:
    """The blocks after ``first`` (fixed letters, or a count drawn from BLOCK_PROBABILITIES),
    each built on a socket of the one before it, with BIG's retries and back-tracking."""
    total = 1 + (plan if isinstance(plan, int) else len(plan))
    letters, weights = list(BLOCK_PROBABILITIES), np.array(list(BLOCK_PROBABILITIES.values()))
    blocks, footprints = [first], [Footprint.of(first)]
    chosen: dict[int, tuple[str, int]] = {}  # position → (letter, socket of the block before)
    trials: dict[int, int] = {}
    builds = 0
    while len(blocks) < total:
        position = len(blocks)
        if position not in chosen:
            letter = plan[position - 1] if isinstance(plan, tuple) else str(rng.choice(letters, p=weights))
            chosen[position], trials[position] = (letter, int(rng.integers(len(blocks[-1].sockets)))), 0
        if trials[position] == MAX_TRIALS:  # rebuild the block before (never the spawn road)
            del chosen[position], trials[position]
            if position > 1:
                blocks.pop(), footprints.pop()
            continue
        trials[position] += 1
        builds += 1
        if builds > MAX_BUILDS:  # e.g. "yy" on 2 lanes: the second merge would leave none
            raise UsageError(
                f"map {plan!r}: no layout after {MAX_BUILDS} block builds (a block string can ask for "
                f"what cannot be built, such as merges below 1 lane or splits above {MAX_LANES})"
            )
        letter, socket = chosen[position]
        site = BlockSite(
            position, blocks[-1].sockets[socket], speed_limit_mps,
            sum(b.letter in JUNCTION_LETTERS for b in blocks), signalised,
        )  # fmt: skip
        try:
            block = BUILDERS[letter](site, sample_parameters(SPACES[letter], rng))
        except BlockFailed:
            continue
        footprint = Footprint.of(block)
        if max(s.lane_count for s in block.sockets) > MAX_LANES or overlaps(block, footprints, footprint):
            continue
        blocks.append(block)
        footprints.append(footprint)
    return blocks


@dataclass(frozen=True, eq=False)
class PGMap:
    """A procedural map.

    :param description: its roads (every block's lanes, junctions and lights).
    :param blocks: the blocks in order (``blocks[0]`` is the spawn road ``I``); each holds its
        entry socket, sockets (pose, lane count, width, node), parameters and lanes.
    :param lane_block: (L,) the block index of every description row.
    :param spawn_road: (``>``, ``>>``), the 10 m road the ego starts on (MetaDrive's).
    :param destination_road: the road whose end is the destination, on the last block.
    :param route: the roads from ``spawn_road`` to ``destination_road`` (fewest roads).
    :param seed: / ``lane_count`` / ``lane_width``: what it was generated with.
    """

    description: RoadDescription
    blocks: tuple[Block, ...]
    lane_block: np.ndarray
    spawn_road: tuple[str, str]
    destination_road: tuple[str, str]
    route: tuple[tuple[str, str], ...]
    seed: int
    lane_count: int
    lane_width: float

    @property
    def letters(self) -> str:
        """The block string, spawn road included (e.g. ``IOSX``)."""
        return "".join(block.letter for block in self.blocks)

    def road_rows(self, road: tuple[str, str]) -> np.ndarray:
        """(n,) description rows of the lanes of ``road``, left to right."""
        return np.array(self.description.graph[road[0]][road[1]], dtype=np.int64)

    @property
    def spawn_lanes(self) -> np.ndarray:
        return self.road_rows(self.spawn_road)

    @property
    def destination_lanes(self) -> np.ndarray:
        return self.road_rows(self.destination_road)

    @property
    def route_rows(self) -> np.ndarray:
        """(len(route),) the row of lane 0 of each route road."""
        return np.array([self.road_rows(road)[0] for road in self.route], dtype=np.int64)


def describe(blocks: list[Block]) -> tuple[RoadDescription, np.ndarray]:
    """The RoadDescription of ``blocks`` and the block of each of its rows (L,). A junction's arm-0
    approach (the previous block's road) is marked as ending at its stop line."""
    records, owner = [], []
    entries = {b.junction.entry_node: j for j, b in enumerate(x for x in blocks if x.junction)}
    for block in blocks:
        for lane in block.lanes:
            if lane.end_node in entries and lane.junction < 0:
                lane = dataclasses.replace(lane, end_junction=entries[lane.end_node], end_arm=0)
            records.append(lane)
            owner.append(block.index)
    junctions = [b.junction for b in blocks if b.junction]
    lights = [
        (j, arm, row)
        for j, x in enumerate(junctions)
        if x.signalised
        for arm, row in zip(x.arms, x.stop_lines, strict=True)
    ]
    description = RoadDescription.from_lanes(
        records,
        junction_centre=np.array([x.centre for x in junctions], dtype=float).reshape(-1, 2),
        junction_arms=tuple(x.arms for x in junctions),
        junction_signalised=np.array([x.signalised for x in junctions], dtype=bool),
        light_junction=np.array([j for j, _, _ in lights], dtype=np.int64),
        light_arm=np.array([arm for _, arm, _ in lights], dtype=np.int64),
        light_xyh=np.array([row for _, _, row in lights], dtype=float).reshape(-1, 3),
    )
    lane_block = np.array(owner, dtype=np.int64)[_graph_order(records)]
    lane_block.flags.writeable = False
    return description, lane_block


def generate_map(
    spec: str | int,
    seed: int,
    *,
    lane_count: int | None = None,
    lane_width_m: float | None = LANE_WIDTH_M,
    signalised: bool = False,
    speed_limit_mps: float = SPEED_LIMIT_MPS,
) -> PGMap:
    """The procedural map of ``spec`` (a block string such as ``"OSX"`` after the spawn road, or a
    number of random blocks) for ``seed``.

    :param lane_count: lanes per direction; None: drawn from {2, 3} (MetaDrive's random_lane_num).
    :param lane_width_m: None: drawn from U[3, 4.5] (MetaDrive's random_lane_width).
    :param signalised: traffic lights at the X and T intersections.
    :param speed_limit_mps: every lane's, except the ramps' 12 m/s.
    :raises UsageError: an unknown letter, an empty string or a count below 1.
    """
    plan = parse_spec(spec)
    rng = np.random.default_rng(seed)
    lanes = int(rng.choice(LANE_COUNTS)) if lane_count is None else int(lane_count)
    width = float(rng.uniform(*RANDOM_LANE_WIDTH_M)) if lane_width_m is None else float(lane_width_m)
    if not 1 <= lanes <= MAX_LANES:
        raise UsageError(f"lane_count {lanes}: must be 1 to {MAX_LANES}")
    blocks = build_blocks(plan, rng, first_block(lanes, width, speed_limit_mps), speed_limit_mps, signalised)
    description, lane_block = describe(blocks)
    goal = blocks[-1].sockets[int(rng.integers(len(blocks[-1].sockets)))].node
    spawn = (">", ">>")
    route = shortest_route(description.graph, spawn, goal)
    if not route:
        raise RuntimeError(f"map {spec!r} seed {seed}: no route from the spawn road to {goal}")
    return PGMap(
        description=description,
        blocks=tuple(blocks),
        lane_block=lane_block,
        spawn_road=spawn,
        destination_road=route[-1][:2],
        route=tuple(road[:2] for road in route),
        seed=int(seed),
        lane_count=lanes,
        lane_width=width,
    )
