"""A signalised town: two-way streets, T- and 4-way junctions, lights.

The town is a grid of junctions ``block_m`` apart joined by straight two-way streets with one lane
each way (right-hand traffic); each junction is highway-env's 4-way intersection geometry, less the
arms a T-junction lacks. The road is described as blocks (``roads.blocks.town``, which gives the
node names and arm directions); ``build_network`` turns it into highway-env lanes for the reference
backend, and the compiled core reads the description itself.

Lights: at every junction with three or more arms, arms 0 and 2 share one phase and arms 1 and 3
the other: green, yellow, all red, then the other axis. Each junction's cycle starts at its own
offset so that the town is not in lock-step.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from drivelab.sim.junctions.arrays import shortest_route as graph_shortest_route
from drivelab.sim.junctions.rules import LightTimings, light_state
from drivelab.sim.roads import blocks
from drivelab.sim.roads.description import RoadDescription

if TYPE_CHECKING:
    from highway_env.road.road import RoadNetwork


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


LAYOUTS = {
    # 3 x 3 junctions: four corners, four T-junctions and one 4-way crossing
    "train": TownLayout("train", *blocks.grid_cells(3, 3)),
    # a smaller 3 x 2 grid with shorter blocks (corners and T-junctions only), drawn in another
    # palette: NoCrash's "new town, new weather" in spirit
    "test": TownLayout("test", *blocks.grid_cells(3, 2), block_m=60.0, palette="dusk"),
}


@functools.cache
def road_description(layout: TownLayout) -> RoadDescription:
    """The town's road (lanes, junctions, lights, crossings) as blocks: a junction block at each
    grid cell (its kind follows from its arms) and a two-way street between neighbours."""
    return blocks.town(layout.junctions, layout.streets, layout.block_m, layout.palette)


def build_network(layout: TownLayout) -> RoadNetwork:
    """The town's lanes as a highway-env network: in each junction highway-env's intersection
    lanes between the arms it has, and a straight street from each exit to the neighbour's
    incoming lane."""
    from drivelab.sim.roads.highway_network import to_road_network

    return to_road_network(road_description(layout))


def street_crossings(layout: TownLayout) -> np.ndarray:
    """One zebra crossing in the middle of every street: rows (centre x, y, walking heading,
    length across the road, width along it)."""
    return road_description(layout).crossings.copy()


def shortest_route(network: RoadNetwork, start: tuple[str, str], goal: str) -> list[tuple[str, str, int]]:
    """Lane indices from road ``start`` to node ``goal`` by breadth-first search (one lane per road);
    [] when the goal cannot be reached (``roads.town_arrays.shortest_route`` on the network's graph)."""
    return graph_shortest_route(network.graph, start, goal)


def approach_of(lane_index: tuple) -> tuple[int, int] | None:
    """(junction, arm) when ``lane_index`` is a street ending at a stop line, else None."""
    _to = lane_index[1]
    if ":ir" not in _to:
        return None
    junction, arm = _to[1:].split(":ir")
    return int(junction), int(arm)


class TownLights:
    """Every signalised approach of a town: stop lines, headings, and their state at a time.

    :param layout: the town.
    :param timings: phase durations.
    :param offsets_s: per junction, where its cycle starts (drawn per episode).
    """

    # the simulator asks the lights, so that it need not know the town's node names
    approach_of = staticmethod(approach_of)

    def __init__(self, layout: TownLayout, timings: LightTimings, offsets_s: np.ndarray) -> None:
        self.layout, self.timings, self.offsets_s = layout, timings, np.asarray(offsets_s, dtype=float)
        desc = road_description(layout)  # the approaches with a light: junctions of three arms or more
        self.approaches = [(int(j), int(k)) for j, k in zip(desc.light_junction, desc.light_arm, strict=True)]
        self.index = {approach: k for k, approach in enumerate(self.approaches)}
        self.positions, self.headings = desc.light_xyh[:, :2].copy(), desc.light_xyh[:, 2].copy()

    def state(self, junction: int, arm: int, time_s: float) -> int | None:
        """The light of one approach, or None where the junction has no lights."""
        if (junction, arm) not in self.index:
            return None
        return light_state(self.timings, arm, time_s, self.offsets_s[junction])

    def table(self, time_s: float) -> np.ndarray:
        """WorldState.traffic_lights rows: stop line x, y, approach heading, state."""
        states = [light_state(self.timings, k, time_s, self.offsets_s[j]) for j, k in self.approaches]
        return np.column_stack([self.positions, self.headings, states]).reshape(-1, 4)
