"""``RoadMap`` arrays (lane outlines, centre lines, markings, edges, crossings, guide lines) from
lanes: a road description's (``road_map``, no highway-env) and, through ``lanes_road_map``,
highway-env's (``highway.build_road_map``): one sampling, so both give the same bits."""

from __future__ import annotations

import dataclasses

import numpy as np

from drivelab.sim.roads.description import LINE_CONTINUOUS, LINE_NONE, STRAIGHT, RoadDescription
from drivelab.world.state import RoadMap

SAMPLE_SPACING_M = 2.0  # curved lanes are turned into polylines with points this far apart


def lane_stations(lane, straight: bool | None = None) -> np.ndarray:
    """Arc-length stations at which to sample a lane: its ends, plus every 2 m if curved.

    :param lane: anything with a ``length`` (a LaneRecord or a highway-env lane).
    :param straight: whether it is straight (default: a LaneRecord's kind)."""
    length = lane.length
    if straight if straight is not None else lane.kind == STRAIGHT:
        return np.array([0.0, length])
    count = max(int(np.ceil(length / SAMPLE_SPACING_M)), 1)
    return np.linspace(0.0, length, count + 1)


def lane_points(lane, stations: np.ndarray, lateral: float | np.ndarray) -> np.ndarray:
    """(len(stations), 2) points of the lane (anything with ``position(s, r)``) at ``stations``
    and ``lateral`` offsets."""
    lateral = np.broadcast_to(lateral, stations.shape)
    return np.array([lane.position(s, r) for s, r in zip(stations, lateral, strict=True)])


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


def lanes_road_map(lanes, straight, widths, lines) -> RoadMap:
    """The RoadMap of ``lanes`` (each with ``length`` and ``position(s, r)``), with per lane
    whether it is ``straight``, its width and its (left, right) line types (highway-env's
    LineType codes: NONE, STRIPED, CONTINUOUS, CONTINUOUS_LINE; the last two are solid)."""
    polygons, centerlines, markings, kinds, edges = [], [], [], [], []
    for lane, is_straight, width, line_types in zip(lanes, straight, widths, lines, strict=True):
        stations = lane_stations(lane, is_straight)
        half_width = np.full(stations.shape, width) / 2
        left = lane_points(lane, stations, -half_width)
        right = lane_points(lane, stations, half_width)
        polygons.append(np.concatenate([left, right[::-1]]))
        centerlines.append(lane_points(lane, stations, 0.0))
        for side, boundary in ((0, left), (1, right)):
            line_type = line_types[side]
            if line_type == LINE_NONE:
                continue
            segments = np.stack([boundary[:-1], boundary[1:]], axis=1)
            solid = line_type >= LINE_CONTINUOUS
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
    )


def road_map(desc: RoadDescription) -> RoadMap:
    """The description's RoadMap: every lane in row order, then its crossings and guide lines."""
    lanes = [desc.lane(row) for row in range(desc.lane_count)]
    base = lanes_road_map(
        lanes,
        [lane.kind == STRAIGHT for lane in lanes],
        [lane.width for lane in lanes],
        [lane.lines for lane in lanes],
    )
    return dataclasses.replace(
        base,
        guide_lines=tuple(line.copy() for line in desc.guide_lines),
        crossings=np.array(desc.crossings, dtype=float).reshape(-1, 5),
    )
