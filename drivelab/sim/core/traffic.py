"""highway-env's traffic model as compiled loops over a vehicle array.

One row per vehicle (columns below), in highway-env's ``road.vehicles`` order, so that the
sequential decisions (who sees whose new target lane) and the pairwise collision order are the
same as highway-env's. Each function names the highway-env method it reproduces:

- kinematic bicycle model, ``Vehicle.step`` / ``clip_actions``;
- lane-following steering and speed control, ``ControlledVehicle.steering_control`` / ``speed_control``;
- IDM, ``IDMVehicle.acceleration`` / ``desired_gap``; MOBIL, ``IDMVehicle.change_lane_policy`` / ``mobil``;
- neighbour search, ``Road.neighbour_vehicles``; collisions, ``RoadObject.handle_collisions`` with
  ``utils.are_polygons_intersecting`` (separating axes, with the "will intersect" impact push).
"""

from __future__ import annotations

import numba
import numpy as np
from numba import njit, prange

from drivelab.sim.core import lanes as L
from drivelab.sim.core.borrow import borrowed
from drivelab.sim.core.lanes import distance

# vehicle columns
(
    X, Y, HEADING, SPEED, STEER, ACCEL, LANE, TARGET_LANE, TARGET_SPEED, DELTA, TIMER, CRASHED,
    IMPACT_X, IMPACT_Y, HAS_IMPACT, CHECK_COLLISIONS, KIND, LEN, WID, ROUTE_START, ROUTE_END, ROUTED,
    YIELDING, WRECKED_S, PEDAL,
) = range(25)  # fmt: skip
# A planned route (highway-env's ``vehicle.route``) is stored in the row: MAX_ROUTE entries of
# (road: the row of its lane 0, lane id: -1 for None) from column ROUTE, ROUTE_START..ROUTE_END-1
# still to be driven; ROUTED is 0 where the route is None. YIELDING: stopped by RegulatedRoad's
# right of way. WRECKED_S: seconds a crashed town vehicle has stood. PEDAL: a pedal vehicle's
# commanded acceleration.
ROUTE, MAX_ROUTE = 25, 12
VEHICLE_COLUMNS = ROUTE + 2 * MAX_ROUTE
# The town's routes are longer (up to 19 roads, and a retargeted ego appends a second one): its
# rows are wider. Kernels read a row's route capacity as (row width - ROUTE) // 2.
TOWN_MAX_ROUTE = 40
TOWN_VEHICLE_COLUMNS = ROUTE + 2 * TOWN_MAX_ROUTE
# KIND: a kinematic Vehicle (continuous-control ego), a ControlledVehicle (meta-action ego), an
# IDMVehicle (traffic), a static obstacle (after every vehicle), a TownVehicle, a pedal vehicle (the
# circuits' ego: acceleration = pedal - drag * speed)
PLAIN, CONTROLLED, IDM, OBSTACLE, TOWN, PEDAL_KIND = 0, 1, 2, 3, 4, 5

# IDM / MOBIL parameters, read from highway-env's IDMVehicle class at reset (IDM_PARAMETERS order)
IDM_PARAMETERS = (
    "ACC_MAX", "COMFORT_ACC_MAX", "COMFORT_ACC_MIN", "DISTANCE_WANTED", "TIME_WANTED", "POLITENESS",
    "LANE_CHANGE_MIN_ACC_GAIN", "LANE_CHANGE_MAX_BRAKING_IMPOSED", "LANE_CHANGE_DELAY",
)  # fmt: skip
ACC_MAX, COMFORT_ACC_MAX, COMFORT_ACC_MIN, DISTANCE_WANTED, TIME_WANTED, POLITENESS = range(6)
MIN_ACC_GAIN, MAX_BRAKING_IMPOSED, LANE_CHANGE_DELAY = 6, 7, 8

# ControlledVehicle and Vehicle constants
TAU_ACC, TAU_HEADING, TAU_LATERAL = 0.6, 0.2, 0.6
TAU_PURSUIT = 0.5 * TAU_HEADING
KP_A, KP_HEADING, KP_LATERAL = 1 / TAU_ACC, 1 / TAU_HEADING, 1 / TAU_LATERAL
MAX_STEERING_ANGLE = np.pi / 3
CAR_LENGTH, CAR_WIDTH = 5.0, 2.0
MAX_SPEED, MIN_SPEED = 40.0, -40.0
# The CARLA study's pedal vehicle: a constant throttle of 0.35 (5 m/s² · 0.35 commanded) settles at
# 30 km/h, the speed the seed reports for its lane actions: drag = 5 · 0.35 / (30 / 3.6).
PEDAL_DRAG_PER_S = 5.0 * 0.35 / (30.0 / 3.6)


@njit(cache=True, inline="always")
def not_zero(value: float) -> float:
    if np.abs(value) > 1e-2:
        return value
    return 1e-2 if value >= 0 else -1e-2


@njit(cache=True, inline="always")
def _clip(value: float, low: float, high: float) -> float:
    return min(max(value, low), high)


