"""Affordances: a few privileged numbers about what lies on the ego's route, measured exactly from
the world (after Conditional Affordance Learning, Sauer et al., CoRL 2018): what ``--algo expert``
drives on, and a privileged baseline for learners.
"""

from __future__ import annotations

import numpy as np
from gymnasium import spaces
from numba import njit

from drivelab.perception.base import Sensor, ego_frame
from drivelab.world.batch import EgoBatch, WorldBatch
from drivelab.world.state import LIGHT_RED, LIGHT_YELLOW

FIELDS = (
    "speed_mps",  # the ego's speed
    "stop_line_m",  # to the stop line of the next traffic light ahead in the ego's lane
    "light_red",  # 1 when that light is red
    "light_yellow",  # 1 when that light is yellow
    "leader_m",  # along the route, to the nearest vehicle on it
    "leader_speed_mps",  # that vehicle's speed along the ego's heading
    "pedestrian_m",  # along the route, to the nearest pedestrian on, next to or walking onto it
    "oncoming_m",  # a left turn is ahead at that light and an oncoming vehicle comes this close
)
ROUTE_STEP_M = 1.0  # the route ahead is sampled this finely
VEHICLE_CORRIDOR_M = 2.5  # a vehicle whose centre is this close to the route is on it
PEDESTRIAN_CORRIDOR_M = 3.0  # a pedestrian this close to the route is about to be on it
PEDESTRIAN_HEADING_M = 9.0  # so is one walking towards it from this close (across the road)
LEFT_TURN_AHEAD_M, LEFT_TURN_M = 20.0, 6.0  # 20 m past the light the route lies 6 m to the left
ONCOMING_COS = -0.7  # heading opposite the ego's within about 45°
ONCOMING_LATERAL_M = 10.0  # the opposite lane (4 m to the left) with room for the ego's heading error


class Affordances(Sensor):
    """``FIELDS`` as float32; a distance with nothing found reads ``range_m``. K worlds at once:
    every body against every route point of its world, ``(K, N, S)``, with no loop over worlds.

    :param range_m: how far along the route to look.
    """

    name = "affordances"
    help = "privileged: speed, next light and its state, leader, pedestrian, oncoming (m)"

    def __init__(self, *, range_m: float = 40.0) -> None:
        if range_m <= 0:
            raise ValueError("affordances needs range_m > 0")
        self.range_m = float(range_m)
        high = np.full(len(FIELDS), max(self.range_m, 50.0), dtype=np.float32)
        self._space = spaces.Box(-high, high, dtype=np.float32)

    def _observe(self, batch: WorldBatch, out: np.ndarray) -> None:
        ego, route = batch.ego, batch.route
        stations = np.arange(0.0, self.range_m + ROUTE_STEP_M, ROUTE_STEP_M)  # (S,)
        path, _ = route.poses_at(route.progress_m[:, None] + stations)  # (K, S, 2)
        state, stop_line_m = batch.light_ahead(self.range_m)  # (K,): state -1 where there is none
        has_light = state >= 0
        leader_found, leader_m, leader = _nearest_on_route(
            batch.vehicles, batch.vehicle_valid, path, stations, ego, VEHICLE_CORRIDOR_M
        )
        walker_found, walker_m, _ = _nearest_on_route(
            batch.pedestrians, batch.pedestrian_valid, path, stations, ego, PEDESTRIAN_CORRIDOR_M,
            PEDESTRIAN_HEADING_M,
        )  # fmt: skip
        leader_speed_mps = leader[:, 3] * np.cos(leader[:, 2] - ego.heading)  # along the ego's heading
        turning = has_light & _turns_left_after(batch, np.where(has_light, stop_line_m, 0.0))
        values = {
            "speed_mps": ego.speed_mps,
            "stop_line_m": np.where(has_light, stop_line_m, self.range_m),
            "light_red": (state == LIGHT_RED).astype(float),
            "light_yellow": (state == LIGHT_YELLOW).astype(float),
            "leader_m": np.where(leader_found, leader_m, self.range_m),
            "leader_speed_mps": np.where(leader_found, leader_speed_mps, 0.0),
            "pedestrian_m": np.where(walker_found, walker_m, self.range_m),
            "oncoming_m": np.where(turning, self._oncoming(batch), self.range_m),
        }
        out[...] = np.stack([values[field] for field in FIELDS], axis=1)  # (K, fields)

    def _oncoming(self, batch: WorldBatch) -> np.ndarray:
        """(K,) distance to the nearest moving vehicle ahead that drives against the ego in the
        opposite lane (left of it, within ``ONCOMING_LATERAL_M``: not on a parallel street), at
        most ``range_m``."""
        vehicles, ego = batch.vehicles, batch.ego  # vehicles (K, N, 6)
        local = ego_frame(vehicles[..., :2], ego.position[:, None], ego.heading[:, None])  # (K, N, 2)
        against = np.cos(vehicles[..., 2] - ego.heading[:, None]) < ONCOMING_COS
        moving = vehicles[..., 3] > 0.5
        ahead = (local[..., 0] > 0) & (local[..., 0] < self.range_m)
        left = (local[..., 1] < 0) & (local[..., 1] > -ONCOMING_LATERAL_M)
        found = batch.vehicle_valid & against & moving & ahead & left
        distance = np.where(found, np.hypot(local[..., 0], local[..., 1]), np.inf)
        return np.minimum(np.min(distance, axis=1, initial=np.inf), self.range_m)


