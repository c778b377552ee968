"""The town's lane metadata as arrays, for its compiled kernels and set-up.

``TownRoadArrays`` holds, per lane row (``LaneTable`` order; every town road has one lane), what
the reference reads from node names (the junction a lane crosses and its turn, the stop line a
street ends at and its light), the light table, the crossings, the streets and every shortest
route between them.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True, eq=False)
class TownRoadArrays:
    """Per lane (L,): ``junction``, ``from_arm``, ``to_arm``, ``turn`` (TURN_* on junction lanes,
    else -1), ``end_junction``/``end_arm`` (the stop line a street ends at, else -1), ``light``
    (that approach's light row, -1 without one), ``in_junction``. Lights (M,): ``light_xyh``
    (M, 3) stop line x, y and approach heading, ``light_junction``, ``light_arm``. ``crossings``
    (C, 5): centre x, y, walking heading, length, width. ``street_lanes`` (S,): the streets' lane
    rows. ``routes`` (L, S, W): lane rows of the shortest route from road r to the end node of
    street g, -1 padded; ``route_length`` (L, S), 0 where unreachable."""

    junction: np.ndarray
    from_arm: np.ndarray
    to_arm: np.ndarray
    turn: np.ndarray
    end_junction: np.ndarray
    end_arm: np.ndarray
    light: np.ndarray
    in_junction: np.ndarray
    light_xyh: np.ndarray
    light_junction: np.ndarray
    light_arm: np.ndarray
    junction_count: int
    crossings: np.ndarray
    street_lanes: np.ndarray
    routes: np.ndarray
    route_length: np.ndarray


def shortest_route(graph: dict, start: tuple[str, str], goal: str) -> list[tuple[str, str, int]]:
    """Lane indices from road ``start`` to node ``goal`` by breadth-first search over ``graph``
    ({from: {to: lanes}}, highway-env's ``RoadNetwork.graph``), one lane per road.

    Unlike highway-env's ``shortest_path`` this never revisits a node and returns [] when the goal
    cannot be reached."""
    queue, seen = deque([(start[1], [start[0], start[1]])]), {start[1]}
    while queue:
        node, path = queue.popleft()
        if node == goal:
            return [(a, b, 0) for a, b in zip(path[:-1], path[1:], strict=True)]
        for nxt in graph.get(node, {}):
            if nxt not in seen:
                seen.add(nxt)
                queue.append((nxt, path + [nxt]))
    return []


def route_table(
    graph: dict, lanes: list[tuple[str, str, int]], streets: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """``routes`` (L, S, W) and ``route_length`` (L, S): every lane's shortest route to the end
    node of every street (see ``TownRoadArrays``)."""
    row = {index: r for r, index in enumerate(lanes)}
    found = [
        [[row[lane] for lane in shortest_route(graph, lane[:2], lanes[s][1])] for s in streets]
        for lane in lanes
    ]
    width = max((len(route) for per_lane in found for route in per_lane), default=0)
    routes = np.full((len(lanes), len(streets), width), -1, dtype=np.int64)
    lengths = np.zeros((len(lanes), len(streets)), dtype=np.int64)
    for r, per_lane in enumerate(found):
        for g, route in enumerate(per_lane):
            routes[r, g, : len(route)], lengths[r, g] = route, len(route)
    return routes, lengths
