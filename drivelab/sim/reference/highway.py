"""The reference backend: highway-env simulates, drivelab reads its state into a WorldState.

Only this module imports highway-env objects. It drives highway-env's own simulation loop
(``_simulate``) and never asks highway-env for an observation or a reward, so sensors and reward
terms are drivelab's alone (and highway-env's pandas-based observation is not paid per step).
"""

from __future__ import annotations

import dataclasses
import functools
import os

import numpy as np

from drivelab.errors import UsageError
from drivelab.sim.roads.road_map import lane_points, lane_stations, lanes_road_map
from drivelab.sim.route import RouteTracker
from drivelab.world.scenario import Scenario
from drivelab.world.state import LIGHT_RED, Ego, Events, RoadMap, WorldState

os.environ.setdefault("PYGAME_HIDE_SUPPORT_PROMPT", "1")

from highway_env import utils as hw_utils  # noqa: E402
from highway_env.road.lane import StraightLane  # noqa: E402
from highway_env.vehicle.behavior import IDMVehicle  # noqa: E402


class IntersectionIDMVehicle(IDMVehicle):
    """highway-env's IDMVehicle, for the intersection's traffic alone (its config's
    ``other_vehicles_type``). ``IntersectionEnv._make_vehicles`` sets its traffic class's
    DISTANCE_WANTED, COMFORT_ACC_MAX and COMFORT_ACC_MIN at every reset; on IDMVehicle itself that
    would change every scenario's traffic for the rest of the process (the town's NPCs, which are
    IDMVehicles, then stop for yellow lights differently once an intersection has been built).
    On this subclass the change stays the intersection's."""


def is_idm_class(cls: type) -> bool:
    """``cls`` is IDMVehicle or a subclass that changes only its constants (no method of its own):
    the compiled core's IDM/MOBIL model, with the class's parameters."""
    if not (isinstance(cls, type) and issubclass(cls, IDMVehicle)):
        return False
    own = cls.__mro__[: cls.__mro__.index(IDMVehicle)]
    return not any(
        callable(value) for c in own for name, value in vars(c).items() if not name.startswith("__")
    )


ROUTE_TIMEOUT_MPS = 10 / 3.6  # an evaluation route must be driven at 10 km/h on average
ROUTE_LOOKAHEAD_M = 1000.0  # a route that never ends (highway, racetrack) is cut here


def _lane_stations(lane) -> np.ndarray:
    """Arc-length stations at which to sample a highway-env lane: its ends, plus every 2 m if curved."""
    return lane_stations(lane, type(lane) is StraightLane)


def _object_rows(objects: list) -> np.ndarray:
    """(N, 6) x, y, heading, speed, length, width of highway-env road objects."""
    return np.array(
        [[*o.position, o.heading, o.speed, o.LENGTH, o.WIDTH] for o in objects], dtype=float
    ).reshape(-1, 6)


def build_road_map(network) -> RoadMap:
    """Convert highway-env's road network to arrays (once per reset)."""
    lanes = network.lanes_list()
    return lanes_road_map(
        lanes,
        [type(lane) is StraightLane for lane in lanes],
        [lane.width_at(0.0) for lane in lanes],
        [tuple(int(t) for t in lane.line_types) for lane in lanes],
    )


class _NoObservation:
    """Stands in for highway-env's observation type: drivelab's sensors read the WorldState."""

    def __init__(self, space) -> None:
        self._space = space

    def space(self):
        return self._space

    def observe(self) -> None:
        return None


class _SkipObservationAndInfo:
    """Mixed into a highway-env env class: skips the work drivelab never reads, highway-env's
    observation at reset (pandas-based, most of a reset's cost) and its ``_info``, which evaluates
    its own reward with a sampled action (and fails for continuous actions on some scenarios)."""

    def define_spaces(self) -> None:
        super().define_spaces()
        self.observation_type = _NoObservation(self.observation_space)

    def _info(self, obs, action=None) -> dict:
        return {}

    def __reduce__(self):
        """Pickle as (highway-env class, state): the subclass is built at run time, so pickle
        cannot find it by name; unpickling rebuilds it from the highway-env class it extends."""
        return _blank_env, (type(self).__bases__[1],), self.__dict__