@njit(cache=True, inline="always")
def speed_index(speed: float, speeds: np.ndarray) -> int:
    """MDPVehicle.speed_to_index: the index of the allowed speed nearest ``speed``."""
    top = speeds.size - 1
    ratio = (speed - speeds[0]) / (speeds[-1] - speeds[0])
    return int(min(max(np.rint(ratio * top), 0.0), float(top)))  # np.round: half to even


@njit(cache=True, inline="always")
def steering_control(v: np.ndarray, lanes: np.ndarray, i: int, target: int) -> float:
    """ControlledVehicle.steering_control: lateral P → heading reference → heading P → steering."""
    s, r = L.local_coordinates(lanes, target, v[i, X], v[i, Y])
    future_heading = L.heading_at(lanes, target, s + v[i, SPEED] * TAU_PURSUIT)
    lateral_speed_command = -KP_LATERAL * r
    heading_command = L.arcsin0(_clip(lateral_speed_command / not_zero(v[i, SPEED]), -1.0, 1.0))
    heading_ref = future_heading + _clip(heading_command, -np.pi / 4, np.pi / 4)
    heading_rate_command = KP_HEADING * L.wrap_to_pi(heading_ref - v[i, HEADING])
    slip_angle = L.arcsin0(_clip(v[i, LEN] / 2 / not_zero(v[i, SPEED]) * heading_rate_command, -1.0, 1.0))
    steering = L.arctan0(2 * L.tan0(slip_angle))
    return _clip(steering, -MAX_STEERING_ANGLE, MAX_STEERING_ANGLE)


