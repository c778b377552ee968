"""The signalised town as a highway-env environment, so that the reference backend runs it.

``TownEnv`` builds a ``drivelab.envs.town`` layout, cycles its traffic lights with the episode's
clock, puts the ego at a random street position with a route to a random stop line elsewhere in
town, and fills the streets with ``TownVehicle``s: IDM/MOBIL drivers that stop for red lights (and
for yellow ones when they can stop comfortably) and wander on random routes.
"""

from __future__ import annotations

import numpy as np
from highway_env import utils
from highway_env.envs.common.abstract import AbstractEnv
from highway_env.road.road import Road
from highway_env.vehicle.behavior import IDMVehicle

from drivelab.envs.town import (
    LAYOUTS,
    LightTimings,
    TownLights,
    approach_of,
    build_network,
    shortest_route,
)
from drivelab.envs.world import LIGHT_GREEN, LIGHT_YELLOW

STOP_MARGIN_M = 1.0  # front bumper to stop line once stopped


class TownVehicle(IDMVehicle):
    """An IDM/MOBIL vehicle that obeys the town's lights and picks a new random route at the end
    of the one it has."""

    def stop_line_ahead(self) -> float | None:
        """Metres from the front bumper to a stop line this vehicle must stop at, else None:
        red lights always (if not past the line), yellow ones when the stop needs no more than
        the comfortable deceleration."""
        road = self.road
        approach = approach_of(self.lane_index) if self.lane_index else None
        if approach is None or not hasattr(road, "lights"):
            return None
        state = road.lights.state(*approach, road.clock())
        if state is None or state == LIGHT_GREEN:
            return None
        ahead_m = self.lane.length - self.lane.local_coordinates(self.position)[0] - self.LENGTH / 2
        if ahead_m < 0:
            return None
        if state == LIGHT_YELLOW and self.speed**2 / (2 * max(ahead_m, 1e-3)) > -self.COMFORT_ACC_MIN:
            return None  # too close to stop: go through on yellow
        return ahead_m

    def acceleration(self, ego_vehicle, front_vehicle=None, rear_vehicle=None) -> float:
        """IDM, plus a stopped virtual leader at the stop line when the light says stop."""
        acceleration = super().acceleration(ego_vehicle, front_vehicle, rear_vehicle)
        if ego_vehicle is not self:
            return acceleration
        ahead_m = self.stop_line_ahead()
        if ahead_m is None:
            return acceleration
        # IDM gaps run centre to centre: put the virtual leader where a desired gap ends at the line
        gap_m = ahead_m - STOP_MARGIN_M + self.DISTANCE_WANTED
        speed = max(self.speed, 0.0)
        ab = -self.COMFORT_ACC_MAX * self.COMFORT_ACC_MIN
        desired_gap = self.DISTANCE_WANTED + speed * self.TIME_WANTED + speed * speed / (2 * np.sqrt(ab))
        target = utils.not_zero(getattr(self, "target_speed", 0.0))
        stop = self.COMFORT_ACC_MAX * (1 - (speed / abs(target)) ** self.DELTA)
        stop -= self.COMFORT_ACC_MAX * (desired_gap / utils.not_zero(gap_m)) ** 2
        return min(acceleration, stop)

    def follow_road(self) -> None:
        if not self.route or len(self.route) <= 1:  # the route (from the lane it steers to) ran out
            self.route = random_route(self.road, self.target_lane_index)
        super().follow_road()


def street_lanes(network) -> list[tuple]:
    """Lane indices of the streets (they end at stop lines)."""
    return [(f, t, 0) for f, to in network.graph.items() for t in to if ":ir" in t]


def random_route(road: Road, start: tuple) -> list[tuple]:
    """A shortest route from lane ``start`` to a random stop line of another street."""
    goals = [lane[1] for lane in street_lanes(road.network) if lane[1] != start[1]]
    for _ in range(10):
        route = shortest_route(road.network, start[:2], goals[road.np_random.integers(len(goals))])
        if route:
            return route
    return [start]


FIXED_ROUTE_COUNT = 25


