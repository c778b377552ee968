"""The fast backend: highway-env builds each episode, drivelab's compiled traffic model runs it.

At reset highway-env lays out the road and places the vehicles exactly as it would itself (same
seed, same scenario code), or, for the highway, drivelab's own spawner draws the same numbers
without building any highway-env object; from then on every step is ``traffic.simulate`` over a
vehicle array (routes, obstacles and the intersection's right-of-way rules included), and the
WorldState is read from that array. The intersection's arrivals and departures between steps are
drawn here from highway-env's own random generator, in highway-env's order.
"""

from __future__ import annotations

import numpy as np
from highway_env import utils as hw_utils
from highway_env.road.regulation import RegulatedRoad
from highway_env.vehicle.behavior import IDMVehicle
from highway_env.vehicle.controller import ControlledVehicle
from highway_env.vehicle.kinematics import Vehicle
from highway_env.vehicle.objects import Obstacle

from drivelab.envs.backends.fast import lanes as L
from drivelab.envs.backends.fast import traffic as T
from drivelab.envs.backends.fast.spawn import IntersectionTraffic, spawn_highway
from drivelab.envs.backends.highway import HighwayBackend, build_road_map
from drivelab.envs.route import RouteTracker
from drivelab.envs.scenarios import SCENARIOS, Scenario
from drivelab.errors import UsageError
from drivelab.world.state import Ego, Events, WorldState

SUPPORTED = tuple(name for name, scenario in SCENARIOS.items() if scenario.fast_backend)
SPAWNERS = {"highway": spawn_highway}
META = ("LANE_LEFT", "IDLE", "LANE_RIGHT", "FASTER", "SLOWER")
ACCELERATION_RANGE, STEERING_RANGE = (-5.0, 5.0), (-np.pi / 4, np.pi / 4)  # ContinuousAction's


def vehicles_to_array(vehicles: list, table: L.LaneTable, objects: list = ()) -> np.ndarray:
    """highway-env vehicles, then its obstacles → rows of ``traffic.VEHICLE_COLUMNS``, in order."""
    row_of = table.row_of
    array = np.zeros((len(vehicles) + len(objects), T.VEHICLE_COLUMNS))
    for i, vehicle in enumerate(vehicles):
        if type(vehicle) is not IDMVehicle and isinstance(vehicle, IDMVehicle):
            raise NotImplementedError(f"the fast backend has no {type(vehicle).__name__}")
        row = array[i]
        row[T.X], row[T.Y] = vehicle.position
        row[T.HEADING], row[T.SPEED] = vehicle.heading, vehicle.speed
        row[T.STEER] = vehicle.action.get("steering", 0.0)
        row[T.ACCEL] = vehicle.action.get("acceleration", 0.0)
        row[T.LANE] = row_of[vehicle.lane_index]
        row[T.TARGET_LANE] = row_of[getattr(vehicle, "target_lane_index", vehicle.lane_index)]
        row[T.TARGET_SPEED] = getattr(vehicle, "target_speed", 0.0)
        row[T.DELTA] = getattr(vehicle, "DELTA", IDMVehicle.DELTA)
        row[T.TIMER] = getattr(vehicle, "timer", 0.0)
        row[T.CRASHED] = float(vehicle.crashed)
        row[T.CHECK_COLLISIONS] = float(vehicle.check_collisions)
        row[T.LEN], row[T.WID] = vehicle.LENGTH, vehicle.WIDTH
        if isinstance(vehicle, IDMVehicle):
            row[T.KIND] = T.IDM
        elif isinstance(vehicle, ControlledVehicle):
            row[T.KIND] = T.CONTROLLED
        elif isinstance(vehicle, Vehicle):
            row[T.KIND] = T.PLAIN
        route = getattr(vehicle, "route", None)
        row[T.ROUTED] = float(route is not None)
        row[T.YIELDING] = float(getattr(vehicle, "is_yielding", False))
        route = route or []
        if len(route) > T.MAX_ROUTE:
            raise NotImplementedError(f"the fast backend keeps routes of at most {T.MAX_ROUTE} roads")
        row[T.ROUTE_END] = len(route)
        for k, (_from, _to, lane_id) in enumerate(route):
            row[T.ROUTE + 2 * k] = table.road_of(_from, _to)
            row[T.ROUTE + 2 * k + 1] = -1 if lane_id is None else lane_id
    for k, obstacle in enumerate(objects, start=len(vehicles)):
        if type(obstacle) is not Obstacle:
            raise NotImplementedError(f"the fast backend has no {type(obstacle).__name__}")
        row = array[k]
        row[T.X], row[T.Y] = obstacle.position
        row[T.HEADING], row[T.SPEED] = obstacle.heading, obstacle.speed
        row[T.LANE] = row[T.TARGET_LANE] = row_of[obstacle.lane_index]
        row[T.CHECK_COLLISIONS] = float(obstacle.check_collisions)
        row[T.LEN], row[T.WID], row[T.KIND] = obstacle.LENGTH, obstacle.WIDTH, T.OBSTACLE
    return array