@functools.cache
def _without_observation_and_info(env_class: type) -> type:
    """``env_class`` with ``_SkipObservationAndInfo`` mixed in, one class per env class."""
    return type(env_class.__name__, (_SkipObservationAndInfo, env_class), {"__module__": __name__})


def _blank_env(env_class: type):
    """An uninitialised instance of ``env_class``'s drivelab subclass; pickle fills its state."""
    cls = _without_observation_and_info(env_class)
    return cls.__new__(cls)


class HighwayBackend:
    """highway-env as a drivelab backend.

    :param scenario: which road and traffic model to build.
    :param traffic: "empty", "regular" or "dense".
    :param control: "meta" (the ego takes highway-env's 5 meta-actions) or "continuous"
        (normalised [acceleration, steering] in [-1, 1], highway-env's ContinuousAction ranges).
    :param overrides: extra highway-env config keys (e.g. ``{"duration": 10}``).
    """

    def __init__(
        self,
        scenario: Scenario,
        traffic: str = "regular",
        control: str = "meta",
        overrides: dict | None = None,
    ) -> None:
        if not scenario.reference_backend:
            raise UsageError(
                f"scenario {scenario.name!r} runs on the compiled core only (backend fast or auto)"
            )
        self.scenario = scenario
        self.control = control
        config, self.keep_npcs, self.extra_vehicles = self.assemble_config(
            scenario, traffic, control, overrides
        )
        env_class = hw_utils.class_from_path(scenario.env_class)
        self.env = _without_observation_and_info(env_class)(config=config)
        self.world: WorldState | None = None

    @staticmethod
    def assemble_config(
        scenario: Scenario, traffic: str, control: str, overrides: dict | None
    ) -> tuple[dict, bool, int]:
        """(highway-env config keys given to the env, keep_npcs, extra_vehicles): the scenario's
        config, its traffic level, the control's action type, then ``overrides`` (drivelab's
        keep_npcs and extra_vehicles among them too)."""
        config = {**scenario.config, **scenario.traffic.get(traffic, {})}
        overrides = dict(overrides or {})
        keep_npcs = overrides.pop("keep_npcs", config.pop("keep_npcs", True))
        extra_vehicles = overrides.pop("extra_vehicles", config.pop("extra_vehicles", 0))
        if control == "meta":
            config["action"] = {"type": "DiscreteMetaAction"}
            if scenario.meta_target_speeds:
                config["action"]["target_speeds"] = list(scenario.meta_target_speeds)
        else:
            config["action"] = {"type": "ContinuousAction", "longitudinal": True, "lateral": True}
            config["policy_frequency"] = scenario.continuous_policy_frequency_hz
        config.update(overrides)
        return config, keep_npcs, extra_vehicles

    # --- timing -------------------------------------------------------------------------------
    @property
    def policy_frequency_hz(self) -> float:
        return float(self.env.config["policy_frequency"])

    @property
    def duration_s(self) -> float:
        return float(self.env.config["duration"])

    # --- episode ------------------------------------------------------------------------------
    def reset(self, seed: int) -> WorldState:
        """Build a new episode from ``seed`` and return its first WorldState."""
        self.env.reset(seed=int(seed))
        self.arrange_traffic()
        road = self.env.road
        self.road_map = build_road_map(road.network)
        self.lights = getattr(road, "lights", None)  # a signalised scenario's TownLights
        lanes = self.route_lanes = self._plan_route()
        self.route_lane_id = lanes[0][2]
        self.route = self.route_for(lanes)
        crossings = getattr(self.env, "crossings", None)
        if crossings is not None:
            self.road_map = dataclasses.replace(self.road_map, crossings=crossings)
        if self.scenario.guide_line:  # painted along the route: one whole lap of the circuit
            self.road_map = dataclasses.replace(self.road_map, guide_lines=(self.route.polyline,))
        self.progress_m = self.route.project(self.env.vehicle.position)
        self.route_time_limit_s = None
        config = self.env.config
        if config.get("fixed_routes") or config.get("retarget") is False:  # one route: NoCrash's
            # time limit (the CoRL 2017 timeout), the route at 10 km/h + 10 s
            self.route_time_limit_s = (self.route.length_m - self.progress_m) / ROUTE_TIMEOUT_MPS + 10.0
        self.world = self._export(Events())
        return self.world

    def step(self, control: int | np.ndarray) -> WorldState:
        """Apply one policy-step's control and advance the simulation."""
        env = self.env
        previous_lane = env.vehicle.lane_index
        env.time += 1 / env.config["policy_frequency"]
        env._simulate(control)
        if self.scenario.traffic_flow:  # highway-env does this in its own step() (IntersectionEnv)
            env._clear_vehicles()
            env._spawn_vehicle(spawn_probability=env.config["spawn_probability"])
        ego = env.vehicle
        self.progress_m = self.route.project(ego.position, self.progress_m)
        if env.config.get("retarget") and self._arrived():  # training in town: a new target
            self.route_lanes = self.route_lanes + env.extend_route()
            self.route = self.route_for(self.route_lanes)
            self.progress_m = self.route.project(ego.position, self.progress_m)
        events = Events(
            collided=bool(ego.crashed),
            collision_with=self._collision_kind(),
            off_road=not ego.on_road or (self.scenario.keep_lane and ego.lane_index[2] != self.route_lane_id),
            arrived=self._arrived(),
            red_light_crossed=self._ran_red_light(previous_lane),
        )
        self.world = self._export(events)
        return self.world

    # --- traffic ------------------------------------------------------------------------------
    def arrange_traffic(self) -> None:
        """Apply the traffic level to the vehicles highway-env placed (remove them, or add more)."""
        road, ego = self.env.road, self.env.vehicle
        if not self.keep_npcs:
            road.vehicles = [v for v in road.vehicles if v is ego]
        rng = self.env.np_random
        wanted = len(road.vehicles) + self.extra_vehicles
        for _ in range(self.extra_vehicles * 10):  # bounded retries to find free spots
            if len(road.vehicles) >= wanted:
                break
            lane_index = road.network.random_lane_index(rng)
            lane = road.network.get_lane(lane_index)
            longitudinal, speed = float(rng.uniform(0, lane.length)), float(lane.speed_limit or 20.0) * 0.8
            vehicle = IDMVehicle.make_on_lane(road, lane_index, longitudinal=longitudinal, speed=speed)
            if min(np.linalg.norm(v.position - vehicle.position) for v in road.vehicles) < 15:
                continue
            if self.scenario.destination:
                vehicle.plan_route_to(self.scenario.destination)
            road.vehicles.append(vehicle)

    # --- route --------------------------------------------------------------------------------
    def _plan_route(self, start: tuple | None = None) -> list[tuple]:
        """Lane indices the ego is meant to follow, from ``start`` (default: the ego's lane)."""
        network = self.env.road.network
        start = start or self.env.vehicle.lane_index
        lane_id = start[2]
        if hasattr(self.env, "ego_route"):  # the scenario planned the ego's route itself
            return list(self.env.ego_route)
        if self.scenario.destination:
            path = network.shortest_path(start[1], self.scenario.destination)
            nodes = [start[0]] + path
        else:
            nodes, length = [start[0], start[1]], network.get_lane(start).length
            while length < ROUTE_LOOKAHEAD_M or self.scenario.circuit:
                successors = list(network.graph.get(nodes[-1], {}))
                if not successors or nodes[-1] == nodes[0]:
                    break
                nodes.append(successors[0])
                length += network.get_lane((nodes[-2], nodes[-1], 0)).length
        return [
            (_from, _to, min(lane_id, len(network.graph[_from][_to]) - 1))
            for _from, _to in zip(nodes[:-1], nodes[1:], strict=True)
        ]

    def route_for(self, lanes: list[tuple]) -> RouteTracker:
        """A RouteTracker along the centre lines of ``lanes``."""
        network = self.env.road.network
        points = [lane_points(network.get_lane(i), _lane_stations(network.get_lane(i)), 0.0) for i in lanes]
        has_goal = bool(self.scenario.destination) or self.scenario.arrival == "route_end"
        return RouteTracker(np.concatenate(points), has_goal=has_goal)

    def _ran_red_light(self, previous_lane: tuple) -> bool:
        """The ego crossed a stop line (left a street for the junction lanes behind it) on red."""
        if self.lights is None:
            return False
        approach = self.lights.approach_of(previous_lane)
        if approach is None or self.env.vehicle.lane_index[0] != previous_lane[1]:
            return False
        return self.lights.state(*approach, self.env.time) == LIGHT_RED

    def _pedestrians(self) -> list:
        return getattr(self.env.road, "pedestrians", [])

    def _collision_kind(self) -> str:
        ego = self.env.vehicle
        if not ego.crashed:
            return ""
        return "pedestrian" if any(p.hit_by is ego for p in self._pedestrians()) else "vehicle"

    def _arrived(self) -> bool:
        ego = self.env.vehicle
        if self.scenario.arrival == "route_end":
            return self.route.length_m - self.progress_m < 2.0
        if self.scenario.arrival == "merge_end":
            return bool(ego.position[0] > self.scenario.arrival_x_m)
        if self.scenario.arrival == "exit":
            return bool(self.env.has_arrived(ego))
        return False

    # --- export -------------------------------------------------------------------------------
    def _export(self, events: Events) -> WorldState:
        env = self.env
        ego = env.vehicle
        lane_index = ego.lane_index
        lane = ego.lane
        s, lateral = lane.local_coordinates(ego.position)
        heading_back, heading_ahead = lane.heading_at(s - 1.0), lane.heading_at(s + 1.0)
        curvature = float(np.angle(np.exp(1j * (heading_ahead - heading_back)))) / 2.0
        target = getattr(ego, "target_lane_index", lane_index)
        others = [v for v in env.road.vehicles if v is not ego]
        vehicles = _object_rows(others)
        pedestrians = _object_rows([p for p in self._pedestrians() if not p.crashed])
        ego_state = Ego(
            position=np.array(ego.position, dtype=float), heading=float(ego.heading),
            speed_mps=float(ego.speed), steering=float(ego.action.get("steering", 0.0)),
            acceleration_mps2=float(ego.action.get("acceleration", 0.0)), length_m=float(ego.LENGTH),
            width_m=float(ego.WIDTH), lane_id=int(lane_index[2]),
            lane_count=len(env.road.network.all_side_lanes(lane_index)), target_lane_id=int(target[2]),
            lane_width_m=float(lane.width_at(s)), lateral_offset_m=float(lateral),
            lane_heading=float(lane.heading_at(s)), lane_curvature=curvature, on_road=bool(ego.on_road),
            in_intersection=self.scenario.in_junction(lane_index),
        )  # fmt: skip
        lights = self.lights.table(env.time) if self.lights is not None else np.zeros((0, 4))
        return WorldState(
            time_s=float(env.time), dt_s=1.0 / self.policy_frequency_hz, ego=ego_state, vehicles=vehicles,
            pedestrians=pedestrians, road=self.road_map, route=self.route.at(self.progress_m), events=events,
            traffic_lights=lights, max_speed_mps=float(ego.MAX_SPEED),
            speed_limit_mps=float(lane.speed_limit or 30.0),
            vehicle_destinations=np.array([v.destination for v in others], dtype=float).reshape(-1, 2),
            vehicle_accelerations=np.array([v.action.get("acceleration", 0.0) for v in others], dtype=float),
        )  # fmt: skip
