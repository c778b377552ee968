"""A road description's ``RoadMap`` (lane outlines, centre lines, markings, edges, crossings,
guide lines) without highway-env: sampled as ``highway.build_road_map`` samples highway-env's
lanes, with the same lane formulas, so that the arrays are the same to the last bit."""

from __future__ import annotations

import numpy as np

from drivelab.envs.backends.roads.description import (
    LINE_CONTINUOUS,
    LINE_NONE,
    STRAIGHT,
    LaneRecord,
    RoadDescription,
)
from drivelab.world.state import RoadMap

SAMPLE_SPACING_M = 2.0  # curved lanes are turned into polylines with points this far apart


def lane_stations(lane: LaneRecord) -> np.ndarray:
    """Arc-length stations at which to sample a lane: its ends, plus every 2 m if curved."""
    length = lane.length
    if lane.kind == STRAIGHT:
        return np.array([0.0, length])
    count = max(int(np.ceil(length / SAMPLE_SPACING_M)), 1)
    return np.linspace(0.0, length, count + 1)


def lane_points(lane: LaneRecord, stations: np.ndarray, lateral: float | np.ndarray) -> np.ndarray:
    """(len(stations), 2) points of the lane at ``stations`` and ``lateral`` offsets."""
    lateral = np.broadcast_to(lateral, stations.shape)
    return np.array([lane.position(s, r) for s, r in zip(stations, lateral, strict=True)])


def _segments(polyline: np.ndarray) -> np.ndarray:
    return np.stack([polyline[:-1], polyline[1:]], axis=1)


def centre_line(desc: RoadDescription, rows) -> np.ndarray:
    """(P, 2) centre line of lanes ``rows`` one after the other, each sampled with its ends (as
    the highway backend samples a route)."""
    lanes = [desc.lane(int(r)) for r in rows]
    return np.concatenate([lane_points(lane, lane_stations(lane), 0.0) for lane in lanes])


def circuit_route(desc: RoadDescription, start: int) -> list[int]:
    """Lane rows of one lap of a closed road from lane row ``start``: the road's first successor
    each time, keeping the lane id (as the highway backend plans a circuit's route)."""
    graph, lane_id = desc.graph, int(desc.lane_id[start])
    first, node = desc.nodes[desc.lane_from[start]], desc.nodes[desc.lane_to[start]]
    rows = [start]
    while node != first and graph.get(node):
        nxt = next(iter(graph[node]))
        lanes = graph[node][nxt]
        rows.append(lanes[min(lane_id, len(lanes) - 1)])
        node = nxt
    return rows


def road_map(desc: RoadDescription) -> RoadMap:
    """The description's RoadMap: every lane in row order, then its crossings and guide lines."""
    polygons, centerlines, widths, markings, kinds, edges = [], [], [], [], [], []
    for row in range(desc.lane_count):
        lane = desc.lane(row)
        stations = lane_stations(lane)
        half_width = np.array([lane.width for _ in stations]) / 2
        left = lane_points(lane, stations, -half_width)
        right = lane_points(lane, stations, half_width)
        polygons.append(np.concatenate([left, right[::-1]]))
        centerlines.append(lane_points(lane, stations, 0.0))
        widths.append(lane.width)
        for side, boundary in ((0, left), (1, right)):
            line_type = lane.lines[side]
            if line_type == LINE_NONE:
                continue
            segments = _segments(boundary)
            solid = line_type == LINE_CONTINUOUS
            markings.append(segments)
            kinds.append(np.full(len(segments), 2 if solid else 1))
            if solid:
                edges.append(segments)
    stack = lambda parts: np.concatenate(parts) if parts else np.zeros((0, 2, 2))  # noqa: E731
    return RoadMap(
        lane_polygons=tuple(polygons),
        lane_centerlines=tuple(centerlines),
        lane_widths_m=np.asarray(widths, dtype=float),
        markings=stack(markings),
        marking_kinds=np.concatenate(kinds) if kinds else np.zeros(0, dtype=int),
        edges=stack(edges),
        guide_lines=tuple(line.copy() for line in desc.guide_lines),
        crossings=np.array(desc.crossings, dtype=float).reshape(-1, 5),
    )
