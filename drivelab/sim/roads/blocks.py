"""The block vocabulary roads are described with, and the two roads drivelab composes from it.

- ``Straight`` and ``Arc``: segments of parallel lanes, chained by pose (position and heading).
- ``Junction`` (``Junction.x``, ``Junction.t``, ``Junction.corner``): highway-env's intersection
  geometry at a junction centre (right turns of radius w + 5, left turns of radius w + 5 + w,
  straight on), for the arms it has; signalised or not.
- ``grid``/``town``: junctions on a grid joined by two-way streets (the town); ``circuit``: a closed
  loop of straights and arcs (the CARLA study's circuits).

Town conventions: arm k of a junction points along ``rotation(90°·k) @ (0, 1)`` (arm 0 is +y, arm
1 is -x, arm 2 is -y, arm 3 is +x); ``J3:ir0`` is the stop line of junction 3's arm 0, ``J3:il2``
the start of its exit along arm 2.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from drivelab.sim.junctions.rows import TURN_LEFT, TURN_RIGHT, TURN_STRAIGHT
from drivelab.sim.junctions.rules import (
    ARM_DIRECTIONS,
    CROSSING_WIDTH_M,
    LANE_WIDTH_M,
    LEFT_TURN_RADIUS_M,
    OUTER_M,
    RIGHT_TURN_RADIUS_M,
    SPEED_LIMIT_MPS,
    TURN_SPEED_MPS,
    LightTimings,
)
from drivelab.sim.roads.description import (
    ARC,
    LINE_CONTINUOUS,
    LINE_NONE,
    LINE_STRIPED,
    STRAIGHT,
    LaneRecord,
    RoadDescription,
)
from drivelab.sim.roads.road_map import lane_points, lane_stations

Cell = tuple[int, int]


# --- segments chained by pose ------------------------------------------------------------------
@dataclass(frozen=True)
class Straight:
    """A straight segment ``length_m`` long: ``lane`` lays each of its parallel lanes."""

    length_m: float

    def lane(self, position, heading: float, offset: float, **lane) -> LaneRecord:
        """The lane ``offset`` to the right of the reference line starting at the pose."""
        normal = np.array([-np.sin(heading), np.cos(heading)])  # to the right
        direction = np.array([np.cos(heading), np.sin(heading)])
        start = position + offset * normal
        return LaneRecord(
            kind=STRAIGHT, start=tuple(start), end=tuple(start + self.length_m * direction), **lane
        )


@dataclass(frozen=True)
class Arc:
    """A circular segment turning ``turn_deg`` (positive: to the right, heading grows with y
    pointing right) with ``radius_m`` along its reference line: ``lane`` lays each parallel lane."""

    radius_m: float
    turn_deg: float

    def lane(self, position, heading: float, offset: float, **lane) -> LaneRecord:
        """The lane ``offset`` to the right of the reference line starting at the pose."""
        normal = np.array([-np.sin(heading), np.cos(heading)])  # to the right
        side = 1.0 if self.turn_deg > 0 else -1.0
        centre = position + side * self.radius_m * normal
        start_phase = heading - side * np.pi / 2
        return LaneRecord(
            kind=ARC, centre=tuple(centre), radius=self.radius_m - side * offset, start_phase=start_phase,
            end_phase=start_phase + np.radians(self.turn_deg), clockwise=side > 0, **lane,
        )  # fmt: skip


def road_lines(k: int, count: int) -> tuple[int, int]:
    """(left, right) markings of lane ``k`` of ``count``: the outer lines solid, the lines between
    lanes dashed (each drawn once, on the left of the lane right of it)."""
    left = LINE_CONTINUOUS if k == 0 else LINE_STRIPED
    right = LINE_CONTINUOUS if k == count - 1 else LINE_NONE
    return left, right


def segment(spec: tuple) -> Straight | Arc:
    """A track entry ``("straight", length_m)`` or ``("arc", radius_m, turn_deg)`` as a block."""
    kind, *values = spec
    return Straight(*values) if kind == "straight" else Arc(*values)


def circuit(
    track, lane_count: int, lane_width_m: float, speed_limit_mps: float, guide_line: bool = False
) -> RoadDescription:
    """A closed road of ``lane_count`` parallel lanes along ``track`` (``segment`` entries starting
    at the origin heading +x).

    Lane 0 is the leftmost; the outer lines are solid, the lines between lanes dashed. Nodes are
    named "0", "1", … so that node ``k`` starts segment ``k`` and the last segment ends at "0".
    ``guide_line``: a line painted along the centre of lane 0, one lap from node "0".
    """
    records = []
    position, heading = np.zeros(2), 0.0
    offsets = (np.arange(lane_count) - (lane_count - 1) / 2) * lane_width_m
    for index, spec in enumerate(track):
        block = segment(spec)
        start, end = str(index), str((index + 1) % len(track))
        for lane_id, offset in enumerate(offsets):
            lines = road_lines(lane_id, lane_count)
            records.append(
                block.lane(
                    position, heading, offset, start_node=start, end_node=end, lines=lines,
                    width=lane_width_m, speed_limit=speed_limit_mps,
                )
            )  # fmt: skip
        reference = records[-lane_count]  # lane 0 of this segment
        position = reference.position(reference.length, -offsets[0])
        heading = float(reference.heading_at(reference.length))
    guide = ()
    if guide_line:
        lap = records[::lane_count]
        guide = (np.concatenate([lane_points(lane, lane_stations(lane), 0.0) for lane in lap]),)
    return RoadDescription.from_lanes(records, guide_lines=guide)


# --- junctions ---------------------------------------------------------------------------------
def rotation(arm: int) -> np.ndarray:
    """(2, 2) rotation by 90°·arm (exactly as highway-env's intersection builds its arms, so
    cos(90°) is 6e-17, not 0)."""
    angle = np.radians(90 * arm)
    return np.array([[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]])


def stop_line(centre: np.ndarray, arm: int) -> np.ndarray:
    """(2,) world position of the stop line at the end of ``arm``'s incoming lane."""
    return centre + rotation(arm) @ np.array([LANE_WIDTH_M / 2, OUTER_M])


