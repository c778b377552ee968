"""A road network as plain arrays: lanes as straight and circular segments, their markings and
connectivity, junction metadata, traffic lights, zebra crossings and guide lines.

Both simulators read one ``RoadDescription``: the compiled core through ``LaneTable`` and
``road_map``, the highway-env reference through ``highway_network.to_road_network``. Nothing here
imports highway-env. Lanes are kept in highway-env's graph order (origin node by first use, then
destination, then lane id), the order in which highway-env breaks ties, so that lane rows, lane
indices and routes mean the same on both backends.

The lane formulas (``LaneRecord.length``, ``position``, ``heading_at``) are highway-env's own
(``highway_env/road/lane.py``), written in its floating-point order, so that what is derived here
(the next block's pose, the sampled polylines) agrees with highway-env to the last bit.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field

import numpy as np

from drivelab.sim.junctions.rules import LightTimings

STRAIGHT, ARC = 0, 1  # lane kinds
LINE_NONE, LINE_STRIPED, LINE_CONTINUOUS = 0, 1, 2  # highway-env's LineType values


@dataclass(frozen=True)
class LaneRecord:
    """One lane while a road is being composed.

    :param start_node: / ``end_node``: the nodes the lane joins (highway-env's ``_from``, ``_to``).
    :param kind: STRAIGHT (``start`` → ``end``) or ARC (``centre``, ``radius``, phases, sense).
    :param lines: marking on the (left, right) side: LINE_NONE / LINE_STRIPED / LINE_CONTINUOUS.
    :param junction: the junction it crosses (-1: a street); ``from_arm`` → ``to_arm`` and ``turn``
        (TURN_RIGHT / TURN_STRAIGHT / TURN_LEFT) there.
    :param end_junction: / ``end_arm``: the junction approach (stop line) the lane ends at, else -1.
    """

    start_node: str
    end_node: str
    kind: int
    start: tuple[float, float] = (np.nan, np.nan)
    end: tuple[float, float] = (np.nan, np.nan)
    centre: tuple[float, float] = (np.nan, np.nan)
    radius: float = np.nan
    start_phase: float = np.nan
    end_phase: float = np.nan
    clockwise: bool = True
    width: float = 4.0
    lines: tuple[int, int] = (LINE_STRIPED, LINE_STRIPED)
    speed_limit: float = 20.0
    priority: int = 0
    forbidden: bool = False
    junction: int = -1
    from_arm: int = -1
    to_arm: int = -1
    turn: int = -1
    end_junction: int = -1
    end_arm: int = -1

    @property
    def sense(self) -> int:
        """highway-env's CircularLane.direction: 1 clockwise, -1 counter-clockwise."""
        return 1 if self.clockwise else -1

    @property
    def length(self) -> float:
        if self.kind == ARC:
            return self.radius * (self.end_phase - self.start_phase) * self.sense
        return np.linalg.norm(np.array(self.end) - np.array(self.start))

    def position(self, longitudinal: float, lateral: float) -> np.ndarray:
        """World point (2,) at (longitudinal, lateral) of the lane."""
        if self.kind == ARC:
            phi = self.sense * longitudinal / self.radius + self.start_phase
            unit = np.array([np.cos(phi), np.sin(phi)])
            return np.array(self.centre) + (self.radius - lateral * self.sense) * unit
        start, end = np.array(self.start), np.array(self.end)
        direction = (end - start) / self.length
        return start + longitudinal * direction + lateral * np.array([-direction[1], direction[0]])

    def heading_at(self, longitudinal: float) -> float:
        if self.kind == ARC:
            phi = self.sense * longitudinal / self.radius + self.start_phase
            return phi + np.pi / 2 * self.sense
        return np.arctan2(self.end[1] - self.start[1], self.end[0] - self.start[0])


# the LaneRecord fields a RoadDescription keeps as (L,) columns, (L, 2) for the pairs
_COLUMNS = {
    **dict.fromkeys(
        ("start", "end", "centre", "radius", "start_phase", "end_phase", "width", "speed_limit"), float
    ),
    **dict.fromkeys(("kind", "lines", "priority", "junction", "from_arm", "to_arm", "turn"), np.int64),
    **dict.fromkeys(("end_junction", "end_arm"), np.int64),
    **dict.fromkeys(("clockwise", "forbidden"), bool),
}
_PAIRS = ("start", "end", "centre", "lines")


def _column(records: list[LaneRecord], name: str) -> np.ndarray:
    column = np.array([getattr(record, name) for record in records], dtype=_COLUMNS[name])
    return column.reshape(-1, 2) if name in _PAIRS else column


@dataclass(frozen=True, eq=False)
class RoadDescription:
    """A road network as arrays (build one with ``RoadDescription.from_lanes`` or ``blocks``).

    Lanes (L rows, highway-env graph order):
    :param nodes: node names (highway-env's: ``J3:ir0``, ``"0"``), in order of first use by a lane.
    :param lane_from: / ``lane_to`` (L,) positions in ``nodes``; ``lane_id`` (L,) id on its road.
    :param kind: (L,) STRAIGHT or ARC.
    :param start: / ``end`` (L, 2): a straight lane's ends (NaN on arcs).
    :param centre: (L, 2), ``radius``, ``start_phase``, ``end_phase`` (L,), ``clockwise`` (L,)
        bool: an arc's circle (NaN on straight lanes).
    :param width: (L,); ``lines`` (L, 2) left and right marking; ``speed_limit`` (L,);
        ``priority`` (L,) int; ``forbidden`` (L,) bool.
    :param junction: (L,) junction crossed (-1: a street), ``from_arm``, ``to_arm``, ``turn``
        (TURN_* of ``fast.town_rows``, -1 on streets); ``end_junction``, ``end_arm`` (L,) the
        approach a lane ends at (-1 none); ``light`` (L,) that approach's light row (-1 none).
    Junctions (J): ``junction_centre`` (J, 2); ``junction_arms`` the arms of each, in the order
    its lanes were laid (highway-env's order); ``junction_signalised`` (J,) bool.
    Lights (M, junction-major): ``light_junction``, ``light_arm`` (M,), ``light_xyh`` (M, 3) stop
    line x, y and approach heading; a light's phase group is its arm % 2; ``timings``.
    ``crossings`` (C, 5) centre x, y, walking heading, length across, width along; ``crossing_lanes``
    (C, 2) the two street lanes each crosses. ``guide_lines``: painted polylines (P_i, 2).
    ``palette``: the renderers' colour theme.
    """

    nodes: tuple[str, ...]
    lane_from: np.ndarray
    lane_to: np.ndarray
    lane_id: np.ndarray
    kind: np.ndarray
    start: np.ndarray
    end: np.ndarray
    centre: np.ndarray
    radius: np.ndarray
    start_phase: np.ndarray
    end_phase: np.ndarray
    clockwise: np.ndarray
    width: np.ndarray
    lines: np.ndarray
    speed_limit: np.ndarray
    priority: np.ndarray
    forbidden: np.ndarray
    junction: np.ndarray
    from_arm: np.ndarray
    to_arm: np.ndarray
    turn: np.ndarray
    end_junction: np.ndarray
    end_arm: np.ndarray
    light: np.ndarray
    junction_centre: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    junction_arms: tuple[tuple[int, ...], ...] = ()
    junction_signalised: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=bool))
    light_junction: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    light_arm: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    light_xyh: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    timings: LightTimings = LightTimings()
    crossings: np.ndarray = field(default_factory=lambda: np.zeros((0, 5)))
    crossing_lanes: np.ndarray = field(default_factory=lambda: np.zeros((0, 2), dtype=np.int64))
    guide_lines: tuple[np.ndarray, ...] = ()
    palette: str = "day"

    def __post_init__(self) -> None:
        # a description is shared (the town's is cached per layout): its arrays are read-only
        for value in vars(self).values():
            for array in value if isinstance(value, tuple) else (value,):
                if isinstance(array, np.ndarray):
                    array.flags.writeable = False

    @staticmethod
    def from_lanes(records: list[LaneRecord], **rest) -> RoadDescription:
        """A description of ``records`` put in highway-env's graph order (a stable grouping by
        origin node, then destination node, each by first use); ``rest``: the other fields
        (``crossing_lanes`` as positions in ``records``). Each lane's ``light`` is the row of
        (end_junction, end_arm) among (``light_junction``, ``light_arm``), else -1."""
        order = _graph_order(records)
        records = [records[k] for k in order]
        nodes = tuple(dict.fromkeys(node for r in records for node in (r.start_node, r.end_node)))
        node_of = {node: k for k, node in enumerate(nodes)}
        lane_id, seen = [], {}
        for r in records:
            key = (r.start_node, r.end_node)
            lane_id.append(seen.get(key, 0))
            seen[key] = lane_id[-1] + 1
        lights = zip(rest.get("light_junction", ()), rest.get("light_arm", ()), strict=True)
        light_of = {(int(j), int(k)): m for m, (j, k) in enumerate(lights)}
        light = [light_of.get((r.end_junction, r.end_arm), -1) for r in records]
        crossing_lanes = rest.pop("crossing_lanes", None)
        if crossing_lanes is not None:  # given as positions in ``records`` before the ordering
            position = np.argsort(order)
            rest["crossing_lanes"] = position[np.asarray(crossing_lanes, dtype=np.int64)].reshape(-1, 2)
        return RoadDescription(
            nodes=nodes,
            lane_from=np.array([node_of[r.start_node] for r in records], dtype=np.int64),
            lane_to=np.array([node_of[r.end_node] for r in records], dtype=np.int64),
            lane_id=np.array(lane_id, dtype=np.int64),
            **{name: _column(records, name) for name in _COLUMNS},
            light=np.array(light, dtype=np.int64),
            **rest,
        )

    @property
    def lane_count(self) -> int:
        return len(self.kind)

    @property
    def in_junction(self) -> np.ndarray:
        """(L,) bool: the lane crosses a junction."""
        return self.junction >= 0

    @property
    def junction_count(self) -> int:
        return len(self.junction_centre)

    def lane(self, row: int) -> LaneRecord:
        """Lane ``row`` as a record (its geometry formulas: length, position, heading)."""
        return LaneRecord(
            self.nodes[self.lane_from[row]], self.nodes[self.lane_to[row]], int(self.kind[row]),
            start=tuple(self.start[row]), end=tuple(self.end[row]), centre=tuple(self.centre[row]),
            radius=self.radius[row], start_phase=self.start_phase[row], end_phase=self.end_phase[row],
            clockwise=bool(self.clockwise[row]), width=self.width[row],
            lines=tuple(int(v) for v in self.lines[row]), speed_limit=self.speed_limit[row],
            priority=int(self.priority[row]), forbidden=bool(self.forbidden[row]),
        )  # fmt: skip

    @property
    def indices(self) -> tuple[tuple[str, str, int], ...]:
        """highway-env lane index (from, to, id) of every row."""
        return tuple(
            (self.nodes[f], self.nodes[t], int(i))
            for f, t, i in zip(self.lane_from, self.lane_to, self.lane_id, strict=True)
        )

    @functools.cached_property
    def graph(self) -> dict[str, dict[str, list[int]]]:
        """{from node: {to node: lane rows}} in highway-env's order (its ``RoadNetwork.graph``
        with rows in place of lanes): what route searches walk."""
        graph: dict[str, dict[str, list[int]]] = {}
        for row, (f, t, _) in enumerate(self.indices):
            graph.setdefault(f, {}).setdefault(t, []).append(row)
        return graph

    @property
    def street_lanes(self) -> np.ndarray:
        """(S,) rows of the lanes that end at a junction approach (the town's streets), in row order."""
        return np.flatnonzero(self.end_junction >= 0).astype(np.int64)


def _graph_order(records: list[LaneRecord]) -> list[int]:
    """Positions of ``records`` in highway-env's graph iteration order after adding them in turn."""
    graph: dict[str, dict[str, list[int]]] = {}
    for k, r in enumerate(records):
        graph.setdefault(r.start_node, {}).setdefault(r.end_node, []).append(k)
    return [k for to in graph.values() for rows in to.values() for k in rows]
