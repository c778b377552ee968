"""A road description as highway-env's ``RoadNetwork`` (for the ``highway`` reference backend).

The only module of the roads package that imports highway-env. Lanes are added in the
description's row order, which is highway-env's graph order, with the description's numbers, so
that highway-env computes the same lengths, directions and headings as the compiled core.
"""

from __future__ import annotations

import numpy as np
from highway_env.road.lane import CircularLane, StraightLane
from highway_env.road.road import RoadNetwork

from drivelab.sim.roads.description import ARC, RoadDescription


def to_road_network(desc: RoadDescription) -> RoadNetwork:
    """highway-env lanes of every row of ``desc`` (line types are highway-env's LineType values)."""
    network = RoadNetwork()
    for row, (start_node, end_node, _) in enumerate(desc.indices):
        limit = desc.speed_limit[row]
        common = {
            "width": float(desc.width[row]),
            "line_types": [int(v) for v in desc.lines[row]],
            "forbidden": bool(desc.forbidden[row]),
            "speed_limit": None if np.isnan(limit) else float(limit),
            "priority": int(desc.priority[row]),
        }
        if desc.kind[row] == ARC:
            lane = CircularLane(
                desc.centre[row].copy(), float(desc.radius[row]), float(desc.start_phase[row]),
                float(desc.end_phase[row]), clockwise=bool(desc.clockwise[row]), **common,
            )  # fmt: skip
        else:
            lane = StraightLane(desc.start[row].copy(), desc.end[row].copy(), **common)
        network.add_lane(start_node, end_node, lane)
    return network