def _nearest_on_route(
    bodies: np.ndarray,
    valid: np.ndarray,
    path: np.ndarray,
    stations: np.ndarray,
    ego: EgoBatch,
    corridor_m: float,
    heading_for_m: float = 0.0,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per world, the nearest body ahead of the ego within ``corridor_m`` of the route, or within
    ``heading_for_m`` and moving towards it: (K,) found, (K,) its distance along the route and
    (K, 6) its row (meaningful where found).

    :param bodies: (K, N, 6) rows with their (K, N) ``valid`` mask.
    :param path: (K, S, 2) route points at the (S,) arc lengths ``stations`` ahead of the ego.
    """
    count, size = bodies.shape[:2]
    if size == 0:
        return np.zeros(count, dtype=bool), np.zeros(count), np.zeros((count, 6))
    gap, nearest = _route_gaps(bodies, path)  # (K, N) each body's nearest route point
    worlds = np.arange(count)[:, None]
    velocity = bodies[..., 3:4] * np.stack([np.cos(bodies[..., 2]), np.sin(bodies[..., 2])], axis=-1)
    to_route = path[worlds, nearest] - bodies[..., :2]
    towards = velocity[..., 0] * to_route[..., 0] + velocity[..., 1] * to_route[..., 1] > 0
    ahead = ego_frame(bodies[..., :2], ego.position[:, None], ego.heading[:, None])[..., 0] > 0
    on = valid & ahead & ((gap < corridor_m) | (towards & (gap < heading_for_m)))
    along = np.where(on, stations[nearest], np.inf)
    best = np.argmin(along, axis=1)  # the first of the nearest, as a search of one world's rows
    found = on.any(axis=1)
    return found, along[worlds[:, 0], best], bodies[worlds[:, 0], best]


@njit(cache=True)
def _route_gaps(bodies, path):
    """(K, N) the distance from each body to the nearest of its world's route points ``path``
    (K, S, 2) and that point's index, the first on ties (a nan distance wins, as argmin has it).
    Each distance is numpy's norm of the difference, sqrt(dx·dx + dy·dy), without the (K, N, S)
    array of them all."""
    count, size, points = bodies.shape[0], bodies.shape[1], path.shape[1]
    gap, nearest = np.empty((count, size)), np.zeros((count, size), dtype=np.int64)
    for k in range(count):
        for n in range(size):
            best, index = np.inf, 0
            for s in range(points):
                dx, dy = bodies[k, n, 0] - path[k, s, 0], bodies[k, n, 1] - path[k, s, 1]
                distance = np.sqrt(dx * dx + dy * dy)
                if distance != distance:  # nan: argmin's pick, whatever follows
                    best, index = distance, s
                    break
                if distance < best:
                    best, index = distance, s
            gap[k, n], nearest[k, n] = best, index
    return gap, nearest


def _turns_left_after(batch: WorldBatch, distance_m: np.ndarray) -> np.ndarray:
    """(K,) the route bends left past the point ``distance_m`` (K,) ahead: 20 m further on it lies
    more than 6 m to the left of where it was heading."""
    route = batch.route
    ahead = route.progress_m[:, None] + np.stack([distance_m, distance_m + LEFT_TURN_AHEAD_M], axis=1)
    points, headings = route.poses_at(ahead)  # (K, 2, 2), (K, 2)
    lateral = ego_frame(points[:, 1], points[:, 0], headings[:, 0])[:, 1]
    return lateral < -LEFT_TURN_M