@njit(cache=True)
def frame_cache(v: np.ndarray, lanes: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Scratch arrays for one simulation frame's ``act``, each value computed once per frame (the
    same bits). ``coords`` (L, N, 4): per lane, every vehicle's (longitudinal, lateral, on the lane
    within 1 m) and, in column 3, the vehicles on the lane sorted by (longitudinal, row); ``done``
    (L,): how many vehicles are on the lane, -1 until first used; ``trig`` (N, 2): cos, sin of
    every heading."""
    coords = np.empty((lanes.shape[0], v.shape[0], 4))
    return coords, np.full(lanes.shape[0], -1, dtype=np.int64), np.empty((v.shape[0], 2))


@njit(cache=True)
def start_frame(v: np.ndarray, done: np.ndarray, trig: np.ndarray) -> None:
    v, done, trig = borrowed((v, done, trig))
    done[:] = -1
    for j in range(v.shape[0]):
        trig[j, 0], trig[j, 1] = L.cos0(v[j, HEADING]), L.sin0(v[j, HEADING])


@njit(cache=True, inline="always")
def lane_coordinates(
    v: np.ndarray, lanes: np.ndarray, coords: np.ndarray, done: np.ndarray, lane: int
) -> None:
    """Fill ``coords[lane]`` once per frame (``fill_lane_coordinates``; only this check is inlined,
    which keeps ``act``'s compile time short)."""
    if done[lane] < 0:
        fill_lane_coordinates(v, lanes, coords, done, lane)


@njit(cache=True)
def fill_lane_coordinates(
    v: np.ndarray, lanes: np.ndarray, coords: np.ndarray, done: np.ndarray, lane: int
) -> None:
    """Every vehicle's ``local_coordinates`` in ``lane``, whether it is on the lane as
    ``Road.neighbour_vehicles`` counts it (``on_lane``, 1 m margin), and the rows of those on it
    sorted by (longitudinal, row) (insertion sort), into ``coords[lane]`` and ``done[lane]``."""
    v, lanes, coords, done = borrowed((v, lanes, coords, done))
    count = 0
    for j in range(v.shape[0]):
        s_j, r_j = L.local_coordinates(lanes, lane, v[j, X], v[j, Y])
        coords[lane, j, 0], coords[lane, j, 1] = s_j, r_j
        coords[lane, j, 2] = 0.0
        if L.on_lane(lanes, lane, s_j, r_j, 1.0):
            coords[lane, j, 2] = 1.0
            rank = count
            while rank > 0 and coords[lane, int(coords[lane, rank - 1, 3]), 0] > s_j:
                coords[lane, rank, 3] = coords[lane, rank - 1, 3]
                rank -= 1
            coords[lane, rank, 3] = j
            count += 1
    done[lane] = count


@njit(cache=True, inline="always")
def cached_neighbours(
    v: np.ndarray, lanes: np.ndarray, coords: np.ndarray, done: np.ndarray, i: int, lane: int
) -> tuple[int, int]:
    """Road.neighbour_vehicles: the vehicles just ahead of and behind vehicle i along ``lane``.

    highway-env scans every vehicle on the lane: the front one is the nearest at or ahead of i
    (the last row among equals), the rear one the nearest behind (the first row among equals).
    Here the same vehicles are found by a binary search in the lane's sorted order."""
    lane_coordinates(v, lanes, coords, done, lane)
    count = done[lane]
    s_i = coords[lane, i, 0]
    low, high = 0, count
    while low < high:  # the first rank at or ahead of s_i
        middle = (low + high) // 2
        if coords[lane, int(coords[lane, middle, 3]), 0] < s_i:
            low = middle + 1
        else:
            high = middle
    front, rear = -1, -1
    rank = low
    while rank < count and int(coords[lane, rank, 3]) == i:
        rank += 1
    if rank < count:
        front = int(coords[lane, rank, 3])
        s_front = coords[lane, front, 0]
        for later in range(rank + 1, count):
            j = int(coords[lane, later, 3])
            if coords[lane, j, 0] != s_front:
                break
            if j != i:
                front = j
    if low > 0:
        rank = low - 1
        s_rear = coords[lane, int(coords[lane, rank, 3]), 0]
        while rank > 0 and coords[lane, int(coords[lane, rank - 1, 3]), 0] == s_rear:
            rank -= 1
        rear = int(coords[lane, rank, 3])
    return front, rear


@njit(cache=True, inline="always")
def cached_desired_gap(v: np.ndarray, p: np.ndarray, trig: np.ndarray, ego: int, front: int) -> float:
    """IDMVehicle.desired_gap, projected on the ego's direction (``trig``: headings' cos, sin)."""
    return desired_gap_to(v, p, trig, ego, front, v[front, SPEED])


@njit(cache=True, inline="always")
def desired_gap_to(v, p, trig, ego: int, front: int, front_speed: float) -> float:
    """``cached_desired_gap`` to a front object at ``front_speed`` whose heading is ``trig[front]``."""
    ab = -p[COMFORT_ACC_MAX] * p[COMFORT_ACC_MIN]
    cos_e, sin_e = trig[ego, 0], trig[ego, 1]
    dvx = v[ego, SPEED] * cos_e - front_speed * trig[front, 0]
    dvy = v[ego, SPEED] * sin_e - front_speed * trig[front, 1]
    dv = dvx * cos_e + dvy * sin_e
    return p[DISTANCE_WANTED] + v[ego, SPEED] * p[TIME_WANTED] + v[ego, SPEED] * dv / (2 * np.sqrt(ab))


@njit(cache=True, inline="always")
def idm_free_road(v: np.ndarray, lanes: np.ndarray, p: np.ndarray, me: int, ego: int) -> float:
    """The free-road term of IDMVehicle.acceleration as computed by vehicle ``me`` (its DELTA)
    for ``ego``: what ``ego`` would do with no one ahead (0 for no vehicle or an obstacle)."""
    if ego < 0 or v[ego, KIND] == OBSTACLE:  # highway-env: only a Vehicle accelerates
        return 0.0
    target_speed = v[ego, TARGET_SPEED] if v[ego, KIND] != PLAIN else 0.0
    limit = lanes[int(v[ego, LANE]), L.SPEED_LIMIT]
    if not np.isnan(limit):
        target_speed = _clip(target_speed, 0.0, limit)
    ratio = max(v[ego, SPEED], 0.0) / np.abs(not_zero(target_speed))
    return p[COMFORT_ACC_MAX] * (1 - ratio ** v[me, DELTA])


@njit(cache=True, inline="always")
def idm_behind(v, lanes, p, coords, done, trig, free_road: float, ego: int, front: int) -> float:
    """IDMVehicle.acceleration from its free-road term (``idm_free_road``, computed once for the
    several fronts MOBIL asks about): less the interaction with ``front`` (none: -1)."""
    if ego < 0 or v[ego, KIND] == OBSTACLE:
        return 0.0
    acceleration = free_road
    if front >= 0:
        lane = int(v[ego, LANE])
        lane_coordinates(v, lanes, coords, done, lane)
        gap_m = coords[lane, front, 0] - coords[lane, ego, 0]
        gap = cached_desired_gap(v, p, trig, ego, front) / not_zero(gap_m)
        acceleration -= p[COMFORT_ACC_MAX] * gap**2
    return acceleration


@njit(cache=True, inline="always")
def cached_idm_acceleration(v, lanes, p, coords, done, trig, me: int, ego: int, front: int) -> float:
    """IDMVehicle.acceleration as computed by vehicle ``me`` (its DELTA) for ``ego`` behind ``front``."""
    free_road = idm_free_road(v, lanes, p, me, ego)
    return idm_behind(v, lanes, p, coords, done, trig, free_road, ego, front)


# What MOBIL needs of vehicle i's own lane, for both side lanes (a (OWN_SIZE,) scratch row that
# ``act`` fills once per vehicle and frame; the old follower's accelerations on first use)
OWN_FREE, OWN_A, OWN_FRONT, OWN_REAR, OWN_REAR_A, OWN_REAR_PRED_A, OWN_REAR_FILLED, OWN_SIZE = range(8)


@njit(cache=True, inline="always")
def own_lane(v, lanes, p, coords, done, trig, i: int, own) -> None:
    """Fill ``own`` for vehicle i: its front and rear on its lane, its free-road term and its
    acceleration behind that front (IDMVehicle.acceleration(self, front))."""
    front, rear = cached_neighbours(v, lanes, coords, done, i, int(v[i, LANE]))
    own[OWN_FREE] = idm_free_road(v, lanes, p, i, i)
    own[OWN_A] = idm_behind(v, lanes, p, coords, done, trig, own[OWN_FREE], i, front)
    own[OWN_FRONT], own[OWN_REAR], own[OWN_REAR_FILLED] = front, rear, 0.0


@njit(cache=True)  # not inlined: inlined, its body made numba compile ``act`` for long
def mobil_side(v, lanes, p, coords, done, trig, i: int, lane: int, own) -> bool:
    """IDMVehicle.mobil: is a change to ``lane`` safe for the new follower, and worth it?
    (``own``: vehicle i's row of ``own_lane``; highway-env's arithmetic, each value computed once.)"""
    v, lanes, p, coords, done, trig, own = borrowed((v, lanes, p, coords, done, trig, own))
    new_preceding, new_following = cached_neighbours(v, lanes, coords, done, i, lane)
    new_following_free = idm_free_road(v, lanes, p, i, new_following)
    new_following_a = idm_behind(
        v, lanes, p, coords, done, trig, new_following_free, new_following, new_preceding
    )
    new_following_pred_a = idm_behind(v, lanes, p, coords, done, trig, new_following_free, new_following, i)
    if new_following_pred_a < -p[MAX_BRAKING_IMPOSED]:
        return False
    self_pred_a = idm_behind(v, lanes, p, coords, done, trig, own[OWN_FREE], i, new_preceding)
    start = int(v[i, ROUTE_START])
    if start < v[i, ROUTE_END] and v[i, ROUTE + 2 * start + 1] >= 0:
        # the next route step names a lane: only move towards it, and only without hard braking
        target_id = lanes[int(v[i, TARGET_LANE]), L.LANE_ID]
        wanted_id = v[i, ROUTE + 2 * start + 1]
        if np.sign(lanes[lane, L.LANE_ID] - target_id) != np.sign(wanted_id - target_id):
            return False
        return not self_pred_a < -p[MAX_BRAKING_IMPOSED]
    if own[OWN_REAR_FILLED] == 0.0:
        old_following, old_preceding = int(own[OWN_REAR]), int(own[OWN_FRONT])
        old_following_free = idm_free_road(v, lanes, p, i, old_following)
        own[OWN_REAR_A] = idm_behind(v, lanes, p, coords, done, trig, old_following_free, old_following, i)
        own[OWN_REAR_PRED_A] = idm_behind(
            v, lanes, p, coords, done, trig, old_following_free, old_following, old_preceding
        )
        own[OWN_REAR_FILLED] = 1.0
    jerk = (
        self_pred_a
        - own[OWN_A]
        + p[POLITENESS] * (new_following_pred_a - new_following_a + own[OWN_REAR_PRED_A] - own[OWN_REAR_A])
    )
    return jerk >= p[MIN_ACC_GAIN]


@njit(cache=True, inline="always")
def abort_change(v, lanes, p, coords, done, trig, i: int, lane: int, target: int) -> None:
    """IDMVehicle.change_lane_policy's abort: vehicle i, changing from ``lane`` to ``target`` on
    the same road, goes back when another vehicle entering ``target`` is within its desired gap."""
    if lanes[lane, L.FIRST_OF_ROAD] != lanes[target, L.FIRST_OF_ROAD]:
        return
    for j in range(v.shape[0]):
        if (
            j != i
            and int(v[j, LANE]) != target
            and (v[j, KIND] == CONTROLLED or v[j, KIND] == IDM)
            and int(v[j, TARGET_LANE]) == target
        ):
            lane_coordinates(v, lanes, coords, done, lane)
            if 0 < coords[lane, j, 0] - coords[lane, i, 0] < cached_desired_gap(v, p, trig, i, j):
                v[i, TARGET_LANE] = lane
                return


@njit(cache=True, inline="always")
def change_lane_policy(v, lanes, p, coords, done, trig, i: int, own) -> None:
    """IDMVehicle.change_lane_policy: abort a change into a lane someone else is entering; else,
    every LANE_CHANGE_DELAY seconds, ask MOBIL about each side lane (the right one last).
    ``own`` (OWN_SIZE,): vehicle i's ``own_lane`` row, or scratch whose OWN_FREE is NaN (filled
    here when MOBIL is asked)."""
    lane, target = int(v[i, LANE]), int(v[i, TARGET_LANE])
    if lane != target:
        abort_change(v, lanes, p, coords, done, trig, i, lane, target)
        return
    if not p[LANE_CHANGE_DELAY] < v[i, TIMER]:
        return
    v[i, TIMER] = 0.0
    lane_id, count = lanes[lane, L.LANE_ID], lanes[lane, L.LANE_COUNT]
    for side in (-1, 1):
        if not (0 <= lane_id + side < count):
            continue
        candidate = lane + side
        if not L.is_reachable_from(lanes, candidate, v[i, X], v[i, Y]):
            continue
        if np.abs(v[i, SPEED]) < 1:
            continue
        if np.isnan(own[OWN_FREE]):
            own_lane(v, lanes, p, coords, done, trig, i, own)
        if mobil_side(v, lanes, p, coords, done, trig, i, candidate, own):
            v[i, TARGET_LANE] = candidate


@njit(cache=True)
def lane_on_next_road(
    lanes: np.ndarray, lane: int, next_road: int, next_id: int, x: float, y: float
) -> tuple[int, float]:
    """RoadNetwork.next_lane_given_next_road: keep the lane id where the lane counts agree,
    else take the next road's lane closest to (x, y). Returns (lane row, its distance)."""
    (lanes,) = borrowed((lanes,))
    count = int(lanes[next_road, L.LANE_COUNT])
    if lanes[lane, L.LANE_COUNT] == count:
        if next_id < 0:
            next_id = int(lanes[lane, L.LANE_ID])
    else:
        best = np.inf
        for k in range(count):
            d = distance(lanes, next_road + k, x, y)
            if d < best:
                next_id, best = k, d
    return next_road + next_id, distance(lanes, next_road + next_id, x, y)


@njit(cache=True)
def next_lane(v: np.ndarray, lanes: np.ndarray, i: int) -> int:
    """RoadNetwork.next_lane for vehicle i's target lane: the route's next road when it starts
    where this one ends (dropping a finished route step), else the successor road whose lane is
    closest; the same lane when the road leads nowhere."""
    v, lanes = borrowed((v, lanes))
    lane = int(v[i, TARGET_LANE])
    road, end_node = int(lanes[lane, L.FIRST_OF_ROAD]), lanes[lane, L.TO_NODE]
    next_road, next_id = -1, -1
    start, stop = int(v[i, ROUTE_START]), int(v[i, ROUTE_END])
    if start < stop:
        if int(v[i, ROUTE + 2 * start]) == road:
            start += 1
            v[i, ROUTE_START] = start
        if start < stop and lanes[int(v[i, ROUTE + 2 * start]), L.FROM_NODE] == end_node:
            next_road, next_id = int(v[i, ROUTE + 2 * start]), int(v[i, ROUTE + 2 * start + 1])
    s, _ = L.local_coordinates(lanes, lane, v[i, X], v[i, Y])
    x, y = L.position(lanes, lane, s, 0.0)
    if next_road >= 0:
        return lane_on_next_road(lanes, lane, next_road, next_id, x, y)[0]
    best_lane, best = lane, np.inf
    for candidate in range(lanes.shape[0]):  # roads leaving the end node, in the network's order
        if lanes[candidate, L.FIRST_OF_ROAD] != candidate or lanes[candidate, L.FROM_NODE] != end_node:
            continue
        row, d = lane_on_next_road(lanes, lane, candidate, -1, x, y)
        if d < best:
            best_lane, best = row, d
    return best_lane


@njit(cache=True, inline="always")
def follow_road(v: np.ndarray, lanes: np.ndarray, i: int) -> None:
    """ControlledVehicle.follow_road: at the end of the target lane, target the next one."""
    target = int(v[i, TARGET_LANE])
    s, _ = L.local_coordinates(lanes, target, v[i, X], v[i, Y])
    if s > lanes[target, L.LENGTH] - L.VEHICLE_LENGTH / 2:
        v[i, TARGET_LANE] = next_lane(v, lanes, i)


@njit(cache=True)
def act(v, lanes, p, coords, done, trig, own) -> None:
    """Road.act: every vehicle decides its controls, in list order (``frame_cache`` arrays;
    ``own`` (OWN_SIZE,) scratch, the caller's, so that it is borrowed here as well)."""
    v, lanes, p, coords, done, trig, own = borrowed((v, lanes, p, coords, done, trig, own))
    start_frame(v, done, trig)
    for i in range(v.shape[0]):
        kind = v[i, KIND]
        if kind == PLAIN or kind == PEDAL_KIND or kind == OBSTACLE:
            continue  # plain and pedal vehicles keep the last continuous action; obstacles never act
        if kind == IDM and v[i, CRASHED] > 0:
            continue
        follow_road(v, lanes, i)
        if kind == CONTROLLED:
            v[i, STEER] = steering_control(v, lanes, i, int(v[i, TARGET_LANE]))
            v[i, ACCEL] = KP_A * (v[i, TARGET_SPEED] - v[i, SPEED])
            continue
        own_lane(v, lanes, p, coords, done, trig, i, own)
        change_lane_policy(v, lanes, p, coords, done, trig, i, own)
        v[i, STEER] = steering_control(v, lanes, i, int(v[i, TARGET_LANE]))
        acceleration = own[OWN_A]
        if int(v[i, LANE]) != int(v[i, TARGET_LANE]):
            front, _ = cached_neighbours(v, lanes, coords, done, i, int(v[i, TARGET_LANE]))
            target_a = idm_behind(v, lanes, p, coords, done, trig, own[OWN_FREE], i, front)
            acceleration = min(acceleration, target_a)
        v[i, ACCEL] = _clip(acceleration, -p[ACC_MAX], p[ACC_MAX])


@njit(cache=True, inline="always")
def step_vehicle(v: np.ndarray, lanes: np.ndarray, i: int, dt: float) -> None:
    """Vehicle.step: clip the actions, integrate the kinematic bicycle, find the lane. A pedal
    vehicle's acceleration is first its pedal minus the drag (the circuits' PedalVehicle.step)."""
    if v[i, KIND] == IDM:
        v[i, TIMER] += dt
    elif v[i, KIND] == PEDAL_KIND:
        v[i, ACCEL] = v[i, PEDAL] - PEDAL_DRAG_PER_S * v[i, SPEED]
    if v[i, CRASHED] > 0:
        v[i, STEER] = 0.0
        v[i, ACCEL] = -1.0 * v[i, SPEED]
    if v[i, SPEED] > MAX_SPEED:
        v[i, ACCEL] = min(v[i, ACCEL], 1.0 * (MAX_SPEED - v[i, SPEED]))
    elif v[i, SPEED] < MIN_SPEED:
        v[i, ACCEL] = max(v[i, ACCEL], 1.0 * (MIN_SPEED - v[i, SPEED]))
    beta = L.arctan0(1 / 2 * L.tan0(v[i, STEER]))
    v[i, X] += v[i, SPEED] * L.cos0(v[i, HEADING] + beta) * dt
    v[i, Y] += v[i, SPEED] * L.sin0(v[i, HEADING] + beta) * dt
    if v[i, HAS_IMPACT] > 0:
        v[i, X] += v[i, IMPACT_X]
        v[i, Y] += v[i, IMPACT_Y]
        v[i, CRASHED] = 1.0
        v[i, HAS_IMPACT] = 0.0
    v[i, HEADING] += v[i, SPEED] * L.sin0(beta) / (v[i, LEN] / 2) * dt
    v[i, SPEED] += v[i, ACCEL] * dt
    v[i, LANE] = L.closest_lane(lanes, v[i, X], v[i, Y], v[i, HEADING], int(v[i, LANE]))


@njit(cache=True)
def _polygon(v: np.ndarray, i: int) -> np.ndarray:
    """Vehicle i's rectangle: its 4 corners and the first again, (5, 2)."""
    corners = np.empty((5, 2))
    _polygon_into(v, i, corners)
    return corners


@njit(cache=True, inline="always")
def _polygon_into(v: np.ndarray, i: int, corners: np.ndarray) -> None:
    c, s = L.cos0(v[i, HEADING]), L.sin0(v[i, HEADING])
    half_l, half_w = v[i, LEN] / 2, v[i, WID] / 2
    local = ((-half_l, -half_w), (-half_l, half_w), (half_l, half_w), (half_l, -half_w))
    for k in range(4):
        px, py = local[k]
        corners[k, 0] = c * px + -s * py + v[i, X]
        corners[k, 1] = s * px + c * py + v[i, Y]
    corners[4, 0], corners[4, 1] = corners[0, 0], corners[0, 1]  # element-wise: cheaper to compile


@njit(cache=True)
def _project(polygon: np.ndarray, nx: float, ny: float) -> tuple[float, float]:
    low, high = np.inf, -np.inf
    for k in range(polygon.shape[0]):
        value = polygon[k, 0] * nx + polygon[k, 1] * ny
        low, high = min(low, value), max(high, value)
    return low, high


@njit(cache=True)
def _interval_distance(min_a: float, max_a: float, min_b: float, max_b: float) -> float:
    return min_b - max_a if min_a < min_b else min_a - max_b


@njit(cache=True)
def polygons_intersecting(a, b, dax, day, dbx, dby):
    """utils.are_polygons_intersecting: (intersecting, will intersect, translation x, y)."""
    intersecting, will_intersect = True, True
    min_distance, axis_x, axis_y = np.inf, 0.0, 0.0
    center_dx = (a[0, 0] + a[1, 0] + a[2, 0] + a[3, 0]) / 4 - (b[0, 0] + b[1, 0] + b[2, 0] + b[3, 0]) / 4
    center_dy = (a[0, 1] + a[1, 1] + a[2, 1] + a[3, 1]) / 4 - (b[0, 1] + b[1, 1] + b[2, 1] + b[3, 1]) / 4
    for polygon in (a, b):
        for k in range(4):
            nx, ny = -polygon[k + 1, 1] + polygon[k, 1], polygon[k + 1, 0] - polygon[k, 0]
            norm = np.sqrt(nx * nx + ny * ny)
            nx, ny = nx / norm, ny / norm
            min_a, max_a = _project(a, nx, ny)
            min_b, max_b = _project(b, nx, ny)
            if _interval_distance(min_a, max_a, min_b, max_b) > 0:
                intersecting = False
            velocity_projection = nx * (dax - dbx) + ny * (day - dby)
            if velocity_projection < 0:
                min_a += velocity_projection
            else:
                max_a += velocity_projection
            distance = _interval_distance(min_a, max_a, min_b, max_b)
            if distance > 0:
                will_intersect = False
            if not intersecting and not will_intersect:
                break
            if np.abs(distance) < min_distance:
                min_distance = np.abs(distance)
                sign = 1.0 if center_dx * nx + center_dy * ny > 0 else -1.0
                axis_x, axis_y = sign * nx, sign * ny
    return intersecting, will_intersect, min_distance * axis_x, min_distance * axis_y


@njit(cache=True)
def handle_collisions(v: np.ndarray, dt: float) -> None:
    """Road.step's collision pass: each vehicle against the vehicles after it, then the obstacles
    (which sit after every vehicle), as RoadObject.handle_collisions."""
    (v,) = borrowed((v,))
    n = v.shape[0]
    diagonals, polygon_i, polygon_j = np.empty(n), np.empty((5, 2)), np.empty((5, 2))
    for i in range(n):
        diagonals[i] = np.sqrt(v[i, LEN] ** 2 + v[i, WID] ** 2)
    for i in range(n):
        if v[i, KIND] == OBSTACLE:
            break
        for j in range(i + 1, n):
            if not (v[i, CHECK_COLLISIONS] > 0 or v[j, CHECK_COLLISIONS] > 0):
                continue
            dx, dy = v[j, X] - v[i, X], v[j, Y] - v[i, Y]
            reach = (diagonals[i] + diagonals[j]) / 2 + v[i, SPEED] * dt
            # sqrt(dx² + dy²) ≥ max(|dx|, |dy|): the square root only when both are within reach
            if np.abs(dx) > reach or np.abs(dy) > reach or np.sqrt(dx * dx + dy * dy) > reach:
                continue
            ci, si = L.cos0(v[i, HEADING]), L.sin0(v[i, HEADING])
            cj, sj = L.cos0(v[j, HEADING]), L.sin0(v[j, HEADING])
            _polygon_into(v, i, polygon_i)
            _polygon_into(v, j, polygon_j)
            intersecting, will_intersect, tx, ty = polygons_intersecting(
                polygon_i, polygon_j,
                v[i, SPEED] * ci * dt, v[i, SPEED] * si * dt, v[j, SPEED] * cj * dt, v[j, SPEED] * sj * dt,
            )  # fmt: skip
            if will_intersect:
                if v[j, KIND] == OBSTACLE:  # the obstacle does not move: the vehicle takes it all
                    v[i, IMPACT_X], v[i, IMPACT_Y], v[i, HAS_IMPACT] = tx, ty, 1.0
                else:
                    v[i, IMPACT_X], v[i, IMPACT_Y], v[i, HAS_IMPACT] = tx / 2, ty / 2, 1.0
                    v[j, IMPACT_X], v[j, IMPACT_Y], v[j, HAS_IMPACT] = -tx / 2, -ty / 2, 1.0
            if intersecting:
                v[i, CRASHED], v[j, CRASHED] = 1.0, 1.0


@njit(cache=True)
def predicted_pose(v: np.ndarray, lanes: np.ndarray, i: int, t: float) -> tuple[float, float, float]:
    """ControlledVehicle.predict_trajectory_constant_speed at time t: (x, y, heading) along its
    route (RoadNetwork.position_heading_along_route; a route step without a lane id keeps the
    current lane id)."""
    lane = int(v[i, LANE])
    s, _ = L.local_coordinates(lanes, lane, v[i, X], v[i, Y])
    s += v[i, SPEED] * t
    start, stop = int(v[i, ROUTE_START]), int(v[i, ROUTE_END])
    if start >= stop:  # highway-env: route or [lane_index]
        return L.position(lanes, lane, s, 0.0) + (L.heading_at(lanes, lane, s),)
    k = start
    while True:
        lane_id = int(v[i, ROUTE + 2 * k + 1])
        row = int(v[i, ROUTE + 2 * k]) + (lane_id if lane_id >= 0 else int(lanes[lane, L.LANE_ID]))
        if k + 1 < stop and s > lanes[row, L.LENGTH]:
            s -= lanes[row, L.LENGTH]
            k += 1
            continue
        return L.position(lanes, row, s, 0.0) + (L.heading_at(lanes, row, s),)


@njit(cache=True)
def _corner_inside(x1, y1, length1, width1, angle1, x2, y2, length2, width2, angle2) -> bool:
    """utils.has_corner_inside: a corner, edge midpoint or the centre of rectangle 1 in rectangle 2."""
    c1, s1 = np.cos(angle1), np.sin(angle1)
    c2, s2 = np.cos(angle2), np.sin(angle2)
    hl, hw = length1 / 2, width1 / 2
    local = (
        (-hl, -hw), (-hl, hw), (hl, hw), (hl, -hw), (0.0, 0.0), (-hl, 0.0), (hl, 0.0), (0.0, -hw), (0.0, hw)
    )  # fmt: skip
    for k in range(9):
        px, py = local[k]
        dx = c1 * px + -s1 * py + x1 - x2
        dy = s1 * px + c1 * py + y1 - y2
        u, w = c2 * dx + -s2 * dy, s2 * dx + c2 * dy  # highway-env rotates by +angle here
        if -length2 / 2 <= u <= length2 / 2 and -width2 / 2 <= w <= width2 / 2:
            return True
    return False


@njit(cache=True)
def conflict_possible(v: np.ndarray, lanes: np.ndarray, i: int, j: int) -> bool:
    """RegulatedRoad.is_conflict_possible: do i and j, driving on at constant speed along their
    routes, come within a (1.5 length x 0.9 width) box of each other in the next 3 s?"""
    for step in range(1, 12):  # np.arange(0.25, 3, 0.25)
        t = 0.25 * step
        x1, y1, h1 = predicted_pose(v, lanes, i, t)
        x2, y2, h2 = predicted_pose(v, lanes, j, t)
        if np.sqrt((x2 - x1) ** 2 + (y2 - y1) ** 2) > v[i, LEN]:
            continue
        l1, w1, l2, w2 = 1.5 * v[i, LEN], 0.9 * v[i, WID], 1.5 * v[j, LEN], 0.9 * v[j, WID]
        if _corner_inside(x1, y1, l1, w1, h1, x2, y2, l2, w2, h2) or _corner_inside(
            x2, y2, l2, w2, h2, x1, y1, l1, w1, h1
        ):
            return True
    return False


@njit(cache=True)
def front_distance(v: np.ndarray, i: int, j: int) -> float:
    """RoadObject.front_distance_to: how far j is ahead of i along i's heading."""
    return np.cos(v[i, HEADING]) * (v[j, X] - v[i, X]) + np.sin(v[i, HEADING]) * (v[j, Y] - v[i, Y])


@njit(cache=True)
def enforce_road_rules(
    v: np.ndarray, lanes: np.ndarray, release_cap_mps: float = np.inf, prioritised_only: bool = False
) -> None:
    """RegulatedRoad.enforce_road_rules: release the vehicles that yielded (highway-env's
    YIELD_DURATION is 0: they yield until the next regulation step), then, for each pair that may
    conflict, the one on the lower-priority lane (or behind) stops.

    :param release_cap_mps: a released vehicle's target speed is its lane's speed limit, at most
        this (the procedural maps' traffic cruises below the limit; inf: highway-env's rule).
    :param prioritised_only: only pairs where one vehicle is on a lane of priority > 0 (the
        procedural maps' junctions and their approaches) are regulated; elsewhere IDM/MOBIL alone
        keeps the gaps (False: every pair, highway-env's rule)."""
    n = v.shape[0]
    for i in range(n):
        if v[i, YIELDING] > 0:
            limit = lanes[int(v[i, LANE]), L.SPEED_LIMIT]
            v[i, TARGET_SPEED] = release_cap_mps if limit > release_cap_mps else limit  # NaN kept
            v[i, YIELDING] = 0.0
    for i in range(n - 1):
        if v[i, KIND] == OBSTACLE:
            break
        for j in range(i + 1, n):
            if v[j, KIND] == OBSTACLE:
                continue
            priority_i, priority_j = lanes[int(v[i, LANE]), L.PRIORITY], lanes[int(v[j, LANE]), L.PRIORITY]
            if prioritised_only and priority_i <= 0 and priority_j <= 0:
                continue
            if not conflict_possible(v, lanes, i, j):
                continue
            if priority_i != priority_j:
                yielding = j if priority_i > priority_j else i
            else:  # the one behind yields
                yielding = i if front_distance(v, i, j) > front_distance(v, j, i) else j
            if v[yielding, KIND] == IDM:  # the meta-action ego (an MDPVehicle) never yields
                v[yielding, TARGET_SPEED] = 0.0
                v[yielding, YIELDING] = 1.0


@njit(cache=True)
def simulate(v, lanes, p, frames: int, dt: float, regulation) -> None:
    """AbstractEnv._simulate for ``frames`` simulation steps of ``dt`` seconds.

    :param regulation: [period, road steps so far]: a RegulatedRoad enforces its rules every
        ``period`` road steps (0: a plain Road); the step count is updated in place.
    """
    v, lanes, p = borrowed((v, lanes, p))
    coords, done, trig = frame_cache(v, lanes)
    own = np.empty(OWN_SIZE)  # act's scratch, borrowed there
    for _ in range(frames):
        act(v, lanes, p, coords, done, trig, own)
        if regulation[0] > 0:
            regulation[1] += 1
            if regulation[1] % regulation[0] == 0:
                enforce_road_rules(v, lanes)
        for i in range(v.shape[0]):
            if v[i, KIND] != OBSTACLE:
                step_vehicle(v, lanes, i, dt)
        handle_collisions(v, dt)


@njit(cache=True)
def _simulate_worlds_serial(v, count, lanes, p, frames, dt, regulation, active) -> None:
    for k in range(v.shape[0]):
        if active[k]:
            simulate(v[k, : count[k]], lanes, p, frames, dt, regulation[k])


@njit(cache=True, parallel=True)
def _simulate_worlds_parallel(v, count, lanes, p, frames, dt, regulation, active) -> None:
    for k in prange(v.shape[0]):
        if active[k]:
            simulate(v[k, : count[k]], lanes, p, frames, dt, regulation[k])


def simulate_worlds(v, count, lanes, p, frames: int, dt: float, regulation, active) -> None:
    """``simulate`` for K worlds: world k's vehicles are ``v[k, :count[k]]`` of the (K, N_max,
    VEHICLE_COLUMNS) buffer and its regulation state ``regulation[k]`` (K, 2); only the worlds
    of ``active`` (K,) bool are simulated, one numba thread per world where numba has several
    threads and there are several worlds."""
    parallel = v.shape[0] > 1 and numba.get_num_threads() > 1
    kernel = _simulate_worlds_parallel if parallel else _simulate_worlds_serial
    kernel(v, count, lanes, p, frames, dt, regulation, active)
