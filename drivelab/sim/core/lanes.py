"""Road geometry as one array: highway-env's straight, sine and circular lanes, once per reset.

Every lane is a row of ``LANE_COLUMNS``; the compiled kernels read the row they need. The
formulas are highway-env's own (``highway_env/road/lane.py``), kept in the same floating-point
order so that coordinates agree to the last bits.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from drivelab.sim.core.borrow import borrowed

STRAIGHT, SINE, CIRCLE = 0, 1, 2
(
    KIND, START_X, START_Y, DIR_X, DIR_Y, HEADING, LENGTH, WIDTH, AMPLITUDE, PULSATION, PHASE,
    CENTER_X, CENTER_Y, RADIUS, START_PHASE, SENSE, SPEED_LIMIT, FORBIDDEN, LANE_ID, LANE_COUNT,
    FIRST_OF_ROAD, FROM_NODE, TO_NODE, PRIORITY, BOX_MIN_X, BOX_MIN_Y, BOX_MAX_X, BOX_MAX_Y,
) = range(28)  # fmt: skip
LANE_COLUMNS = 28
# BOX_*: a box around the lane's centre line (a straight lane's segment, a circular lane's whole
# circle; unbounded for a sine lane). ``closest_lane`` skips a lane whose box is farther than the
# best distance found so far: highway-env's distance to a lane (|lateral| + how far beyond its
# ends) is never less than the Euclidean distance to its centre line, so the answer is the same.
BOX_MARGIN_M = 1e-6  # far above the rounding of either distance (1e-13 m on a town)
VEHICLE_LENGTH = 5.0  # AbstractLane.VEHICLE_LENGTH


@dataclass(frozen=True)
class LaneTable:
    """Lanes of a highway-env road network as arrays.

    :param rows: (L, LANE_COLUMNS) float array, one lane per row, in ``network.lanes_list()`` order
        (the order highway-env breaks ties in when it looks for the closest lane).
    :param indices: highway-env lane index (from, to, id) of each row.
    :param nodes: road-network node names; ``FROM_NODE`` / ``TO_NODE`` hold positions in it.
    """

    rows: np.ndarray
    indices: tuple[tuple, ...]
    nodes: tuple[str, ...] = ()

    @property
    def row_of(self) -> dict[tuple, int]:
        return {index: row for row, index in enumerate(self.indices)}

    @staticmethod
    def from_network(network) -> LaneTable:
        from highway_env.road.lane import CircularLane, SineLane, StraightLane  # only to convert a road

        indices = [
            (f, t, i) for f, to in network.graph.items() for t, lanes in to.items() for i in range(len(lanes))
        ]
        nodes = list(dict.fromkeys([node for f, t, _ in indices for node in (f, t)]))
        node_of = {node: k for k, node in enumerate(nodes)}
        first = {}
        rows = np.zeros((len(indices), LANE_COLUMNS))
        for row, (f, t, i) in enumerate(indices):
            lane = network.get_lane((f, t, i))
            first.setdefault((f, t), row)
            values = rows[row]
            values[LENGTH], values[WIDTH] = lane.length, lane.width_at(0.0)
            values[SPEED_LIMIT] = np.nan if lane.speed_limit is None else lane.speed_limit
            values[FORBIDDEN], values[PRIORITY] = float(lane.forbidden), lane.priority
            values[LANE_ID], values[LANE_COUNT] = i, len(network.graph[f][t])
            values[FIRST_OF_ROAD] = first[(f, t)]
            values[FROM_NODE], values[TO_NODE] = node_of[f], node_of[t]
            if isinstance(lane, CircularLane):
                values[KIND] = CIRCLE
                values[CENTER_X], values[CENTER_Y] = lane.center
                values[RADIUS], values[START_PHASE] = lane.radius, lane.start_phase
                values[SENSE] = lane.direction
            elif isinstance(lane, StraightLane):
                values[KIND] = SINE if isinstance(lane, SineLane) else STRAIGHT
                values[START_X], values[START_Y] = lane.start
                values[DIR_X], values[DIR_Y] = lane.direction
                values[HEADING] = lane.heading
                if isinstance(lane, SineLane):
                    values[AMPLITUDE], values[PULSATION] = lane.amplitude, lane.pulsation
                    values[PHASE] = lane.phase
            else:
                raise NotImplementedError(f"the fast backend has no {type(lane).__name__} yet")
        _fill_boxes(rows)
        return LaneTable(rows, tuple(indices), tuple(nodes))

    @staticmethod
    def from_description(desc) -> LaneTable:
        """The rows of a ``roads.description.RoadDescription`` (no highway-env object): the same
        numbers ``from_network(to_road_network(desc))`` gives, computed with highway-env's lane
        formulas in its floating-point order (length, direction, heading of a straight lane)."""
        from drivelab.sim.roads.description import ARC

        indices = desc.indices
        rows = np.zeros((len(indices), LANE_COLUMNS))
        rows[:, WIDTH], rows[:, SPEED_LIMIT] = desc.width, desc.speed_limit
        rows[:, FORBIDDEN], rows[:, PRIORITY] = desc.forbidden, desc.priority
        rows[:, LANE_ID], rows[:, FROM_NODE], rows[:, TO_NODE] = desc.lane_id, desc.lane_from, desc.lane_to
        for row, (f, t, _) in enumerate(indices):
            road = desc.graph[f][t]
            values = rows[row]
            values[LANE_COUNT], values[FIRST_OF_ROAD] = len(road), road[0]
            if desc.kind[row] == ARC:  # highway-env's CircularLane.__init__
                sense = 1 if desc.clockwise[row] else -1
                radius, start_phase = desc.radius[row], desc.start_phase[row]
                values[KIND], values[LENGTH] = CIRCLE, radius * (desc.end_phase[row] - start_phase) * sense
                values[CENTER_X], values[CENTER_Y] = desc.centre[row]
                values[RADIUS], values[START_PHASE], values[SENSE] = radius, start_phase, sense
            else:  # highway-env's StraightLane.__init__
                start, end = desc.start[row].copy(), desc.end[row].copy()
                length = np.linalg.norm(end - start)
                values[KIND], values[LENGTH] = STRAIGHT, length
                values[START_X], values[START_Y] = start
                values[DIR_X], values[DIR_Y] = (end - start) / length
                values[HEADING] = np.arctan2(end[1] - start[1], end[0] - start[0])
        _fill_boxes(rows)
        return LaneTable(rows, indices, tuple(desc.nodes))

    def road_of(self, _from: str, _to: str) -> int:
        """The row of lane 0 of road (_from, _to): how routes name a road."""
        return self.row_of[(_from, _to, 0)]


def _fill_boxes(rows: np.ndarray) -> None:
    """BOX_* of every lane row (see BOX_MARGIN_M)."""
    for values in rows:
        if values[KIND] == STRAIGHT:
            end_x = values[START_X] + values[LENGTH] * values[DIR_X]
            end_y = values[START_Y] + values[LENGTH] * values[DIR_Y]
            values[BOX_MIN_X], values[BOX_MAX_X] = min(values[START_X], end_x), max(values[START_X], end_x)
            values[BOX_MIN_Y], values[BOX_MAX_Y] = min(values[START_Y], end_y), max(values[START_Y], end_y)
        elif values[KIND] == CIRCLE:
            x, y, radius = values[CENTER_X], values[CENTER_Y], values[RADIUS]
            values[BOX_MIN_X], values[BOX_MAX_X] = x - radius, x + radius
            values[BOX_MIN_Y], values[BOX_MAX_Y] = y - radius, y + radius
        else:
            values[BOX_MIN_X] = values[BOX_MIN_Y] = -np.inf
            values[BOX_MAX_X] = values[BOX_MAX_Y] = np.inf


TWO_PI = 2 * np.pi


# The trigonometric functions with their zero written out (IEEE 754 fixes sin, tan, arcsin and
# arctan of a signed zero to that zero and cos of it to 1: the library's own bits, without its
# call). A vehicle driving straight along a lane's centre has heading, steering and offset 0.
@njit(cache=True, inline="always")
def sin0(x: float) -> float:
    return x if x == 0.0 else np.sin(x)


@njit(cache=True, inline="always")
def cos0(x: float) -> float:
    return 1.0 if x == 0.0 else np.cos(x)


@njit(cache=True, inline="always")
def tan0(x: float) -> float:
    return x if x == 0.0 else np.tan(x)


@njit(cache=True, inline="always")
def arctan0(x: float) -> float:
    return x if x == 0.0 else np.arctan(x)


@njit(cache=True, inline="always")
def arcsin0(x: float) -> float:
    return x if x == 0.0 else np.arcsin(x)


@njit(cache=True, inline="always")
def wrap_to_pi(angle: float) -> float:
    """highway-env's ``((angle + pi) % (2 pi)) - pi``, bit for bit. Python's float ``%`` is
    ``fmod`` plus a sign fix; ``fmod`` (a slow library call) is exact and returns its argument
    when that lies within one period, so the two usual cases are written out: ``x`` in [0, 2 pi)
    gives ``x`` (``+0.0`` for a zero, the same once pi is taken off), ``x`` in (-2 pi, 0) gives
    ``x + 2 pi``, as Python computes them."""
    x = angle + np.pi
    if 0.0 <= x < TWO_PI:
        return x - np.pi
    if -TWO_PI < x < 0.0:
        return (x + TWO_PI) - np.pi
    return (x % TWO_PI) - np.pi


@njit(cache=True, inline="always")
def local_coordinates(lanes: np.ndarray, lane: int, x: float, y: float) -> tuple[float, float]:
    """(longitudinal, lateral) of the world point (x, y) in ``lane``."""
    row = lanes[lane]
    if row[KIND] == CIRCLE:
        dx, dy = x - row[CENTER_X], y - row[CENTER_Y]
        phi = np.arctan2(dy, dx)
        phi = row[START_PHASE] + wrap_to_pi(phi - row[START_PHASE])
        r = np.sqrt(dx * dx + dy * dy)
        return row[SENSE] * (phi - row[START_PHASE]) * row[RADIUS], row[SENSE] * (row[RADIUS] - r)
    dx, dy = x - row[START_X], y - row[START_Y]
    longitudinal = dx * row[DIR_X] + dy * row[DIR_Y]
    lateral = dx * -row[DIR_Y] + dy * row[DIR_X]
    if row[KIND] == SINE:
        lateral = lateral - row[AMPLITUDE] * np.sin(row[PULSATION] * longitudinal + row[PHASE])
    return longitudinal, lateral


@njit(cache=True, inline="always")
def circle_lateral(lanes: np.ndarray, lane: int, x: float, y: float) -> float:
    """A circular lane's lateral coordinate of (x, y) as ``local_coordinates`` computes it (the
    same operations, so the same bits) without its arctan2: a cheap exact test that a point is
    too far to the side for the lane."""
    row = lanes[lane]
    dx, dy = x - row[CENTER_X], y - row[CENTER_Y]
    return row[SENSE] * (row[RADIUS] - np.sqrt(dx * dx + dy * dy))


@njit(cache=True, inline="always")
def heading_at(lanes: np.ndarray, lane: int, longitudinal: float) -> float:
    row = lanes[lane]
    if row[KIND] == CIRCLE:
        phi = row[SENSE] * longitudinal / row[RADIUS] + row[START_PHASE]
        return phi + np.pi / 2 * row[SENSE]
    if row[KIND] == SINE:
        slope = row[AMPLITUDE] * row[PULSATION] * np.cos(row[PULSATION] * longitudinal + row[PHASE])
        return row[HEADING] + np.arctan(slope)
    return row[HEADING]


@njit(cache=True, inline="always")
def on_lane(lanes: np.ndarray, lane: int, longitudinal: float, lateral: float, margin: float) -> bool:
    row = lanes[lane]
    return (
        np.abs(lateral) <= row[WIDTH] / 2 + margin
        and -VEHICLE_LENGTH <= longitudinal
        and longitudinal < row[LENGTH] + VEHICLE_LENGTH
    )


@njit(cache=True)
def distance(lanes: np.ndarray, lane: int, x: float, y: float) -> float:
    """AbstractLane.distance: lateral offset plus how far the point lies beyond either end."""
    (lanes,) = borrowed((lanes,))
    s, r = local_coordinates(lanes, lane, x, y)
    return np.abs(r) + max(s - lanes[lane, LENGTH], 0.0) + max(0.0 - s, 0.0)


@njit(cache=True)
def is_reachable_from(lanes: np.ndarray, lane: int, x: float, y: float) -> bool:
    row = lanes[lane]
    if row[FORBIDDEN] > 0:
        return False
    longitudinal, lateral = local_coordinates(lanes, lane, x, y)
    return (
        np.abs(lateral) <= 2 * row[WIDTH]
        and 0 <= longitudinal
        and longitudinal < row[LENGTH] + VEHICLE_LENGTH
    )


@njit(cache=True, inline="always")
def closest_lane(lanes: np.ndarray, x: float, y: float, heading: float, hint: int = -1) -> int:
    """highway-env's get_closest_lane_index: L1 distance plus heading misalignment, first minimum.

    ``hint`` (a lane likely to be the closest: the vehicle's lane before it moved) is measured
    first; a lane whose distance before the heading term (which only adds) already reaches the
    best is then skipped without computing that term. Ties still go to the first lane in order,
    so the answer is the same as scanning every lane in order.
    """
    best, best_distance = 0, np.inf
    if hint >= 0:
        s, r = local_coordinates(lanes, hint, x, y)
        angle = np.abs(wrap_to_pi(heading - heading_at(lanes, hint, s)))
        distance = np.abs(r) + max(s - lanes[hint, LENGTH], 0.0) + max(0.0 - s, 0.0) + angle
        if distance < best_distance:
            best, best_distance = hint, distance
    for lane in range(lanes.shape[0]):
        if lane == hint:
            continue
        row = lanes[lane]
        outside = max(row[BOX_MIN_X] - x, x - row[BOX_MAX_X], row[BOX_MIN_Y] - y, y - row[BOX_MAX_Y])
        if outside > best_distance + BOX_MARGIN_M:
            continue  # its distance is at least this far: it cannot be the closest
        if row[KIND] == CIRCLE and np.abs(circle_lateral(lanes, lane, x, y)) > best_distance:
            continue  # |lateral| (the same bits as below) alone exceeds the best
        s, r = local_coordinates(lanes, lane, x, y)
        partial = np.abs(r) + max(s - lanes[lane, LENGTH], 0.0) + max(0.0 - s, 0.0)
        if partial > best_distance or (partial == best_distance and lane > best):
            continue
        angle = np.abs(wrap_to_pi(heading - heading_at(lanes, lane, s)))
        distance = partial + angle
        if distance < best_distance or (distance == best_distance and lane < best):
            best, best_distance = lane, distance
    return best


@njit(cache=True)
def position(lanes: np.ndarray, lane: int, longitudinal: float, lateral: float) -> tuple[float, float]:
    """World point at (longitudinal, lateral) of ``lane``."""
    (lanes,) = borrowed((lanes,))
    row = lanes[lane]
    if row[KIND] == CIRCLE:
        phi = row[SENSE] * longitudinal / row[RADIUS] + row[START_PHASE]
        radius = row[RADIUS] - lateral * row[SENSE]
        return row[CENTER_X] + radius * np.cos(phi), row[CENTER_Y] + radius * np.sin(phi)
    if row[KIND] == SINE:
        lateral = lateral + row[AMPLITUDE] * np.sin(row[PULSATION] * longitudinal + row[PHASE])
    return (
        row[START_X] + longitudinal * row[DIR_X] + lateral * -row[DIR_Y],
        row[START_Y] + longitudinal * row[DIR_Y] + lateral * row[DIR_X],
    )
