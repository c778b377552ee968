"""Affordances: a few privileged numbers about what lies on the ego's route, read from the world.

In the spirit of Conditional Affordance Learning (Sauer et al., CoRL 2018): instead of pixels, the
distances a rule-based driver needs, measured exactly. ``--algo expert`` drives on them; a learner
may use them as a privileged baseline (an upper bound on what perception could give it).
"""

from __future__ import annotations

import numpy as np
from gymnasium import spaces

from drivelab.perception.base import Sensor, ego_frame
from drivelab.world.state import LIGHT_RED, LIGHT_YELLOW, WorldState

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
    """``FIELDS`` as float32; a distance with nothing found reads ``range_m``.

    :param range_m: how far along the route to look.
    """

    name = "affordances"

    def __init__(self, *, range_m: float = 40.0) -> None:
        if range_m <= 0:
            raise ValueError("affordances needs range_m > 0")
        self.range_m = float(range_m)
        high = np.full(len(FIELDS), max(self.range_m, 50.0), dtype=np.float32)
        self._space = spaces.Box(-high, high, dtype=np.float32)

    @property
    def space(self) -> spaces.Box:
        return self._space

    def observe(self, world: WorldState) -> np.ndarray:
        ego, route = world.ego, world.route
        stations = np.arange(0.0, self.range_m + ROUTE_STEP_M, ROUTE_STEP_M)
        path, _ = route.poses_at(route.progress_m + stations)
        values = dict.fromkeys(FIELDS, self.range_m)
        values["speed_mps"], values["light_red"], values["light_yellow"] = ego.speed_mps, 0.0, 0.0
        light = world.light_ahead(self.range_m)
        if light is not None:
            values["stop_line_m"] = light[1]
            values["light_red"] = float(light[0] == LIGHT_RED)
            values["light_yellow"] = float(light[0] == LIGHT_YELLOW)
        leader = self._nearest_on_route(world.vehicles, path, stations, ego, VEHICLE_CORRIDOR_M)
        if leader is not None:
            values["leader_m"] = leader[0]
            row = world.vehicles[leader[1]]
            values["leader_speed_mps"] = row[3] * float(np.cos(row[2] - ego.heading))
        else:
            values["leader_speed_mps"] = 0.0
        walker = self._nearest_on_route(
            world.pedestrians, path, stations, ego, PEDESTRIAN_CORRIDOR_M, PEDESTRIAN_HEADING_M
        )
        if walker is not None:
            values["pedestrian_m"] = walker[0]
        if light is not None and self._turns_left_after(world, light[1]):
            values["oncoming_m"] = self._oncoming(world)
        return np.array([values[f] for f in FIELDS], dtype=np.float32)

    @staticmethod
    def _nearest_on_route(
        bodies, path, stations, ego, corridor_m, heading_for_m=0.0
    ) -> tuple[float, int] | None:
        """(distance along the route, row) of the nearest body ahead of the ego within
        ``corridor_m`` of the route, or within ``heading_for_m`` and moving towards it; None if none."""
        if len(bodies) == 0:
            return None
        gaps = np.linalg.norm(bodies[:, None, :2] - path[None], axis=2)  # (N, S)
        nearest = gaps.argmin(axis=1)
        gap = gaps[np.arange(len(bodies)), nearest]
        velocity = bodies[:, 3:4] * np.column_stack([np.cos(bodies[:, 2]), np.sin(bodies[:, 2])])
        towards = np.einsum("ij,ij->i", velocity, path[nearest] - bodies[:, :2]) > 0
        ahead = ego_frame(bodies[:, :2], ego.position, ego.heading)[:, 0] > 0
        on = ahead & ((gap < corridor_m) | (towards & (gap < heading_for_m)))
        if not on.any():
            return None
        rows = np.flatnonzero(on)
        best = rows[np.argmin(stations[nearest[rows]])]
        return float(stations[nearest[best]]), int(best)

    @staticmethod
    def _turns_left_after(world: WorldState, distance_m: float) -> bool:
        """The route bends left past the point ``distance_m`` ahead: 20 m further on it lies more
        than 6 m to the left of where it was heading."""
        route = world.route
        points, headings = route.poses_at(
            route.progress_m + np.array([distance_m, distance_m + LEFT_TURN_AHEAD_M])
        )
        lateral = ego_frame(points[1:], points[0], float(headings[0]))[0, 1]
        return bool(lateral < -LEFT_TURN_M)

    def _oncoming(self, world: WorldState) -> float:
        """Distance to the nearest moving vehicle ahead that drives against the ego in the opposite
        lane (left of it, within ``ONCOMING_LATERAL_M``: not on a parallel street), at most ``range_m``."""
        vehicles, ego = world.vehicles, world.ego
        if len(vehicles) == 0:
            return self.range_m
        local = ego_frame(vehicles[:, :2], ego.position, ego.heading)
        against = np.cos(vehicles[:, 2] - ego.heading) < ONCOMING_COS
        moving = vehicles[:, 3] > 0.5
        ahead = (local[:, 0] > 0) & (local[:, 0] < self.range_m)
        left = (local[:, 1] < 0) & (local[:, 1] > -ONCOMING_LATERAL_M)
        found = against & moving & ahead & left
        return min(float(np.hypot(*local[found].T).min()), self.range_m) if found.any() else self.range_m
