"""The procedural maps' traffic as compiled loops over ONE world's arrays (the caller loops the worlds).

``blocks_simulate`` is ``traffic.simulate`` with ``blocks_act`` in place of ``traffic.act``; it
differs for the traffic rows (KIND ``IDM``) only:

- **lane changes** (highway-env's MOBIL, ``blocks_mobil``) only on ``changeable`` lanes (side by
  side, outside the intersections and roundabouts: ``blocks_spawn.changeable_lanes``), and only
  when the rest of the route can still be driven from the new lane (``route_feasible``). On an
  ``ending`` lane (one leading into a taper that merges into its neighbour) the change is
  mandatory: checked every frame, taken as soon as MOBIL's safety criterion holds
  (``merge_safe``); a vehicle that finds no gap stops at the lane's end (``stop_ahead``).
- **the next lane** at the end of a lane (``blocks_follow_road``): the continuation on the route's
  next road, its named lane first, else one from which the rest of the route can be driven; off
  the route, the continuation with the same lane id, else the first; a dead end is kept (the
  vehicle leaves the map).
- **traffic lights**: the town's stop-line rule (``junctions.traffic.town_acceleration`` with no
  leader), its deceleration taken when lower.

Arrays (one world): ``v`` (N, VEHICLE_COLUMNS) vehicle rows; ``lanes`` the map's lane rows (lane
indices local to the map); the description's LANE_METADATA arrays (``light`` -1 on lanes without
one); ``changeable``, ``ending`` (L,) bool; ``successor_start`` (L + 1,) offsets into
``successors`` (E,) (the CSR of ``blocks_spawn._continuations``, offsets possibly shifted);
``light_states`` (M,) LIGHT_* of the map's lights.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from drivelab.sim.core import lanes as L
from drivelab.sim.core import traffic as T
from drivelab.sim.core.borrow import borrowed
from drivelab.sim.junctions.rows import PEDESTRIAN_COLUMNS
from drivelab.sim.junctions.traffic import stop_ahead, town_acceleration

_NO_PEDESTRIANS = np.zeros((0, PEDESTRIAN_COLUMNS))


@njit(cache=True)
def route_feasible(
    v: np.ndarray, lanes: np.ndarray, successor_start: np.ndarray, successors: np.ndarray, i: int,
    lane: int, first: int,
) -> bool:  # fmt: skip
    """Whether vehicle i's route entries ``first`` … ROUTE_END − 1 (roads) can be driven from lane
    row ``lane``, each step a lane continuing the one before it (depth-first over the
    continuations; a route holds at most a dozen roads and few lanes branch)."""
    v, lanes, successor_start, successors = borrowed((v, lanes, successor_start, successors))
    n = int(v[i, T.ROUTE_END]) - first
    if n <= 0:
        return True
    edge = np.empty(n, dtype=np.int64)  # the next continuation to try at each depth
    path = np.empty(n, dtype=np.int64)  # the lane chosen at each depth
    depth, edge[0] = 0, successor_start[lane]
    while True:
        parent = lane if depth == 0 else path[depth - 1]
        wanted = v[i, T.ROUTE + 2 * (first + depth)]
        found = False
        while edge[depth] < successor_start[parent + 1]:
            candidate = successors[edge[depth]]
            edge[depth] += 1
            if lanes[candidate, L.FIRST_OF_ROAD] == wanted:
                path[depth], found = candidate, True
                break
        if found:
            if depth == n - 1:
                return True
            depth += 1
            edge[depth] = successor_start[path[depth - 1]]
        elif depth == 0:
            return False
        else:
            depth -= 1


@njit(cache=True, inline="always")
def _after_road(v: np.ndarray, lanes: np.ndarray, i: int, lane: int) -> int:
    """The first of vehicle i's route entries after the road of ``lane`` (a route's first entry
    is the road the vehicle is on until it is left)."""
    start = int(v[i, T.ROUTE_START])
    if start < v[i, T.ROUTE_END] and v[i, T.ROUTE + 2 * start] == lanes[lane, L.FIRST_OF_ROAD]:
        start += 1
    return start


@njit(cache=True)
def blocks_follow_road(
    v: np.ndarray, lanes: np.ndarray, successor_start: np.ndarray, successors: np.ndarray, i: int
) -> None:
    """At the end of vehicle i's target lane (as ``ControlledVehicle.follow_road``: within half a
    vehicle length of it), target the next lane (see the module docstring); the finished route
    entry is dropped."""
    v, lanes, successor_start, successors = borrowed((v, lanes, successor_start, successors))
    target = int(v[i, T.TARGET_LANE])
    s, _ = L.local_coordinates(lanes, target, v[i, T.X], v[i, T.Y])
    if s <= lanes[target, L.LENGTH] - L.VEHICLE_LENGTH / 2:
        return
    start = _after_road(v, lanes, i, target)
    v[i, T.ROUTE_START] = start
    first, stop = successor_start[target], successor_start[target + 1]
    if stop == first:
        return  # a dead end: the vehicle drives on to the lane's end and leaves
    choice = -1
    if start < v[i, T.ROUTE_END]:
        wanted, named = v[i, T.ROUTE + 2 * start], v[i, T.ROUTE + 2 * start + 1]
        for named_only in (True, False):
            for e in range(first, stop):
                candidate = successors[e]
                if lanes[candidate, L.FIRST_OF_ROAD] != wanted or (
                    named_only and lanes[candidate, L.LANE_ID] != named
                ):
                    continue
                if route_feasible(v, lanes, successor_start, successors, i, candidate, start + 1):
                    choice = candidate
                    break
            if choice >= 0:
                break
    if choice < 0:  # no route left (or off it): the lane's own continuation, else the first
        choice = successors[first]
        for e in range(first, stop):
            if lanes[successors[e], L.LANE_ID] == lanes[target, L.LANE_ID]:
                choice = successors[e]
                break
    v[i, T.TARGET_LANE] = choice


@njit(cache=True)
def rear_across(
    v: np.ndarray, lanes: np.ndarray, coords: np.ndarray, done: np.ndarray, i: int, lane: int,
    successor_start: np.ndarray, successors: np.ndarray,
) -> int:  # fmt: skip
    """The vehicle behind vehicle i on ``lane`` (``traffic.cached_neighbours``' rear), else the one
    nearest the end of a lane that ``lane`` continues (it comes onto ``lane`` next; highway-env's
    neighbour search, which looks at the lane alone, misses it at a road's start), else -1."""
    v, lanes, coords, done, successor_start, successors = borrowed(
        (v, lanes, coords, done, successor_start, successors)
    )
    _, rear = T.cached_neighbours(v, lanes, coords, done, i, lane)
    if rear >= 0:
        return rear
    behind_m = np.inf
    for r in range(lanes.shape[0]):
        for e in range(successor_start[r], successor_start[r + 1]):
            if successors[e] != lane:
                continue
            T.lane_coordinates(v, lanes, coords, done, r)
            for rank in range(done[r] - 1, -1, -1):  # the farthest along the lane first
                j = int(coords[r, rank, 3])
                if j != i:
                    if lanes[r, L.LENGTH] - coords[r, j, 0] < behind_m:
                        rear, behind_m = j, lanes[r, L.LENGTH] - coords[r, j, 0]
                    break
    return rear


@njit(cache=True)
def blocks_mobil(
    v: np.ndarray, lanes: np.ndarray, p: np.ndarray, coords: np.ndarray, done: np.ndarray,
    trig: np.ndarray, i: int, lane: int, successor_start: np.ndarray, successors: np.ndarray,
) -> bool:  # fmt: skip
    """highway-env's ``IDMVehicle.mobil`` (``traffic.mobil_side``) without its planned-lane branch
    (the route is checked by ``route_feasible``); the new follower may come from the lane before
    ``lane`` (``rear_across``)."""
    v, lanes, p, coords, done, trig, successor_start, successors = borrowed(
        (v, lanes, p, coords, done, trig, successor_start, successors)
    )
    new_preceding, _ = T.cached_neighbours(v, lanes, coords, done, i, lane)
    new_following = rear_across(v, lanes, coords, done, i, lane, successor_start, successors)
    new_following_a = T.cached_idm_acceleration(
        v, lanes, p, coords, done, trig, i, new_following, new_preceding
    )
    new_following_pred_a = T.cached_idm_acceleration(v, lanes, p, coords, done, trig, i, new_following, i)
    if new_following_pred_a < -p[T.MAX_BRAKING_IMPOSED]:
        return False
    old_preceding, old_following = T.cached_neighbours(v, lanes, coords, done, i, int(v[i, T.LANE]))
    self_pred_a = T.cached_idm_acceleration(v, lanes, p, coords, done, trig, i, i, new_preceding)
    self_a = T.cached_idm_acceleration(v, lanes, p, coords, done, trig, i, i, old_preceding)
    old_following_a = T.cached_idm_acceleration(v, lanes, p, coords, done, trig, i, old_following, i)
    old_following_pred_a = T.cached_idm_acceleration(
        v, lanes, p, coords, done, trig, i, old_following, old_preceding
    )
    jerk = (
        self_pred_a
        - self_a
        + p[T.POLITENESS] * (new_following_pred_a - new_following_a + old_following_pred_a - old_following_a)
    )
    return jerk >= p[T.MIN_ACC_GAIN]


@njit(cache=True)
def merge_safe(
    v: np.ndarray, lanes: np.ndarray, p: np.ndarray, coords: np.ndarray, done: np.ndarray,
    trig: np.ndarray, i: int, lane: int, successor_start: np.ndarray, successors: np.ndarray,
) -> bool:  # fmt: skip
    """MOBIL's safety criterion for a mandatory change to ``lane`` (``traffic.mobil_side``'s branch
    for a lane the route asks for), the new follower as ``blocks_mobil`` finds it."""
    v, lanes, p, coords, done, trig, successor_start, successors = borrowed(
        (v, lanes, p, coords, done, trig, successor_start, successors)
    )
    new_preceding, _ = T.cached_neighbours(v, lanes, coords, done, i, lane)
    new_following = rear_across(v, lanes, coords, done, i, lane, successor_start, successors)
    new_following_pred_a = T.cached_idm_acceleration(v, lanes, p, coords, done, trig, i, new_following, i)
    if new_following_pred_a < -p[T.MAX_BRAKING_IMPOSED]:
        return False
    self_pred_a = T.cached_idm_acceleration(v, lanes, p, coords, done, trig, i, i, new_preceding)
    return not self_pred_a < -p[T.MAX_BRAKING_IMPOSED]


@njit(cache=True, inline="always")
def _side_lane(v: np.ndarray, lanes: np.ndarray, i: int, lane: int, side: int, changeable: np.ndarray) -> int:
    """The lane beside ``lane`` on ``side`` (-1 left, +1 right) when vehicle i may change to it
    (changeable and reachable), else -1."""
    lane_id, count = lanes[lane, L.LANE_ID], lanes[lane, L.LANE_COUNT]
    if not (0 <= lane_id + side < count):
        return -1
    candidate = lane + side
    if not changeable[candidate] or not L.is_reachable_from(lanes, candidate, v[i, T.X], v[i, T.Y]):
        return -1
    return candidate


@njit(cache=True, inline="always")
def _route_goes_on(
    v: np.ndarray, lanes: np.ndarray, i: int, lane: int, successor_start: np.ndarray, successors: np.ndarray
) -> bool:
    """Vehicle i's route can be driven on from ``lane`` (``route_feasible`` after its road)."""
    first = _after_road(v, lanes, i, lane)
    return route_feasible(v, lanes, successor_start, successors, i, lane, first)


@njit(cache=True)
def blocks_change_lane_policy(
    v: np.ndarray, lanes: np.ndarray, p: np.ndarray, coords: np.ndarray, done: np.ndarray,
    trig: np.ndarray, i: int, changeable: np.ndarray, ending: np.ndarray, successor_start: np.ndarray,
    successors: np.ndarray,
) -> None:  # fmt: skip
    """``IDMVehicle.change_lane_policy`` (``traffic.change_lane_policy``: abort a change into a lane
    someone else is entering; every LANE_CHANGE_DELAY seconds ask MOBIL about each side lane, the
    right one last) on ``changeable`` lanes, to side lanes from which the route goes on."""
    v, lanes, p, coords, done, trig, changeable, ending, successor_start, successors = borrowed(
        (v, lanes, p, coords, done, trig, changeable, ending, successor_start, successors)
    )
    lane, target = int(v[i, T.LANE]), int(v[i, T.TARGET_LANE])
    if lane != target:
        T.abort_change(v, lanes, p, coords, done, trig, i, lane, target)
        return
    if ending[lane]:  # a mandatory change, looked for every frame
        for side in (-1, 1):
            candidate = _side_lane(v, lanes, i, lane, side, changeable)
            if (
                candidate >= 0
                and not ending[candidate]
                and merge_safe(v, lanes, p, coords, done, trig, i, candidate, successor_start, successors)
                and _route_goes_on(v, lanes, i, candidate, successor_start, successors)
            ):
                v[i, T.TARGET_LANE] = candidate
                return
        return
    if not p[T.LANE_CHANGE_DELAY] < v[i, T.TIMER]:
        return
    v[i, T.TIMER] = 0.0
    if not changeable[lane] or np.abs(v[i, T.SPEED]) < 1:
        return
    for side in (-1, 1):
        candidate = _side_lane(v, lanes, i, lane, side, changeable)
        if (
            candidate >= 0
            and blocks_mobil(v, lanes, p, coords, done, trig, i, candidate, successor_start, successors)
            and _route_goes_on(v, lanes, i, candidate, successor_start, successors)
        ):
            v[i, T.TARGET_LANE] = candidate


@njit(cache=True)
def blocks_act(
    v, lanes, p, coords, done, trig, junction, from_arm, to_arm, turn, end_junction, end_arm, light,
    changeable, ending, successor_start, successors, light_states,
) -> None:  # fmt: skip
    """``traffic.act`` with the procedural maps' traffic rules (see the module docstring)."""
    v, lanes, p, coords, done, trig, changeable, ending, successor_start, successors = borrowed(
        (v, lanes, p, coords, done, trig, changeable, ending, successor_start, successors)
    )  # no reference counts in the inlined helpers (``borrow``)
    junction, from_arm, to_arm, turn, end_junction, end_arm, light, light_states = borrowed(
        (junction, from_arm, to_arm, turn, end_junction, end_arm, light, light_states)
    )
    T.start_frame(v, done, trig)
    not_seen = np.zeros((0, 0), dtype=np.int8)  # town_acceleration's lane_s flags: no leader, none read
    for i in range(v.shape[0]):
        kind = v[i, T.KIND]
        if kind == T.PLAIN or kind == T.PEDAL_KIND or kind == T.OBSTACLE:
            continue
        if kind == T.IDM and v[i, T.CRASHED] > 0:
            continue
        if kind == T.CONTROLLED:
            T.follow_road(v, lanes, i)
            v[i, T.STEER] = T.steering_control(v, lanes, i, int(v[i, T.TARGET_LANE]))
            v[i, T.ACCEL] = T.KP_A * (v[i, T.TARGET_SPEED] - v[i, T.SPEED])
            continue
        blocks_follow_road(v, lanes, successor_start, successors, i)
        blocks_change_lane_policy(
            v, lanes, p, coords, done, trig, i, changeable, ending, successor_start, successors
        )
        v[i, T.STEER] = T.steering_control(v, lanes, i, int(v[i, T.TARGET_LANE]))
        front, _ = T.cached_neighbours(v, lanes, coords, done, i, int(v[i, T.LANE]))
        acceleration = T.cached_idm_acceleration(v, lanes, p, coords, done, trig, i, i, front)
        if int(v[i, T.LANE]) != int(v[i, T.TARGET_LANE]):
            front, _ = T.cached_neighbours(v, lanes, coords, done, i, int(v[i, T.TARGET_LANE]))
            target_a = T.cached_idm_acceleration(v, lanes, p, coords, done, trig, i, i, front)
            acceleration = min(acceleration, target_a)
        lane = int(v[i, T.LANE])
        if ending[lane] and lane == int(v[i, T.TARGET_LANE]):  # no gap to merge into yet
            s, _ = L.local_coordinates(lanes, lane, v[i, T.X], v[i, T.Y])
            acceleration = min(acceleration, stop_ahead(v, p, i, lanes[lane, L.LENGTH] - s - v[i, T.LEN] / 2))
        if light[lane] >= 0:  # the town's stop line (with no leader: IDM's free term)
            acceleration = min(
                acceleration,
                town_acceleration(
                    v, _NO_PEDESTRIANS, lanes, p, coords, done, trig, not_seen, i, -1, junction, from_arm,
                    to_arm, turn, end_junction, end_arm, light, light_states,
                ),
            )  # fmt: skip
        v[i, T.ACCEL] = T._clip(acceleration, -p[T.ACC_MAX], p[T.ACC_MAX])


@njit(cache=True)
def blocks_simulate(
    v, lanes, p, frames, dt, regulation, release_cap_mps, junction, from_arm, to_arm, turn,
    end_junction, end_arm, light, changeable, ending, successor_start, successors, light_states,
    ego_max_speed_mps,
) -> None:  # fmt: skip
    """``traffic.simulate`` (the road's rules every ``regulation[0]`` frames, at the junctions only, a
    released vehicle cruising at ``release_cap_mps``) with ``blocks_act``; the lights hold their
    ``light_states`` through the step. The ego rows go no faster than ``ego_max_speed_mps``
    (``Vehicle.clip_actions``' rule at MAX_SPEED; MetaDrive's ego tops out at 80 km/h)."""
    v, lanes, p, regulation, changeable, ending, successor_start, successors = borrowed(
        (v, lanes, p, regulation, changeable, ending, successor_start, successors)
    )
    junction, from_arm, to_arm, turn, end_junction, end_arm, light, light_states = borrowed(
        (junction, from_arm, to_arm, turn, end_junction, end_arm, light, light_states)
    )
    coords, done, trig = T.frame_cache(v, lanes)
    for _ in range(frames):
        blocks_act(
            v, lanes, p, coords, done, trig, junction, from_arm, to_arm, turn, end_junction, end_arm,
            light, changeable, ending, successor_start, successors, light_states,
        )  # fmt: skip
        if regulation[0] > 0:
            regulation[1] += 1
            if regulation[1] % regulation[0] == 0:
                T.enforce_road_rules(v, lanes, release_cap_mps, True)
        for i in range(v.shape[0]):
            kind = v[i, T.KIND]
            if kind == T.OBSTACLE:
                continue
            if kind != T.IDM and v[i, T.SPEED] > ego_max_speed_mps:
                v[i, T.ACCEL] = min(v[i, T.ACCEL], 1.0 * (ego_max_speed_mps - v[i, T.SPEED]))
            T.step_vehicle(v, lanes, i, dt)
        T.handle_collisions(v, dt)
