"""A signalised town on highway-env's road network: two-way streets, T- and 4-way junctions, lights.

The town is a grid of junctions ``block_m`` apart joined by straight two-way streets with one lane
each way (right-hand traffic). Each junction is highway-env's own 4-way intersection geometry
(its incoming, straight, left- and right-turn lanes) moved to the junction's centre, with the
arms a T-junction lacks left out. Node names: ``J3:ir0`` is the stop line of junction 3's arm 0,
``J3:il2`` the start of its exit along arm 2; arm k points along ``rotation(90°·k) @ (0, 1)``
(arm 0 is +y, arm 1 is -x, arm 2 is -y, arm 3 is +x).

Lights: at every junction with three or more arms, arms 0 and 2 share one phase and arms 1 and 3
the other: green, yellow, all red, then the other axis. Each junction's cycle starts at its own
offset so that the town is not in lock-step.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from highway_env.road.lane import CircularLane, LineType, StraightLane
from highway_env.road.road import RoadNetwork

from drivelab.envs.backends.roads.town_arrays import TownRoadArrays, town_arrays_from_network
from drivelab.envs.backends.roads.town_arrays import shortest_route as graph_shortest_route
from drivelab.envs.backends.roads.town_rules import (  # noqa: F401 (re-exported for the town's users)
    ARM_DIRECTIONS,
    CROSSING_WIDTH_M,
    LANE_WIDTH_M,
    LEFT_TURN_RADIUS_M,
    OUTER_M,
    RIGHT_TURN_RADIUS_M,
    SPEED_LIMIT_MPS,
    TURN_SPEED_MPS,
    LightTimings,
    light_state,
)


@dataclass(frozen=True)
class TownLayout:
    """Which grid cells hold a junction and which neighbours a street joins.

    :param name: "train" or "test".
    :param junctions: (column, row) grid cells.
    :param streets: pairs of junction indices joined by a street (grid neighbours).
    :param block_m: distance between neighbouring junction centres.
    :param palette: colour theme name for renderers (the test town looks different).
    """

    name: str
    junctions: tuple[tuple[int, int], ...]
    streets: tuple[tuple[int, int], ...]
    block_m: float = 70.0
    palette: str = "day"

    def arms(self, junction: int) -> dict[int, int]:
        """{arm: neighbouring junction} of ``junction``."""
        column, row = self.junctions[junction]
        found = {}
        for a, b in self.streets:
            if junction not in (a, b):
                continue
            other = b if a == junction else a
            step = (self.junctions[other][0] - column, self.junctions[other][1] - row)
            found[ARM_DIRECTIONS.index(step)] = other
        return found

    def centre(self, junction: int) -> np.ndarray:
        column, row = self.junctions[junction]
        return np.array([column * self.block_m, row * self.block_m], dtype=float)


def _grid(columns: int, rows: int, missing: tuple[tuple[tuple[int, int], tuple[int, int]], ...]):
    cells = tuple((c, r) for r in range(rows) for c in range(columns))
    index = {cell: k for k, cell in enumerate(cells)}
    streets = []
    for (c, r), k in index.items():
        for step in ((1, 0), (0, 1)):
            other = (c + step[0], r + step[1])
            if other in index and ((c, r), other) not in missing:
                streets.append((k, index[other]))
    return cells, tuple(streets)


# Training town: 3 x 3 junctions: four corners, four T-junctions and one 4-way crossing.
_TRAIN = _grid(3, 3, missing=())
# Test town: a smaller 3 x 2 grid with shorter blocks (corners and T-junctions only), drawn in
# another palette: NoCrash's "new town, new weather" in spirit.
_TEST = _grid(3, 2, missing=())
LAYOUTS = {
    "train": TownLayout("train", *_TRAIN),
    "test": TownLayout("test", *_TEST, block_m=60.0, palette="dusk"),
}


def _rotation(arm: int) -> np.ndarray:
    angle = np.radians(90 * arm)
    return np.array([[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]])


def stop_line(layout: TownLayout, junction: int, arm: int) -> np.ndarray:
    """World position of the stop line at the end of ``arm``'s incoming lane."""
    return layout.centre(junction) + _rotation(arm) @ np.array([LANE_WIDTH_M / 2, OUTER_M])