def fixed_routes(network) -> list[tuple[tuple, str]]:
    """The town's evaluation routes: 25 (start street, target stop line) pairs drawn once from a
    generator seeded 0, the same for every agent, run and seed (NoCrash evaluates fixed routes)."""
    rng = np.random.default_rng(0)
    streets = street_lanes(network)
    routes = []
    while len(routes) < FIXED_ROUTE_COUNT:
        start, goal = streets[rng.integers(len(streets))], streets[rng.integers(len(streets))][1]
        if goal != start[1] and shortest_route(network, start[:2], goal):
            routes.append((start, goal))
    return routes


class TownEnv(AbstractEnv):
    """highway-env environment of the town (drivelab reads it through its highway backend)."""

    @classmethod
    def default_config(cls) -> dict:
        config = super().default_config()
        config.update(
            {
                "observation": {"type": "Kinematics"},
                "action": {"type": "DiscreteMetaAction", "target_speeds": [0, 4.5, 9]},
                "layout": "train",
                "vehicles_count": 15,
                "light_timings": {"green_s": 10.0, "yellow_s": 3.0, "all_red_s": 1.0},
                "simulation_frequency": 10,  # RLAD runs CARLA at 10 FPS
                "policy_frequency": 5,  # and repeats each action twice
                "duration": 60,
                "ego_start_speed": 0.0,
                # training: a new random target each time one is reached (the episode goes on);
                # evaluation sets it False, and "fixed_routes": True draws from the town's list
                "retarget": False,
                "fixed_routes": False,
            }
        )
        return config

    def _reset(self) -> None:
        layout = LAYOUTS[self.config["layout"]]
        self.road = Road(network=build_network(layout), np_random=self.np_random, record_history=False)
        timings = LightTimings(**self.config["light_timings"])
        offsets = self.np_random.uniform(0.0, timings.cycle_s, size=len(layout.junctions))
        self.road.lights = TownLights(layout, timings, offsets)
        self.road.clock = lambda: self.time
        self._make_vehicles()

    def _make_vehicles(self) -> None:
        road, rng = self.road, self.np_random
        streets = street_lanes(road.network)
        if self.config["fixed_routes"]:
            start, goal = fixed_routes(road.network)[int(rng.integers(FIXED_ROUTE_COUNT))]
            self.ego_route = shortest_route(road.network, start[:2], goal)
        else:
            start = streets[rng.integers(len(streets))]
            self.ego_route = random_route(road, start)
        lane = road.network.get_lane(start)
        longitudinal = rng.uniform(5.0, max(lane.length - 20.0, 5.0))
        ego = self.action_type.vehicle_class(
            road,
            lane.position(longitudinal, 0.0),
            lane.heading_at(longitudinal),
            self.config["ego_start_speed"],
        )
        if hasattr(ego, "route"):  # a meta-action ego follows the planned route itself
            ego.route = list(self.ego_route)
        road.vehicles.append(ego)
        self.vehicle = ego
        self.controlled_vehicles = [ego]
        for _ in range(self.config["vehicles_count"]):
            for _ in range(10):  # a few tries at a free spot
                index = streets[rng.integers(len(streets))]
                lane = road.network.get_lane(index)
                position = lane.position(rng.uniform(5.0, lane.length - 5.0), 0.0)
                if min(np.linalg.norm(v.position - position) for v in road.vehicles) > 12.0:
                    break
            else:
                continue
            s = lane.local_coordinates(position)[0]
            vehicle = TownVehicle(road, position, lane.heading_at(s), speed=rng.uniform(4.0, 8.0))
            vehicle.target_lane_index, vehicle.target_speed = index, lane.speed_limit
            vehicle.route = random_route(road, index)
            vehicle.randomize_behavior()
            road.vehicles.append(vehicle)

    def extend_route(self) -> list[tuple]:
        """A new random target from the end of the ego's route: the lanes to append to it."""
        more = random_route(self.road, self.ego_route[-1])[1:]
        self.ego_route = self.ego_route + more
        if hasattr(self.vehicle, "route"):
            self.vehicle.route = (self.vehicle.route or []) + list(more)
        return more

    def _reward(self, action) -> float:
        return 0.0  # drivelab's reward shapers score the town

    def _is_terminated(self) -> bool:
        return self.vehicle.crashed

    def _is_truncated(self) -> bool:
        return self.time >= self.config["duration"]