@dataclass(frozen=True)
class Junction:
    """highway-env's intersection geometry between the arms a junction has.

    :param arms: the arms present (0..3), in the order their lanes are laid (each arm's right
        turn, left turn, then straight on, where the exit arm exists).
    :param signalised: traffic lights on every approach (arms 0/2, then 1/3).
    """

    arms: tuple[int, ...]
    signalised: bool = False

    @staticmethod
    def x(arms: tuple[int, ...] = (0, 1, 2, 3), signalised: bool = True) -> Junction:
        """A 4-way junction (``arms``: the four arms, in laying order)."""
        assert sorted(arms) == [0, 1, 2, 3]
        return Junction(tuple(arms), signalised)

    @staticmethod
    def t(missing_arm: int, arms: tuple[int, ...] | None = None, signalised: bool = True) -> Junction:
        """A T-junction without ``missing_arm``."""
        arms = tuple(k for k in range(4) if k != missing_arm) if arms is None else tuple(arms)
        assert sorted(arms) == sorted(k for k in range(4) if k != missing_arm)
        return Junction(arms, signalised)

    @staticmethod
    def corner(arms: tuple[int, int]) -> Junction:
        """A 2-arm junction (a bend, or a straight join), unsignalised."""
        assert len(arms) == 2
        return Junction(tuple(arms), False)

    def lanes(self, centre: np.ndarray, index: int) -> list[LaneRecord]:
        """The junction's lanes, as junction ``index`` at ``centre`` (2,)."""
        w, records = LANE_WIDTH_M, []
        left_centre = np.array([-LEFT_TURN_RADIUS_M + w / 2, LEFT_TURN_RADIUS_M - w / 2])
        for k in self.arms:
            angle, turn = np.radians(90 * k), rotation(k)
            nodes = {"start_node": f"J{index}:ir{k}", "junction": index, "from_arm": k}
            # turns and straight on from arm k, where the exit arm exists
            if (k - 1) % 4 in self.arms:
                records.append(LaneRecord(
                    end_node=f"J{index}:il{(k - 1) % 4}", to_arm=(k - 1) % 4, turn=TURN_RIGHT, kind=ARC,
                    centre=tuple(centre + turn @ np.array([OUTER_M, OUTER_M])), radius=RIGHT_TURN_RADIUS_M,
                    start_phase=angle + np.radians(180), end_phase=angle + np.radians(270),
                    lines=(LINE_NONE, LINE_CONTINUOUS), speed_limit=TURN_SPEED_MPS, width=w, **nodes,
                ))  # fmt: skip
            if (k + 1) % 4 in self.arms:
                records.append(LaneRecord(
                    end_node=f"J{index}:il{(k + 1) % 4}", to_arm=(k + 1) % 4, turn=TURN_LEFT, kind=ARC,
                    centre=tuple(centre + turn @ left_centre),
                    radius=LEFT_TURN_RADIUS_M, start_phase=angle, end_phase=angle + np.radians(-90),
                    clockwise=False, lines=(LINE_NONE, LINE_NONE), speed_limit=TURN_SPEED_MPS, width=w,
                    **nodes,
                ))  # fmt: skip
            if (k + 2) % 4 in self.arms:
                records.append(LaneRecord(
                    end_node=f"J{index}:il{(k + 2) % 4}", to_arm=(k + 2) % 4, turn=TURN_STRAIGHT,
                    kind=STRAIGHT, start=tuple(centre + turn @ np.array([w / 2, OUTER_M])),
                    end=tuple(centre + turn @ np.array([w / 2, -OUTER_M])), lines=(LINE_NONE, LINE_NONE),
                    speed_limit=SPEED_LIMIT_MPS, width=w, **nodes,
                ))  # fmt: skip
        return records


