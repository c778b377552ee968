"""The fast backend: highway-env builds each episode, drivelab's compiled traffic model runs it.

At reset highway-env lays out the road and places the vehicles exactly as it would itself (same
seed, same scenario code); from then on every step is ``traffic.simulate`` over a vehicle array,
and the WorldState is read from that array. Scenarios whose roads branch (merge, roundabout,
intersection) need route following that is not ported yet: they are refused with a clear error.
"""

from __future__ import annotations

import numpy as np
from highway_env import utils as hw_utils
from highway_env.vehicle.behavior import IDMVehicle
from highway_env.vehicle.controller import ControlledVehicle
from highway_env.vehicle.kinematics import Vehicle

from drivelab.envs.backends.fast import lanes as L
from drivelab.envs.backends.fast import traffic as T
from drivelab.envs.backends.fast.spawn import spawn_highway
from drivelab.envs.backends.highway import HighwayBackend, build_road_map
from drivelab.envs.route import RouteTracker
from drivelab.envs.scenarios import Scenario
from drivelab.envs.world import Ego, Events, WorldState
from drivelab.errors import UsageError

SUPPORTED = ("highway",)
SPAWNERS = {"highway": spawn_highway}
META = ("LANE_LEFT", "IDLE", "LANE_RIGHT", "FASTER", "SLOWER")
ACCELERATION_RANGE, STEERING_RANGE = (-5.0, 5.0), (-np.pi / 4, np.pi / 4)  # ContinuousAction's


def link_successors(table: L.LaneTable, network) -> None:
    """Fill NEXT_LANE where a road has exactly one successor with as many lanes (else -1)."""
    row_of = table.row_of
    for row, (_from, _to, lane_id) in enumerate(table.indices):
        successors = list(network.graph.get(_to, {}).items())
        if len(successors) == 1 and len(successors[0][1]) == len(network.graph[_from][_to]):
            table.rows[row, L.NEXT_LANE] = row_of[(_to, successors[0][0], lane_id)]


def vehicles_to_array(vehicles: list, table: L.LaneTable) -> np.ndarray:
    """highway-env vehicles → rows of ``traffic.VEHICLE_COLUMNS``, in the same order."""
    row_of = table.row_of
    array = np.zeros((len(vehicles), T.VEHICLE_COLUMNS))
    for i, vehicle in enumerate(vehicles):
        if type(vehicle) is not IDMVehicle and isinstance(vehicle, IDMVehicle):
            raise NotImplementedError(f"the fast backend has no {type(vehicle).__name__}")
        if isinstance(vehicle, IDMVehicle) and vehicle.route:
            raise NotImplementedError("the fast backend does not follow planned routes yet")
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
        if isinstance(vehicle, IDMVehicle):
            row[T.KIND] = T.IDM
        elif isinstance(vehicle, ControlledVehicle):
            row[T.KIND] = T.CONTROLLED
        elif isinstance(vehicle, Vehicle):
            row[T.KIND] = T.PLAIN
        if vehicle.LENGTH != T.CAR_LENGTH or vehicle.WIDTH != T.CAR_WIDTH:
            raise NotImplementedError("the fast backend assumes 5 m x 2 m vehicles")
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
        """Convert the road highway-env just built (lanes, drawing, routes) to arrays."""
        network = self.builder.env.road.network
        self.table = L.LaneTable.from_network(network)
        link_successors(self.table, network)
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
                self.builder.reset(0)  # the road never changes: build it once
                self._take_road()
            speeds = getattr(env.action_type, "target_speeds", None)
            self.vehicles = SPAWNERS[self.scenario.name](
                seed, self.table, self.graph_keys, env.config, self.control, speeds
            )
            self.ego = 0
        else:
            self.builder.reset(seed)
            self._take_road()
            self.vehicles = vehicles_to_array(env.road.vehicles, self.table)
            self.ego = env.road.vehicles.index(env.vehicle)
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
        v, e = self.vehicles, self.ego
        if self.control == "meta":
            self._apply_meta(control)
        else:
            # ContinuousAction.get_action, in the action's own dtype as highway-env computes it
            accel, steer = np.clip(control, -1, 1)
            v[e, T.ACCEL] = hw_utils.lmap(accel, [-1, 1], ACCELERATION_RANGE)
            v[e, T.STEER] = hw_utils.lmap(steer, [-1, 1], STEERING_RANGE)
        T.simulate(v, self.lanes, self.idm, self.frames, self.dt_s)
        self.time_s += 1 / self.policy_frequency_hz
        position = v[e, [T.X, T.Y]]
        self.progress_m = self.route.project(position, self.progress_m)
        self.world = self._export()
        return self.world

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
        others = np.delete(v, e, axis=0)
        vehicles = np.column_stack(
            [
                others[:, [T.X, T.Y, T.HEADING, T.SPEED]],
                np.full(len(others), T.CAR_LENGTH),
                np.full(len(others), T.CAR_WIDTH),
            ]
        )
        ego = Ego(
            position=np.array([x, y]),
            heading=float(v[e, T.HEADING]),
            speed_mps=float(v[e, T.SPEED]),
            steering=float(v[e, T.STEER]),
            acceleration_mps2=float(v[e, T.ACCEL]),
            length_m=T.CAR_LENGTH,
            width_m=T.CAR_WIDTH,
            lane_id=int(lanes[lane, L.LANE_ID]),
            lane_count=int(lanes[lane, L.LANE_COUNT]),
            target_lane_id=int(lanes[target, L.LANE_ID]),
            lane_width_m=float(lanes[lane, L.WIDTH]),
            lateral_offset_m=float(lateral),
            lane_heading=float(L.heading_at(lanes, lane, s)),
            lane_curvature=float(np.angle(np.exp(1j * (heading_ahead - heading_back)))) / 2.0,
            on_road=bool(on_road),
            in_intersection=lane_index[0] in self.scenario.intersection_nodes,
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
            ),
            max_speed_mps=T.MAX_SPEED,
            speed_limit_mps=30.0 if np.isnan(limit) else float(limit),
        )