def build_network(layout: TownLayout) -> RoadNetwork:
    """The town's lanes: in each junction highway-env's intersection lanes between the arms it
    has, and a straight street from each exit to the neighbour's incoming lane."""
    net = RoadNetwork()
    n, c, s = LineType.NONE, LineType.CONTINUOUS, LineType.STRIPED
    w = LANE_WIDTH_M
    for j in range(len(layout.junctions)):
        centre, arms = layout.centre(j), layout.arms(j)
        for k in arms:
            angle, rotation = np.radians(90 * k), _rotation(k)
            # turns and straight on from arm k, where the exit arm exists
            if (k - 1) % 4 in arms:
                net.add_lane(f"J{j}:ir{k}", f"J{j}:il{(k - 1) % 4}", CircularLane(
                    centre + rotation @ np.array([OUTER_M, OUTER_M]), RIGHT_TURN_RADIUS_M,
                    angle + np.radians(180), angle + np.radians(270),
                    line_types=[n, c], speed_limit=TURN_SPEED_MPS,
                ))  # fmt: skip
            if (k + 1) % 4 in arms:
                net.add_lane(f"J{j}:ir{k}", f"J{j}:il{(k + 1) % 4}", CircularLane(
                    centre + rotation @ np.array([-LEFT_TURN_RADIUS_M + w / 2, LEFT_TURN_RADIUS_M - w / 2]),
                    LEFT_TURN_RADIUS_M, angle, angle + np.radians(-90), clockwise=False,
                    line_types=[n, n], speed_limit=TURN_SPEED_MPS,
                ))  # fmt: skip
            if (k + 2) % 4 in arms:
                net.add_lane(f"J{j}:ir{k}", f"J{j}:il{(k + 2) % 4}", StraightLane(
                    centre + rotation @ np.array([w / 2, OUTER_M]),
                    centre + rotation @ np.array([w / 2, -OUTER_M]),
                    line_types=[n, n], speed_limit=SPEED_LIMIT_MPS,
                ))  # fmt: skip
    for a, b in layout.streets:
        for start_j, end_j in ((a, b), (b, a)):
            out_arm = next(k for k, other in layout.arms(start_j).items() if other == end_j)
            in_arm = (out_arm + 2) % 4
            start = layout.centre(start_j) + _rotation(out_arm) @ np.array([-w / 2, OUTER_M])
            net.add_lane(
                f"J{start_j}:il{out_arm}",
                f"J{end_j}:ir{in_arm}",
                StraightLane(
                    start, stop_line(layout, end_j, in_arm), line_types=[s, c], speed_limit=SPEED_LIMIT_MPS
                ),
            )
    return net


def street_crossings(layout: TownLayout) -> np.ndarray:
    """One zebra crossing in the middle of every street: rows (centre x, y, walking heading,
    length across the road, width along it)."""
    rows = []
    for a, b in layout.streets:
        centre = (layout.centre(a) + layout.centre(b)) / 2
        along = layout.centre(b) - layout.centre(a)
        heading = float(np.arctan2(along[1], along[0])) + np.pi / 2
        rows.append([*centre, heading, 2 * LANE_WIDTH_M, CROSSING_WIDTH_M])
    return np.array(rows, dtype=float).reshape(-1, 5)


def signalised(layout: TownLayout) -> list[tuple[int, int]]:
    """(junction, arm) of every approach that has a light: junctions with three or more arms."""
    return [(j, k) for j in range(len(layout.junctions)) if len(layout.arms(j)) >= 3 for k in layout.arms(j)]


def shortest_route(network: RoadNetwork, start: tuple[str, str], goal: str) -> list[tuple[str, str, int]]:
    """Lane indices from road ``start`` to node ``goal`` by breadth-first search (one lane per road);
    [] when the goal cannot be reached (``roads.town_arrays.shortest_route`` on the network's graph)."""
    return graph_shortest_route(network.graph, start, goal)


class TownLights:
    """Every signalised approach of a town: stop lines, headings, and their state at a time.

    :param layout: the town.
    :param timings: phase durations.
    :param offsets_s: per junction, where its cycle starts (drawn per episode).
    """

    @staticmethod
    def approach_of(lane_index: tuple) -> tuple[int, int] | None:
        """(junction, arm) when ``lane_index`` is a street ending at a stop line, else None (the
        simulator asks the lights, so that it need not know the town's node names)."""
        return approach_of(lane_index)

    def __init__(self, layout: TownLayout, timings: LightTimings, offsets_s: np.ndarray) -> None:
        self.layout, self.timings, self.offsets_s = layout, timings, np.asarray(offsets_s, dtype=float)
        self.approaches = signalised(layout)
        self.index = {approach: k for k, approach in enumerate(self.approaches)}
        self.positions = np.array([stop_line(layout, j, k) for j, k in self.approaches]).reshape(-1, 2)
        # arm k points along rotation(90°·k) @ (0, 1), at 90°·k + 90°; its incoming lane drives back
        self.headings = np.radians([90.0 * k - 90.0 for _, k in self.approaches])

    def state(self, junction: int, arm: int, time_s: float) -> int | None:
        """The light of one approach, or None where the junction has no lights."""
        if (junction, arm) not in self.index:
            return None
        return light_state(self.timings, arm, time_s, self.offsets_s[junction])

    def table(self, time_s: float) -> np.ndarray:
        """WorldState.traffic_lights rows: stop line x, y, approach heading, state."""
        states = [light_state(self.timings, k, time_s, self.offsets_s[j]) for j, k in self.approaches]
        return np.column_stack([self.positions, self.headings, states]).reshape(-1, 4)


def approach_of(lane_index: tuple) -> tuple[int, int] | None:
    """(junction, arm) when ``lane_index`` is a street ending at a stop line, else None."""
    _to = lane_index[1]
    if ":ir" not in _to:
        return None
    junction, arm = _to[1:].split(":ir")
    return int(junction), int(arm)


def road_arrays(layout: TownLayout) -> TownRoadArrays:
    """The compiled kernels' arrays of ``layout`` (lane metadata, lights, crossings, routes)."""
    lights = TownLights(layout, LightTimings(), np.zeros(len(layout.junctions)))
    return town_arrays_from_network(
        build_network(layout),
        lights.approaches,
        np.column_stack([lights.positions, lights.headings]),
        street_crossings(layout),
        len(layout.junctions),
    )