# --- the town ----------------------------------------------------------------------------------
def grid_cells(
    columns: int, rows: int, missing: tuple[tuple[Cell, Cell], ...] = ()
) -> tuple[tuple[Cell, ...], tuple[tuple[int, int], ...]]:
    """Junction cells (column, row), row-major, and the streets joining grid neighbours (pairs of
    cell indices) except the ``missing`` (cell, cell) links."""
    cells = tuple((c, r) for r in range(rows) for c in range(columns))
    index = {cell: k for k, cell in enumerate(cells)}
    return cells, tuple(
        (k, index[other])
        for (c, r), k in index.items()
        for other in ((c + 1, r), (c, r + 1))
        if other in index and ((c, r), other) not in missing
    )


def junction_arms(
    cells: tuple[Cell, ...], streets: tuple[tuple[int, int], ...], junction: int
) -> dict[int, int]:
    """{arm: neighbouring junction} of ``junction``, in the order of ``streets``."""
    column, row = cells[junction]
    neighbours = [b if a == junction else a for a, b in streets if junction in (a, b)]
    return {ARM_DIRECTIONS.index((cells[n][0] - column, cells[n][1] - row)): n for n in neighbours}


def cell_centre(cell: Cell, block_m: float) -> np.ndarray:
    """(2,) world position of a grid cell's junction centre."""
    column, row = cell
    return np.array([column * block_m, row * block_m], dtype=float)


def junction_block(arms: tuple[int, ...]) -> Junction:
    """The block a grid cell with these arms (laying order) gets: signalised with three or more."""
    return Junction(tuple(arms), signalised=len(arms) >= 3)


def town(
    cells: tuple[Cell, ...],
    streets: tuple[tuple[int, int], ...],
    block_m: float,
    palette: str = "day",
    timings: LightTimings = LightTimings(),
) -> RoadDescription:
    """Junctions at ``cells`` (``block_m`` apart) joined by ``streets``: in each junction the lanes
    of its block, and a straight one-lane street each way between neighbours (right-hand traffic).
    Lights at every junction with three or more arms; a zebra crossing mid-street."""
    w = LANE_WIDTH_M
    centres = [cell_centre(cell, block_m) for cell in cells]
    arms = [junction_arms(cells, streets, j) for j in range(len(cells))]
    blocks = [junction_block(tuple(a)) for a in arms]
    records = [lane for j, block in enumerate(blocks) for lane in block.lanes(centres[j], j)]
    crossing_lanes, crossings = [], []
    for a, b in streets:
        for start_j, end_j in ((a, b), (b, a)):
            out_arm = next(k for k, other in arms[start_j].items() if other == end_j)
            in_arm = (out_arm + 2) % 4
            start = centres[start_j] + rotation(out_arm) @ np.array([-w / 2, OUTER_M])
            records.append(LaneRecord(
                f"J{start_j}:il{out_arm}", f"J{end_j}:ir{in_arm}", STRAIGHT, start=tuple(start),
                end=tuple(stop_line(centres[end_j], in_arm)), lines=(LINE_STRIPED, LINE_CONTINUOUS),
                speed_limit=SPEED_LIMIT_MPS, width=w, end_junction=end_j, end_arm=in_arm,
            ))  # fmt: skip
        crossing_lanes.append((len(records) - 2, len(records) - 1))
        centre = (centres[a] + centres[b]) / 2
        along = centres[b] - centres[a]
        heading = float(np.arctan2(along[1], along[0])) + np.pi / 2
        crossings.append([*centre, heading, 2 * LANE_WIDTH_M, CROSSING_WIDTH_M])
    lights = [(j, k) for j, block in enumerate(blocks) if block.signalised for k in block.arms]
    positions = np.array([stop_line(centres[j], k) for j, k in lights]).reshape(-1, 2)
    # arm k points along rotation(90°·k) @ (0, 1), at 90°·k + 90°; its incoming lane drives back
    headings = np.radians([90.0 * k - 90.0 for _, k in lights])
    return RoadDescription.from_lanes(
        records,
        junction_centre=np.array(centres, dtype=float).reshape(-1, 2),
        junction_arms=tuple(block.arms for block in blocks),
        junction_signalised=np.array([block.signalised for block in blocks], dtype=bool),
        light_junction=np.array([j for j, _ in lights], dtype=np.int64),
        light_arm=np.array([k for _, k in lights], dtype=np.int64),
        light_xyh=np.column_stack([positions, headings]).reshape(-1, 3),
        timings=timings,
        crossings=np.array(crossings, dtype=float).reshape(-1, 5),
        crossing_lanes=np.array(crossing_lanes, dtype=np.int64).reshape(-1, 2),
        palette=palette,
    )


def grid(
    columns: int, rows: int, block_m: float, missing: tuple[tuple[Cell, Cell], ...] = (), palette: str = "day"
) -> RoadDescription:
    """A town of ``columns`` × ``rows`` junctions ``block_m`` apart, every grid neighbour joined
    except the ``missing`` links (``palette``: the renderers' colour theme)."""
    cells, streets = grid_cells(columns, rows, missing)
    return town(cells, streets, block_m, palette)
