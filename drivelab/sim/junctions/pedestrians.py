"""The town's traffic lights, pedestrians, pedestrian hits and wreck towing as compiled loops over
ONE world's arrays, each the reference method (``scenarios.town.reference_env``,
``junctions.rules``) in its order and scalar arithmetic:

- ``light_states``: ``rules.light_state`` of every light row;
- ``walk_pedestrians``: ``Pedestrian.walk`` (and ``_gap_clear``) of every pedestrian in spawn order;
- ``hit_pedestrians``: ``TownRoad._hit_pedestrians`` (highway-env's ``_is_colliding`` box test);
- ``clear_wrecks``: ``TownRoad._clear_wrecks`` (crashed NPC rows towed, the rows closing up).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from drivelab.sim.core import traffic as T
from drivelab.sim.core.borrow import borrowed
from drivelab.sim.core.pcg64 import standard_exponential_inv
from drivelab.sim.junctions import rows as R
from drivelab.sim.junctions.rules import (
    COURTESY_M,
    CROSSING_CLEAR_M,
    CROSSING_GAP_M,
    CROSSING_GAP_S,
    FACING_COS,
    MEAN_WAIT_S,
    MOVING_MPS,
    PAVEMENT_M,
    PEDESTRIAN_SIZE_M,
    WRECK_CLEARED_S,
)
from drivelab.world.state import LIGHT_GREEN, LIGHT_RED, LIGHT_YELLOW

PEDESTRIAN_DIAGONAL_M = np.sqrt(PEDESTRIAN_SIZE_M**2 + PEDESTRIAN_SIZE_M**2)  # RoadObject.diagonal


@njit(cache=True)
def light_states(
    light_junction, light_arm, offsets, green_s: float, yellow_s: float, all_red_s: float, time_s: float, out
) -> None:  # fmt: skip
    """``out[m]`` = ``light_state(timings, light_arm[m], time_s, offsets[light_junction[m]])``
    (LIGHT_GREEN / YELLOW / RED) for every light row m. ``light_junction``, ``light_arm``, ``out``:
    (M,); ``offsets``: (J,), the world's cycle offsets of every junction. Python's float ``%``
    (the result takes the divisor's sign), as the reference."""
    half = green_s + yellow_s + all_red_s
    cycle = 2 * (green_s + yellow_s + all_red_s)
    for m in range(light_arm.shape[0]):
        phase = (time_s - offsets[light_junction[m]]) % cycle
        if light_arm[m] % 2 == 1:
            phase = (phase - half) % cycle
        if phase < green_s:
            out[m] = LIGHT_GREEN
        elif phase < green_s + yellow_s:
            out[m] = LIGHT_YELLOW
        else:
            out[m] = LIGHT_RED


@njit(cache=True)
def light_states_worlds(light_junction, light_arm, start, stop, offsets, timings, time_s, active, out):
    """``light_states`` of world k's lights (rows ``start[k]:stop[k]`` of ``light_junction`` /
    ``light_arm``) with its offsets ``offsets[k]`` (K, J) at ``time_s[k]``, into ``out[k]`` (K, M),
    for the worlds of ``active``; ``timings``: (green, yellow, all red) seconds."""
    for k in range(out.shape[0]):
        if active[k]:
            a, b = start[k], stop[k]
            light_states(
                light_junction[a:b], light_arm[a:b], offsets[k], timings[0], timings[1], timings[2],
                time_s[k], out[k, : b - a],
            )  # fmt: skip


@njit(cache=True)
def gap_clear(peds: np.ndarray, i: int, v: np.ndarray, count: int) -> bool:
    """``Pedestrian._gap_clear`` of pedestrian ``i`` over vehicle rows 0..count-1 (ego included):
    no vehicle within CROSSING_CLEAR_M of the crossing's centre, none facing it within
    CROSSING_GAP_M + CROSSING_GAP_S·speed, nor within COURTESY_M."""
    peds, v = borrowed((peds, v))
    cx, cy = peds[i, R.P_CENTRE_X], peds[i, R.P_CENTRE_Y]
    for j in range(count):
        dx, dy = cx - v[j, T.X], cy - v[j, T.Y]
        distance = np.sqrt(dx * dx + dy * dy)
        if distance < CROSSING_CLEAR_M:
            return False
        facing = np.cos(v[j, T.HEADING]) * dx + np.sin(v[j, T.HEADING]) * dy > FACING_COS * distance
        if facing and distance < CROSSING_GAP_M + CROSSING_GAP_S * max(v[j, T.SPEED], 0.0):
            return False
        if facing and distance < COURTESY_M:
            return False
    return True


@njit(cache=True)
def walk_pedestrians(
    peds: np.ndarray, pcount: int, v: np.ndarray, count: int, dt: float, rng_words: np.ndarray
) -> None:
    """``Pedestrian.walk(dt, road.vehicles)`` of pedestrian rows 0..pcount-1 in order, the waits
    drawn from the world's generator ``rng_words`` (6,) in pedestrian order, as the reference."""
    peds, v, rng_words = borrowed((peds, v, rng_words))
    for i in range(pcount):
        if peds[i, R.P_CRASHED] != 0.0:
            peds[i, R.P_SPEED] = 0.0
            continue
        side = peds[i, R.P_SIDE]
        if peds[i, R.P_SPEED] == 0.0:
            peds[i, R.P_WAIT_S] -= dt
            if peds[i, R.P_WAIT_S] <= 0.0 and gap_clear(peds, i, v, count):
                peds[i, R.P_HEADING] = np.arctan2(
                    -side * peds[i, R.P_ACROSS_Y], -side * peds[i, R.P_ACROSS_X]
                )
                peds[i, R.P_SPEED] = peds[i, R.P_PACE]
            continue
        step = peds[i, R.P_SPEED] * dt
        peds[i, R.P_X] = peds[i, R.P_X] + step * np.cos(peds[i, R.P_HEADING])
        peds[i, R.P_Y] = peds[i, R.P_Y] + step * np.sin(peds[i, R.P_HEADING])
        dx, dy = peds[i, R.P_X] - peds[i, R.P_CENTRE_X], peds[i, R.P_Y] - peds[i, R.P_CENTRE_Y]
        if -side * (dx * peds[i, R.P_ACROSS_X] + dy * peds[i, R.P_ACROSS_Y]) >= PAVEMENT_M:
            peds[i, R.P_SIDE], peds[i, R.P_SPEED] = -side, 0.0
            peds[i, R.P_WAIT_S] = MEAN_WAIT_S * standard_exponential_inv(rng_words)


@njit(cache=True)
def _pedestrian_polygon(peds: np.ndarray, i: int) -> np.ndarray:
    """RoadObject.polygon of a pedestrian: its PEDESTRIAN_SIZE_M square, closed (5, 2)."""
    c, s = np.cos(peds[i, R.P_HEADING]), np.sin(peds[i, R.P_HEADING])
    corners = np.empty((5, 2))
    half = PEDESTRIAN_SIZE_M / 2
    local = ((-half, -half), (-half, half), (half, half), (half, -half))
    for k in range(4):
        px, py = local[k]
        corners[k, 0] = c * px + -s * py + peds[i, R.P_X]
        corners[k, 1] = s * px + c * py + peds[i, R.P_Y]
    corners[4, 0], corners[4, 1] = corners[0, 0], corners[0, 1]  # element-wise (see traffic._polygon_into)
    return corners


@njit(cache=True)
def hit_pedestrians(peds: np.ndarray, pcount: int, v: np.ndarray, count: int, ego: int) -> None:
    """``TownRoad._hit_pedestrians``: every pair (pedestrian not crashed, vehicle faster than
    MOVING_MPS), pedestrian-major, closer than (pedestrian diagonal + the largest moving diagonal)/2
    gets highway-env's ``vehicle._is_colliding(pedestrian, 0)`` (its sphere check, then the exact
    box test); a hit marks both crashed, and the pedestrian HIT_EGO when the vehicle is row ``ego``.
    A pedestrian hit once is skipped for the later vehicles."""
    peds, v = borrowed((peds, v))
    reach_vehicle = -1.0
    for j in range(count):
        if v[j, T.SPEED] > MOVING_MPS:
            reach_vehicle = max(reach_vehicle, np.sqrt(v[j, T.LEN] ** 2 + v[j, T.WID] ** 2))
    if reach_vehicle < 0.0:
        return  # no moving vehicle
    reach = (PEDESTRIAN_DIAGONAL_M + reach_vehicle) / 2
    for i in range(pcount):
        if peds[i, R.P_CRASHED] != 0.0:
            continue
        for j in range(count):
            if v[j, T.SPEED] <= MOVING_MPS:
                continue
            dx, dy = peds[i, R.P_X] - v[j, T.X], peds[i, R.P_Y] - v[j, T.Y]
            gap = np.sqrt(dx * dx + dy * dy)
            if not gap < reach or peds[i, R.P_CRASHED] != 0.0:
                continue
            diagonal = np.sqrt(v[j, T.LEN] ** 2 + v[j, T.WID] ** 2)
            if gap > (diagonal + PEDESTRIAN_DIAGONAL_M) / 2 + v[j, T.SPEED] * 0.0:
                continue  # _is_colliding's own sphere check
            if T.polygons_intersecting(T._polygon(v, j), _pedestrian_polygon(peds, i), 0.0, 0.0, 0.0, 0.0)[0]:
                v[j, T.CRASHED], peds[i, R.P_CRASHED] = 1.0, 1.0
                peds[i, R.P_HIT_EGO] = 1.0 if j == ego else 0.0


@njit(cache=True)
def clear_wrecks(v: np.ndarray, count: int, ego: int, dt: float) -> tuple[int, int]:
    """``TownRoad._clear_wrecks``: every crashed row but the ego's adds ``dt`` to WRECKED_S (the
    reference's float sum) and is removed once WRECKED_S >= WRECK_CLEARED_S; kept rows close up in
    order, freed rows become zeros. Returns the new (count, ego row)."""
    (v,) = borrowed((v,))
    kept, new_ego = 0, ego
    for j in range(count):
        if j != ego and v[j, T.CRASHED] != 0.0:
            v[j, T.WRECKED_S] = v[j, T.WRECKED_S] + dt
            if v[j, T.WRECKED_S] >= WRECK_CLEARED_S:
                continue
        if j == ego:
            new_ego = kept
        if kept != j:
            for column in range(v.shape[1]):  # element-wise (see traffic._polygon_into)
                v[kept, column] = v[j, column]
        kept += 1
    v[kept:count] = 0.0
    return kept, new_ego
