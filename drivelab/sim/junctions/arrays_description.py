"""The town's kernel arrays (``TownRoadArrays``) read from its road description, not from node
names: the lane metadata the blocks recorded, the light table, the crossings, and the table of
every shortest route between the streets."""

from __future__ import annotations

from drivelab.sim.junctions.arrays import TownRoadArrays, route_table
from drivelab.sim.junctions.rows import LANE_METADATA
from drivelab.sim.roads.description import RoadDescription


def town_arrays(desc: RoadDescription) -> TownRoadArrays:
    """``desc``'s TownRoadArrays (rows in its lane order, which is ``LaneTable``'s)."""
    streets = desc.street_lanes
    routes, lengths = route_table(desc.graph, list(desc.indices), streets)
    return TownRoadArrays(
        **{name: getattr(desc, name).copy() for name in LANE_METADATA},
        in_junction=desc.in_junction,
        light_xyh=desc.light_xyh.copy(),
        light_junction=desc.light_junction.copy(),
        light_arm=desc.light_arm.copy(),
        junction_count=desc.junction_count,
        crossings=desc.crossings.copy(),
        street_lanes=streets,
        routes=routes,
        route_length=lengths,
    )
