"""The town's vehicles as compiled loops over ONE world's arrays (the caller loops the worlds).

``town_act`` is ``Road.act()`` of the reference town (``scenarios/town/reference_env.py``): every
vehicle row decides its controls in list order; the ego rows behave as in ``traffic.act``, and
``TOWN`` rows are highway-env's ``TownVehicle``:

- ``TownVehicle.act``: the target speed is the current lane's limit, or the next planned lane's
  once within TURN_BRAKE_MARGIN_M plus the braking distance to it, set before ``follow_road``;
- ``TownVehicle.follow_road``: with at most one route entry left, a new ``random_route`` from the
  target lane (``random_goal``'s draws on the world's PCG64 words), then
  ``ControlledVehicle.follow_road``;
- ``IDMVehicle.act``: ``change_lane_policy`` (``traffic``'s), steering to the target lane, IDM
  behind the leader on the current lane and, while changing lanes, on the target lane;
- leaders are found as ``Road.neighbour_vehicles`` with ``neighbour_vehicles_connected_lanes``
  (``connected_front``) over the vehicles and then the pedestrians not crashed; the gap is
  ``TownVehicle.lane_distance_to``: the straight-line distance, signed by the lane projection;
- ``TownVehicle.acceleration``: IDM, then the minimum with a stopped virtual leader at the stop
  line when ``stop_line_ahead`` says stop.

``town_step`` is ``Road.step``'s vehicle loop: ``Vehicle.step`` for every row, and for ``TOWN``
rows the IDM timer and ``TownVehicle.step``'s no-reversing clamp.

Arrays (one world): ``v`` (N_max, TOWN_VEHICLE_COLUMNS) vehicle rows, ``0..count-1`` live;
``peds`` (P_max, PEDESTRIAN_COLUMNS) pedestrian rows, ``0..pcount-1`` live; ``lanes`` the lane
table; ``p`` the IDM parameters; ``coords``, ``done``, ``trig`` the frame cache
(``town_frame_cache``); the road arrays of ``road_arrays_tuple``, in its order; ``light_states``
(M,) LIGHT_* at the step's end time; ``rng_words`` (6,) the world's PCG64 state, advanced in place.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from drivelab.sim.core import lanes as L
from drivelab.sim.core import traffic as T
from drivelab.sim.core.borrow import borrowed
from drivelab.sim.core.pcg64 import bounded_int
from drivelab.sim.junctions.rows import LANE_METADATA, P_CRASHED, P_HEADING, P_SPEED, P_X, P_Y, TURN_LEFT
from drivelab.sim.junctions.rules import (
    MOVING_MPS,
    ONCOMING_WATCH_M,
    ROUTE_GOAL_TRIES,
    STOP_MARGIN_M,
    TURN_BRAKE_MARGIN_M,
)
from drivelab.world.state import LIGHT_GREEN, LIGHT_RED, LIGHT_YELLOW

NO_STOP = -1.0  # stop_line_ahead's None (a distance to stop at is never negative)


@njit(cache=True, inline="always")
def py_square(x: float) -> float:
    """``x ** 2`` as Python (and numpy's scalar power) computes it for a float: libm's
    ``pow(x, 2.0)``, which is not always ``x * x`` (glibc's differs by an ULP for about 1 in 1 500
    random speeds). LLVM rewrites ``pow(x, 2.0)`` as ``x * x``, so the exponent is made opaque:
    ``2.0 + 0.0 * x`` is 2.0 for any finite x, which LLVM cannot assume."""
    return x ** (2.0 + 0.0 * x)


def town_frame_cache(vehicles: int, pedestrians: int, lane_count: int):
    """Scratch arrays of one frame's ``town_act`` for up to ``vehicles`` vehicle rows and
    ``pedestrians`` pedestrian rows (pedestrian k at j = count + k) on ``lane_count`` lanes:
    ``traffic.frame_cache``'s ``coords`` (L, N+P, 4), ``done`` (L,), ``trig`` (N+P, 2). Allocate
    once per world; ``town_act`` refills what it reads."""
    size = vehicles + pedestrians
    return np.empty((lane_count, size, 4)), np.full(lane_count, -1, dtype=np.int64), np.empty((size, 2))


def road_arrays_tuple(arrays, lanes: np.ndarray) -> tuple:
    """The road arrays ``town_act`` takes, in its argument order: the ``TownRoadArrays`` fields
    LANE_METADATA, ``street_lanes`` (S,), ``routes`` (L, S, W), ``route_length`` (L, S) as int64;
    then ``connected_lanes(lanes)``."""
    names = (*LANE_METADATA, "street_lanes", "routes", "route_length")
    return (
        *(np.ascontiguousarray(getattr(arrays, name), dtype=np.int64) for name in names),
        *connected_lanes(lanes),
    )


@njit(cache=True, inline="always")
def planned_next(v: np.ndarray, lanes: np.ndarray, i: int) -> int:
    """TownVehicle.next_lane: the lane row of the first route entry that starts where vehicle i's
    current lane ends, else -1 (a route entry without a lane id names the road's lane 0)."""
    end_node = lanes[int(v[i, T.LANE]), L.TO_NODE]
    for k in range(int(v[i, T.ROUTE_START]), int(v[i, T.ROUTE_END])):
        road = int(v[i, T.ROUTE + 2 * k])
        if lanes[road, L.FROM_NODE] == end_node:
            return road + max(int(v[i, T.ROUTE + 2 * k + 1]), 0)
    return -1


@njit(cache=True)
def random_goal(
    lanes: np.ndarray, start: int, street_lanes: np.ndarray, route_length: np.ndarray, rng_words: np.ndarray
) -> int:
    """town_env.random_route's goal from lane row ``start``: a street (its index in
    ``street_lanes``) drawn among those whose end node is not ``start``'s (street order), up to
    ROUTE_GOAL_TRIES times until one is reachable; -1 when none was (the route is then ``start``
    alone). The draws are ``integers(goals)`` on the PCG64 ``rng_words``."""
    lanes, street_lanes, route_length, rng_words = borrowed((lanes, street_lanes, route_length, rng_words))
    end_node = lanes[start, L.TO_NODE]
    goals = 0
    for g in range(street_lanes.shape[0]):
        if lanes[street_lanes[g], L.TO_NODE] != end_node:
            goals += 1
    if goals == 0:
        raise ValueError("a town street has no other street to route to")
    for _ in range(ROUTE_GOAL_TRIES):
        pick = bounded_int(rng_words, goals)
        street = -1
        for g in range(street_lanes.shape[0]):
            if lanes[street_lanes[g], L.TO_NODE] != end_node:
                if pick == 0:
                    street = g
                    break
                pick -= 1
        if route_length[start, street] > 0:
            return street
    return -1


@njit(cache=True)
def random_route(v, lanes, i: int, start: int, street_lanes, routes, route_length, rng_words) -> None:
    """town_env.random_route from lane row ``start`` into vehicle i's route entries: the route to
    ``random_goal``'s street, else ``start`` alone."""
    v, lanes, routes, route_length = borrowed((v, lanes, routes, route_length))
    street = random_goal(lanes, start, street_lanes, route_length, rng_words)
    if street >= 0:
        n = route_length[start, street]
        if n > (v.shape[1] - T.ROUTE) // 2:
            raise ValueError("a town route is longer than the vehicle row's route capacity")
        for k in range(n):
            row = routes[start, street, k]
            v[i, T.ROUTE + 2 * k] = lanes[row, L.FIRST_OF_ROAD]
            v[i, T.ROUTE + 2 * k + 1] = lanes[row, L.LANE_ID]
        v[i, T.ROUTE_START], v[i, T.ROUTE_END], v[i, T.ROUTED] = 0.0, n, 1.0
        return
    v[i, T.ROUTE] = lanes[start, L.FIRST_OF_ROAD]
    v[i, T.ROUTE + 1] = lanes[start, L.LANE_ID]
    v[i, T.ROUTE_START], v[i, T.ROUTE_END], v[i, T.ROUTED] = 0.0, 1.0, 1.0


@njit(cache=True, inline="always")
def object_xy(v: np.ndarray, peds: np.ndarray, j: int) -> tuple[float, float]:
    """Position of vehicle j, or of pedestrian j - count."""
    if j < v.shape[0]:
        return v[j, T.X], v[j, T.Y]
    return peds[j - v.shape[0], P_X], peds[j - v.shape[0], P_Y]


@njit(cache=True, inline="always")
def lane_s(v, peds, lanes, coords, seen, lane: int, j: int) -> float:
    """Object j's longitudinal coordinate in ``lane`` (computed once per frame: the same bits);
    ``seen[lane, j]`` becomes 1 if it is on the lane (``on_lane``, 1 m margin), else 0."""
    if seen[lane, j] < 0:
        x, y = object_xy(v, peds, j)
        s, r = L.local_coordinates(lanes, lane, x, y)
        coords[lane, j, 0], coords[lane, j, 1] = s, r
        seen[lane, j] = 1 if L.on_lane(lanes, lane, s, r, 1.0) else 0
    return coords[lane, j, 0]


def connected_lanes(lanes: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The static tables ``connected_front`` searches, per lane row (made once per road):

    - ``search`` (L, S), ``search_size`` (L,): the lanes ``neighbour_vehicles_connected_lanes``
      looks on, in order: the lane, its successor roads', its predecessor roads' (the same lane
      index on each road, else its lane 0);
    - ``search_offset`` (L, S): what shifts a longitudinal coordinate on that lane into the lane's
      frame (+ the lane's length for successors, - their own for predecessors);
    - ``discs`` (L, 3): x, y and squared radius of a disc holding every point ``on_lane`` counts as on
      the lane: |r| from the centre line at s, at most |s - length/2| from the lane's middle, 1 m more
      for rounding (sine lanes: an infinite radius).
    """
    count = lanes.shape[0]
    rows = np.arange(count)
    first = lanes[:, L.FIRST_OF_ROAD] == rows

    def lane_on(road: int, lane_id: float) -> int:
        return int(road) + (int(lane_id) if lane_id < lanes[road, L.LANE_COUNT] else 0)

    found: list[tuple[list[int], list[float]]] = []
    for lane in range(count):
        lane_id = lanes[lane, L.LANE_ID]
        leaving = rows[first & (lanes[:, L.FROM_NODE] == lanes[lane, L.TO_NODE])]  # successor roads
        entering = rows[first & (lanes[:, L.TO_NODE] == lanes[lane, L.FROM_NODE])]  # predecessor roads
        roads = [lane_on(road, lane_id) for road in leaving]
        into = [lane_on(road, lane_id) for road in entering]
        offset = (
            [0.0] + [lanes[lane, L.LENGTH]] * len(roads) + [-lanes[previous, L.LENGTH] for previous in into]
        )
        found.append(([lane, *roads, *into], offset))
    width = max(len(search) for search, _ in found)
    search = np.zeros((count, width), dtype=np.int64)
    offset = np.zeros((count, width))
    size = np.array([len(lanes_on) for lanes_on, _ in found], dtype=np.int64)
    for lane, (lanes_on, shifts) in enumerate(found):
        search[lane, : len(lanes_on)], offset[lane, : len(shifts)] = lanes_on, shifts
    discs = np.empty((count, 3))
    for lane in range(count):
        half = lanes[lane, L.LENGTH] / 2
        discs[lane, 0], discs[lane, 1] = L.position(lanes, lane, half, 0.0)
        reach = half + L.VEHICLE_LENGTH + lanes[lane, L.WIDTH] / 2 + 1.0 + 1.0
        discs[lane, 2] = np.inf if lanes[lane, L.KIND] == L.SINE else reach * reach
    return search, offset, size, discs


@njit(cache=True, inline="always")
def lane_objects(v, peds, lanes, coords, seen, discs, near, near_count, lane: int) -> None:
    """``near[lane, :near_count[lane]]``: the objects on ``lane`` (``on_lane``, 1 m margin) in
    scan order (vehicles, then pedestrians not crashed), listed once per frame: only those inside
    the lane's disc (and, on a circular lane, within its lateral reach) are measured."""
    if near_count[lane] >= 0:
        return
    count, n = v.shape[0], 0
    cx, cy, reach2 = discs[lane, 0], discs[lane, 1], discs[lane, 2]
    arc, half_width = lanes[lane, L.KIND] == L.CIRCLE, lanes[lane, L.WIDTH] / 2 + 1.0
    for j in range(count + peds.shape[0]):
        if j >= count and peds[j - count, P_CRASHED] > 0:
            continue
        if seen[lane, j] < 0:  # not measured yet in this frame: off the lane outside its disc
            x, y = object_xy(v, peds, j)
            dx, dy = x - cx, y - cy
            if dx * dx + dy * dy > reach2:
                continue
            if arc and not np.abs(L.circle_lateral(lanes, lane, x, y)) <= half_width:
                continue  # on_lane's lateral test fails (the same bits), its arctan2 spared
            lane_s(v, peds, lanes, coords, seen, lane, j)
        if seen[lane, j] == 1:
            near[lane, n] = j
            n += 1
    near_count[lane] = n


@njit(cache=True)
def connected_front(
    v, peds, lanes, coords, seen, near, near_count, search, search_offset, search_size, discs, i: int,
    lane: int
) -> int:  # fmt: skip
    """Road.neighbour_vehicles(vehicle i, lane)[0] with ``neighbour_vehicles_connected_lanes``:
    the row of the leader (a vehicle j < count, or pedestrian k as count + k), -1 for none: the
    nearest at or ahead of vehicle i (the last in scan order among equals), each object placed on the
    first of the lanes ``search[lane]`` it lies on, its longitudinal coordinate shifted into the
    lane's frame (the lanes' object lists: ``lane_objects``)."""
    v, peds, lanes, coords, seen, near, near_count, search, search_offset, search_size, discs = borrowed(
        (v, peds, lanes, coords, seen, near, near_count, search, search_offset, search_size, discs)
    )
    s = lane_s(v, peds, lanes, coords, seen, lane, i)
    front, s_front = -1, 0.0
    for k in range(search_size[lane]):
        other = search[lane, k]
        lane_objects(v, peds, lanes, coords, seen, discs, near, near_count, other)
        for m in range(near_count[other]):
            j = near[other, m]
            if j == i:
                continue
            placed = False  # on an earlier lane of the search: its lists are made, so measured there
            for earlier in range(k):
                if seen[search[lane, earlier], j] == 1:
                    placed = True
                    break
            if placed:
                continue
            s_j = coords[other, j, 0] + search_offset[lane, k]
            # the nearest, the last in scan order among equals
            if s <= s_j and (front < 0 or s_j < s_front or (s_j == s_front and j > front)):
                front, s_front = j, s_j
    return front


@njit(cache=True)
def left_turn_must_wait(
    v, lanes, i: int, turn_lane: int, junction, from_arm, to_arm, turn, end_junction, end_arm
) -> bool:  # fmt: skip
    """town_env.left_turn_must_wait: ``turn_lane`` is a left turn and another vehicle (the ego
    included) moving at MOVING_MPS or more is in the junction coming from the opposite arm (not
    leaving by it), or on the street to the opposite stop line within ONCOMING_WATCH_M of it."""
    v, lanes, junction, from_arm, to_arm, turn, end_junction, end_arm = borrowed(
        (v, lanes, junction, from_arm, to_arm, turn, end_junction, end_arm)
    )
    if turn[turn_lane] != TURN_LEFT:
        return False
    j, opposite = junction[turn_lane], (from_arm[turn_lane] + 2) % 4
    for o in range(v.shape[0]):
        if o == i or v[o, T.SPEED] < MOVING_MPS:
            continue
        lane = int(v[o, T.LANE])
        if junction[lane] == j and from_arm[lane] == opposite and to_arm[lane] != opposite:
            return True
        if end_junction[lane] == j and end_arm[lane] == opposite:
            s, _ = L.local_coordinates(lanes, lane, v[o, T.X], v[o, T.Y])
            if lanes[lane, L.LENGTH] - s < ONCOMING_WATCH_M:
                return True
    return False


@njit(cache=True)
def stop_line_ahead(
    v, lanes, p, i: int, junction, from_arm, to_arm, turn, end_junction, end_arm, light, light_states
) -> float:  # fmt: skip
    """TownVehicle.stop_line_ahead: metres from vehicle i's front bumper to the stop line it must
    stop at, else NO_STOP. It reads no frame cache: ``blocks_traffic`` calls it (through
    ``town_acceleration`` without a leader) with ``traffic``'s cache, whose flags are per lane."""
    v, lanes, p, light, light_states = borrowed((v, lanes, p, light, light_states))
    lane = int(v[i, T.LANE])
    if light[lane] < 0:
        return NO_STOP
    state = light_states[light[lane]]
    s, _ = L.local_coordinates(lanes, lane, v[i, T.X], v[i, T.Y])
    ahead_m = lanes[lane, L.LENGTH] - s - v[i, T.LEN] / 2
    if ahead_m < 0:
        return NO_STOP
    if state == LIGHT_GREEN:
        turn_lane = planned_next(v, lanes, i)
        if turn_lane >= 0 and left_turn_must_wait(
            v, lanes, i, turn_lane, junction, from_arm, to_arm, turn, end_junction, end_arm
        ):
            return ahead_m
        return NO_STOP
    if state == LIGHT_YELLOW and py_square(v[i, T.SPEED]) / (2 * max(ahead_m, 1e-3)) > -p[T.COMFORT_ACC_MIN]:
        return NO_STOP
    return ahead_m


@njit(cache=True)
def town_acceleration(
    v, peds, lanes, p, coords, done, trig, seen, i: int, front: int, junction, from_arm, to_arm, turn,
    end_junction, end_arm, light, light_states
) -> float:  # fmt: skip
    """TownVehicle.acceleration(self, front): IDM with the straight-line gap to ``front`` (a
    vehicle row, a pedestrian as count + k, or -1), then the stop line's virtual leader.
    ``coords`` and ``seen`` (``town_act``'s) are read only with a front."""
    v, peds, lanes, p, coords, done, trig, seen = borrowed((v, peds, lanes, p, coords, done, trig, seen))
    count = v.shape[0]
    acceleration = T.cached_idm_acceleration(v, lanes, p, coords, done, trig, i, i, -1)
    if front >= 0:
        if front < count:
            fx, fy = v[front, T.X], v[front, T.Y]
            desired_gap = T.cached_desired_gap(v, p, trig, i, front)
        else:  # a pedestrian (its heading's cos, sin in trig[front])
            k = front - count
            fx, fy = peds[k, P_X], peds[k, P_Y]
            desired_gap = T.desired_gap_to(v, p, trig, i, front, peds[k, P_SPEED])
        lane = int(v[i, T.LANE])
        along = lane_s(v, peds, lanes, coords, seen, lane, front) - lane_s(
            v, peds, lanes, coords, seen, lane, i
        )
        dx, dy = fx - v[i, T.X], fy - v[i, T.Y]
        gap_m = math.copysign(math.sqrt(dx * dx + dy * dy), along)
        # IDMVehicle.acceleration squares with np.power(·, 2): numpy's square, x * x
        acceleration -= p[T.COMFORT_ACC_MAX] * (desired_gap / T.not_zero(gap_m)) ** 2
    ahead_m = stop_line_ahead(
        v, lanes, p, i, junction, from_arm, to_arm, turn, end_junction, end_arm, light, light_states
    )
    if ahead_m == NO_STOP:
        return acceleration
    return min(acceleration, stop_ahead(v, p, i, ahead_m))


@njit(cache=True, inline="always")
def stop_ahead(v, p, i: int, ahead_m: float) -> float:
    """IDM's acceleration of vehicle i behind a stopped virtual leader ``ahead_m`` metres beyond
    its front bumper, to stand STOP_MARGIN_M short of it (TownVehicle.acceleration's stop line)."""
    gap_m = ahead_m - STOP_MARGIN_M + p[T.DISTANCE_WANTED]
    speed = max(v[i, T.SPEED], 0.0)
    ab = -p[T.COMFORT_ACC_MAX] * p[T.COMFORT_ACC_MIN]
    desired_gap = p[T.DISTANCE_WANTED] + speed * p[T.TIME_WANTED] + speed * speed / (2 * np.sqrt(ab))
    target = T.not_zero(v[i, T.TARGET_SPEED])
    stop = p[T.COMFORT_ACC_MAX] * (1 - (speed / np.abs(target)) ** v[i, T.DELTA])
    return stop - p[T.COMFORT_ACC_MAX] * py_square(desired_gap / T.not_zero(gap_m))


@njit(cache=True)
def town_act(
    v, count: int, peds, pcount: int, lanes, p, coords, done, trig, junction, from_arm, to_arm, turn,
    end_junction, end_arm, light, street_lanes, routes, route_length, search, search_offset, search_size,
    discs, light_states, rng_words
) -> None:  # fmt: skip
    """Road.act of one town world: rows ``0..count-1`` of ``v`` decide their controls in order
    (see the module docstring for the arrays). The frame's scratch is made here and ``_act_rows``
    borrows it: ``own`` (``traffic.own_lane``), ``near`` and ``near_count`` (``lane_objects``), and
    ``seen`` (which objects ``lane_s`` measured on which lane, -1: not yet)."""
    size = count + pcount
    own = np.empty(T.OWN_SIZE)
    near = np.empty((lanes.shape[0], size), dtype=np.int64)
    near_count = np.full(lanes.shape[0], -1, dtype=np.int64)
    seen = np.full((lanes.shape[0], size), -1, dtype=np.int8)
    _act_rows(
        v, count, peds, pcount, lanes, p, coords, done, trig, junction, from_arm, to_arm, turn,
        end_junction, end_arm, light, street_lanes, routes, route_length, search, search_offset,
        search_size, discs, light_states, rng_words, own, near, near_count, seen,
    )  # fmt: skip


@njit(cache=True)
def _act_rows(
    v, count: int, peds, pcount: int, lanes, p, coords, done, trig, junction, from_arm, to_arm, turn,
    end_junction, end_arm, light, street_lanes, routes, route_length, search, search_offset, search_size,
    discs, light_states, rng_words, own, near, near_count, seen
) -> None:  # fmt: skip
    """``town_act``'s loop over the rows, every array borrowed."""
    v, peds, lanes, p, coords, done, trig, light_states, rng_words = borrowed(
        (v, peds, lanes, p, coords, done, trig, light_states, rng_words)
    )  # no reference counts in the inlined helpers (``borrow``)
    own, near, near_count, seen = borrowed((own, near, near_count, seen))
    junction, from_arm, to_arm, turn, end_junction, end_arm, light = borrowed(
        (junction, from_arm, to_arm, turn, end_junction, end_arm, light)
    )
    street_lanes, routes, route_length, search, search_offset, search_size, discs = borrowed(
        (street_lanes, routes, route_length, search, search_offset, search_size, discs)
    )
    w, q = v[:count], peds[:pcount]
    T.start_frame(w, done, trig)
    for k in range(pcount):
        trig[count + k, 0], trig[count + k, 1] = np.cos(q[k, P_HEADING]), np.sin(q[k, P_HEADING])
    for i in range(count):
        kind = w[i, T.KIND]
        if kind == T.PLAIN or kind == T.PEDAL_KIND or kind == T.OBSTACLE:
            continue  # plain and pedal vehicles keep their last action; obstacles never act
        if kind != T.CONTROLLED and kind != T.TOWN:
            raise ValueError("town_act drives CONTROLLED, PLAIN, PEDAL_KIND and TOWN rows only")
        # one call site each for the inlined follow_road and steering_control (each is compiled anew)
        lane = int(w[i, T.LANE])
        if kind == T.TOWN:  # TownVehicle.act: the turn's speed limit, before follow_road
            limit = lanes[lane, L.SPEED_LIMIT]
            turn_lane = planned_next(w, lanes, i)
            if turn_lane >= 0:
                next_limit = lanes[turn_lane, L.SPEED_LIMIT]
                ahead_m = lanes[lane, L.LENGTH] - lane_s(w, q, lanes, coords, seen, lane, i)
                braking = (py_square(w[i, T.SPEED]) - py_square(next_limit)) / (2 * -p[T.COMFORT_ACC_MIN])
                if ahead_m < TURN_BRAKE_MARGIN_M + braking:
                    limit = min(limit, next_limit)
            w[i, T.TARGET_SPEED] = limit
            if w[i, T.CRASHED] > 0:
                continue
            if w[i, T.ROUTE_END] - w[i, T.ROUTE_START] <= 1:
                target = int(w[i, T.TARGET_LANE])
                random_route(w, lanes, i, target, street_lanes, routes, route_length, rng_words)
        T.follow_road(w, lanes, i)
        if kind == T.TOWN:
            own[T.OWN_FREE] = np.nan  # the own-lane row is made only if MOBIL is asked
            T.change_lane_policy(w, lanes, p, coords, done, trig, i, own)
        w[i, T.STEER] = T.steering_control(w, lanes, i, int(w[i, T.TARGET_LANE]))
        if kind == T.CONTROLLED:
            w[i, T.ACCEL] = T.KP_A * (w[i, T.TARGET_SPEED] - w[i, T.SPEED])
            continue
        front = connected_front(
            w, q, lanes, coords, seen, near, near_count, search, search_offset, search_size, discs, i, lane
        )
        acceleration = town_acceleration(
            w, q, lanes, p, coords, done, trig, seen, i, front,
            junction, from_arm, to_arm, turn, end_junction, end_arm, light, light_states,
        )  # fmt: skip
        target = int(w[i, T.TARGET_LANE])
        if lane != target:
            front = connected_front(
                w, q, lanes, coords, seen, near, near_count, search, search_offset, search_size, discs, i,
                target,
            )  # fmt: skip
            target_a = town_acceleration(
                w, q, lanes, p, coords, done, trig, seen, i, front,
                junction, from_arm, to_arm, turn, end_junction, end_arm, light, light_states,
            )  # fmt: skip
            acceleration = min(acceleration, target_a)
        w[i, T.ACCEL] = T._clip(acceleration, -p[T.ACC_MAX], p[T.ACC_MAX])


@njit(cache=True)
def town_step(v: np.ndarray, count: int, lanes: np.ndarray, dt: float) -> None:
    """Road.step's vehicle loop for rows ``0..count-1``: Vehicle.step (``traffic.step_vehicle``);
    a TOWN row first adds ``dt`` to its IDM timer and after the step does not reverse
    (``speed = max(speed, 0)``). The ego (not TOWN) is not clamped."""
    v, lanes = borrowed((v, lanes))
    for i in range(count):
        kind = v[i, T.KIND]
        if kind == T.OBSTACLE:
            continue
        if kind == T.TOWN:
            v[i, T.TIMER] += dt
        T.step_vehicle(v, lanes, i, dt)
        if kind == T.TOWN and v[i, T.SPEED] < 0.0:  # Python's max(speed, 0.0): speed unless 0.0 > speed
            v[i, T.SPEED] = 0.0


def red_light_runs(lanes, previous_lane, lane, light, light_state, active) -> np.ndarray:
    """(K,) whether each ``active`` world's ego ran a red light in its step: it left lane
    ``previous_lane``, whose light (``light`` (K,), -1: none) was red at the step's end
    (``light_state`` (K, lights)), for a lane ``lane`` that starts where that one ends."""
    k = len(lane)
    state = light_state[np.arange(k), np.maximum(light, 0)] if light_state.shape[1] else np.zeros(k, int)
    crossed = lanes[lane, L.FROM_NODE] == lanes[previous_lane, L.TO_NODE]
    return active & (light >= 0) & crossed & (state == LIGHT_RED)