def idm_parameters() -> np.ndarray:
    """IDMVehicle's class parameters as the kernels read them."""
    return np.array([float(getattr(IDMVehicle, name)) for name in T.IDM_PARAMETERS])


class FastBackend:
    """Same scenarios, same WorldState as HighwayBackend, simulated by compiled array code.

    :param scenario: a scenario in ``SUPPORTED``.
    :param traffic: "empty", "regular" or "dense".
    :param control: "meta" or "continuous".
    :param overrides: extra highway-env config keys.
    """

    def __init__(
        self, scenario: Scenario, traffic: str = "regular", control: str = "meta", overrides=None
    ) -> None:
        if scenario.name not in SUPPORTED:
            raise UsageError(
                f"backend 'fast' does not run scenario {scenario.name!r} yet "
                f"(it runs {', '.join(SUPPORTED)}); use --backend highway"
            )
        self.scenario, self.control = scenario, control
        self.builder = HighwayBackend(scenario, traffic, control, overrides)
        config = self.builder.env.config
        self.frames = int(config["simulation_frequency"] // config["policy_frequency"])
        self.dt_s = 1 / config["simulation_frequency"]

    @property
    def policy_frequency_hz(self) -> float:
        return self.builder.policy_frequency_hz

    @property
    def duration_s(self) -> float:
        return self.builder.duration_s

    def _take_road(self) -> None:
        """Convert the road highway-env just built (lanes, drawing) to arrays. Every scenario's
        road is the same in every episode, so this runs once."""
        network = self.builder.env.road.network
        self.table = L.LaneTable.from_network(network)
        self.lanes = self.table.rows
        self.road_map = build_road_map(network)
        self.graph_keys = {f: list(to) for f, to in network.graph.items()}
        self.routes: dict[int, RouteTracker] = {}

    def reset(self, seed: int) -> WorldState:
        """A new episode from ``seed``: spawned here where drivelab has the scenario's spawner
        (highway), else built by highway-env and taken over as arrays."""
        env = self.builder.env
        if self.scenario.name in SPAWNERS:
            if not hasattr(self, "table"):
                self.builder.reset(0)
                self._take_road()
            speeds = getattr(env.action_type, "target_speeds", None)
            self.vehicles = SPAWNERS[self.scenario.name](
                seed, self.table, self.graph_keys, env.config, self.control, speeds
            )
            self.ego = 0
            self.regulation = np.zeros(2)
        else:
            env.reset(seed=int(seed))
            self.builder.arrange_traffic()
            if not hasattr(self, "table"):
                self._take_road()
            road = env.road
            self.vehicles = vehicles_to_array(road.vehicles, self.table, road.objects)
            self.ego = road.vehicles.index(env.vehicle)
            if isinstance(road, RegulatedRoad):
                if RegulatedRoad.YIELD_DURATION != 0:
                    raise NotImplementedError("the fast backend assumes RegulatedRoad.YIELD_DURATION = 0")
                period = int(1 / self.dt_s / RegulatedRoad.REGULATION_FREQUENCY)
                self.regulation = np.array([period, road.steps], dtype=float)
            else:
                self.regulation = np.zeros(2)
        if self.scenario.name == "intersection":
            self.arrivals = IntersectionTraffic(env, self.table)
        ego_lane = int(self.vehicles[self.ego, T.LANE])
        if ego_lane not in self.routes:
            self.routes[ego_lane] = self.builder.route_for(
                self.builder._plan_route(self.table.indices[ego_lane])
            )
        self.route = self.routes[ego_lane]
        self.target_speeds = np.asarray(getattr(env.action_type, "target_speeds", [0.0]), dtype=float)
        self.idm = idm_parameters()
        self.time_s = 0.0
        self.progress_m = self.route.project(self.vehicles[self.ego, [T.X, T.Y]])
        self.world = self._export()
        return self.world

    def _apply_meta(self, action: int) -> None:
        """MDPVehicle.act for the ego's meta-action (the controls follow in the kernel)."""
        v, e, name = self.vehicles, self.ego, META[int(action)]
        if name in ("FASTER", "SLOWER"):
            speeds = self.target_speeds
            ratio = (v[e, T.SPEED] - speeds[0]) / (speeds[-1] - speeds[0])
            index = int(np.clip(np.round(ratio * (speeds.size - 1)), 0, speeds.size - 1))
            index = int(np.clip(index + (1 if name == "FASTER" else -1), 0, speeds.size - 1))
            v[e, T.TARGET_SPEED] = speeds[index]
            return
        T.follow_road(v, self.lanes, e)
        if name in ("LANE_LEFT", "LANE_RIGHT"):
            target = int(v[e, T.TARGET_LANE])
            first, count = int(self.lanes[target, L.FIRST_OF_ROAD]), int(self.lanes[target, L.LANE_COUNT])
            lane_id = int(self.lanes[target, L.LANE_ID]) + (1 if name == "LANE_RIGHT" else -1)
            candidate = first + int(np.clip(lane_id, 0, count - 1))
            if L.is_reachable_from(self.lanes, candidate, v[e, T.X], v[e, T.Y]):
                v[e, T.TARGET_LANE] = candidate

    def step(self, control: int | np.ndarray) -> WorldState:
        """One policy step: the ego's control, then ``frames`` simulation steps."""
        self.apply_control(control)
        T.simulate(self.vehicles, self.lanes, self.idm, self.frames, self.dt_s, self.regulation)
        return self.after_simulation()

    def apply_control(self, control: int | np.ndarray) -> None:
        """Set the ego's meta-action targets or continuous controls (before simulating)."""
        v, e = self.vehicles, self.ego
        if self.control == "meta":
            self._apply_meta(control)
        else:
            # ContinuousAction.get_action, in the action's own dtype as highway-env computes it
            accel, steer = np.clip(control, -1, 1)
            v[e, T.ACCEL] = hw_utils.lmap(accel, [-1, 1], ACCELERATION_RANGE)
            v[e, T.STEER] = hw_utils.lmap(steer, [-1, 1], STEERING_RANGE)

    def after_simulation(self) -> WorldState:
        """Advance the clock, the traffic's arrivals and departures, the route, and export the new
        WorldState (after simulating)."""
        self.time_s += 1 / self.policy_frequency_hz
        if self.scenario.name == "intersection":  # IntersectionEnv.step: clear, then spawn
            self.vehicles, self.ego = self.arrivals.clear(self.vehicles, self.ego)
            self.vehicles = self.arrivals.spawn(self.vehicles, self.builder.env.config["spawn_probability"])
        self.progress_m = self.route.project(self.vehicles[self.ego, [T.X, T.Y]], self.progress_m)
        self.world = self._export()
        return self.world

    def _arrived(self) -> bool:
        if self.scenario.arrival == "merge_end":
            return bool(self.vehicles[self.ego, T.X] > 370)
        if self.scenario.arrival == "exit":
            return self.arrivals.has_exited(self.vehicles[self.ego], exit_distance_m=25.0)
        return False

    def _export(self) -> WorldState:
        v, e, lanes = self.vehicles, self.ego, self.lanes
        lane = int(v[e, T.LANE])
        x, y = v[e, T.X], v[e, T.Y]
        s, lateral = L.local_coordinates(lanes, lane, x, y)
        heading_back, heading_ahead = L.heading_at(lanes, lane, s - 1.0), L.heading_at(lanes, lane, s + 1.0)
        on_road = L.on_lane(lanes, lane, s, lateral, 0.0)
        target = int(v[e, T.TARGET_LANE]) if v[e, T.KIND] != T.PLAIN else lane
        lane_index = self.table.indices[lane]
        limit = lanes[lane, L.SPEED_LIMIT]
        others = v[v[:, T.KIND] != T.OBSTACLE]  # highway-env exports vehicles, not obstacles
        vehicles = np.delete(others, e, axis=0)[:, [T.X, T.Y, T.HEADING, T.SPEED, T.LEN, T.WID]]
        ego = Ego(
            position=np.array([x, y]),
            heading=float(v[e, T.HEADING]),
            speed_mps=float(v[e, T.SPEED]),
            steering=float(v[e, T.STEER]),
            acceleration_mps2=float(v[e, T.ACCEL]),
            length_m=float(v[e, T.LEN]),
            width_m=float(v[e, T.WID]),
            lane_id=int(lanes[lane, L.LANE_ID]),
            lane_count=int(lanes[lane, L.LANE_COUNT]),
            target_lane_id=int(lanes[target, L.LANE_ID]),
            lane_width_m=float(lanes[lane, L.WIDTH]),
            lateral_offset_m=float(lateral),
            lane_heading=float(L.heading_at(lanes, lane, s)),
            lane_curvature=float(np.angle(np.exp(1j * (heading_ahead - heading_back)))) / 2.0,
            on_road=bool(on_road),
            in_intersection=self.scenario.in_junction(lane_index),
        )
        return WorldState(
            time_s=self.time_s,
            dt_s=1.0 / self.policy_frequency_hz,
            ego=ego,
            vehicles=vehicles,
            road=self.road_map,
            route=self.route.at(self.progress_m),
            events=Events(
                collided=bool(v[e, T.CRASHED] > 0),
                collision_with="vehicle" if v[e, T.CRASHED] > 0 else "",
                off_road=not on_road,
                arrived=self._arrived(),
            ),
            max_speed_mps=T.MAX_SPEED,
            speed_limit_mps=30.0 if np.isnan(limit) else float(limit),
        )
