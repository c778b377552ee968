"""The signalised town's episode set-up for the compiled core (seed 000; its preset is
``drivelab.envs.scenarios.town``).

The reference (``backend="highway"``) builds the road, lights, pedestrians and traffic as
highway-env objects (``drivelab.envs.town_env``). ``town_episode`` sets up the same episode from a
seed as arrays, without any highway-env object: it draws the numbers ``TownEnv._reset`` draws,
from a generator seeded as gymnasium seeds ``env.np_random`` (``PCG64(SeedSequence(seed))``), in
the same order, and computes positions with highway-env's lane formulas call for call
(``fast.spawn.LaneGeometry``), so a seed gives bit for bit the reference's vehicle rows,
pedestrian rows, light offsets, ego route, NoCrash time limit and generator state (tested in
``tests/envs/test_town_spawn.py``). The draws, in order:

1. light offsets ``uniform(0, cycle, size=J)``, every junction (corners included);
2. the ego: a fixed route ``integers(25)`` (``fixed_routes``) or a street ``integers(S)`` and a
   random route (``integers(goals)`` per try, at most ROUTE_GOAL_TRIES tries); then its place
   ``uniform(5, max(length - 20, 5))`` along the start street;
3. per NPC: up to 10 tries of (street ``integers(S)``, place ``uniform(5, length - 5)``) until it
   is more than 12 m from every vehicle placed (else it is skipped), then speed ``uniform(4, 8)``,
   a random route from its street, DELTA ``uniform(3.5, 4.5)``;
4. per pedestrian: crossing ``integers(C)``, pavement ``choice([-1, 1])``, offset along the
   crossing ``uniform(-0.4, 0.4)``, pace ``uniform(1, 1.6)``, first wait ``uniform(0, 40)``.

Routes come from the road's route table (``TownRoadArrays.routes``: the reference's breadth-first
``shortest_route`` from every lane to every street's stop line). A random route's goals are the
streets that do not end where the start lane ends: exactly those whose table route is not the
start lane alone (length 1), so no node name is read.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np
from gymnasium.utils import seeding

from drivelab.envs.backends.fast import lanes as L
from drivelab.envs.backends.fast import pcg64
from drivelab.envs.backends.fast import town_rows as R
from drivelab.envs.backends.fast import traffic as T
from drivelab.envs.backends.fast.spawn import DELTA_RANGE, LaneGeometry, ego_kind, vehicle_row
from drivelab.envs.backends.roads.town_arrays import TownRoadArrays
from drivelab.envs.backends.roads.town_rules import (
    FIXED_ROUTE_COUNT,
    MEAN_WAIT_S,
    PAVEMENT_M,
    ROUTE_GOAL_TRIES,
    LightTimings,
)
from drivelab.envs.route import RouteTracker

PLACEMENT_TRIES = 10  # TownEnv._make_vehicles: tries at a free spot per NPC
NPC_SPACING_M = 12.0  # an NPC is placed more than this from every vehicle already placed
ROUTE_TIMEOUT_EXTRA_S = 10.0  # NoCrash's time limit: the route at ROUTE_TIMEOUT_MPS, plus this


class TownEpisode(NamedTuple):
    """One town episode as set up from its seed (``town_episode``).

    :param vehicles: (N, TOWN_VEHICLE_COLUMNS) the ego then the NPCs (KIND TOWN), as
        ``vehicles_to_array(road.vehicles, table, town_class=TownVehicle)`` lays them out.
    :param ego: the ego's row (0).
    :param pedestrians: (P, PEDESTRIAN_COLUMNS) in spawn order.
    :param light_offsets_s: (J,) every junction's cycle offset (``TownLights.offsets_s``).
    :param ego_route: (R,) int64 lane rows of the ego's planned route (``TownEnv.ego_route``).
    :param route_time_limit_s: the NoCrash time limit with fixed routes, else inf (what
        ``HighwayBackend.route_time_limit_s`` is; inf where it is None).
    :param rng: the episode's generator after the set-up (``env.np_random``): the frames' draws
        go on from it.
    :param rng_state: (6,) uint64 ``pcg64.state_of(rng)``, for the compiled kernels.
    """

    vehicles: np.ndarray
    ego: int
    pedestrians: np.ndarray
    light_offsets_s: np.ndarray
    ego_route: np.ndarray
    route_time_limit_s: float
    rng: np.random.Generator
    rng_state: np.ndarray


@dataclass
class TownSetup:
    """What a town set-up reads from the road, once per road and configuration (``of``).

    :param table: the town's LaneTable; ``geometry`` its highway-env lane formulas.
    :param arrays: the town's lane metadata, crossings and route table.
    :param vehicles_count, pedestrians_count: the traffic level's NPCs and pedestrians.
    :param cycle_s: the lights' cycle; ``ego_start_speed``: the ego's initial speed.
    :param fixed_routes: NoCrash's fixed routes (else a random start and route).
    :param target_speeds: the meta-action ego's allowed speeds (MDPVehicle's).
    :param ego_length, ego_width, npc_length, npc_width, lane_change_delay, idm_delta: the
        vehicle classes' constants, as the simulator's road holds them (``vehicle_row`` reads them).
    """

    table: L.LaneTable
    geometry: LaneGeometry
    arrays: TownRoadArrays
    vehicles_count: int
    pedestrians_count: int
    cycle_s: float
    ego_start_speed: float
    fixed_routes: bool
    target_speeds: np.ndarray
    ego_length: float
    ego_width: float
    npc_length: float
    npc_width: float
    lane_change_delay: float
    idm_delta: float
    _goals: dict = field(default_factory=dict, repr=False)
    _fixed: np.ndarray | None = field(default=None, repr=False)

    def __post_init__(self) -> None:
        self.street_list = [int(lane) for lane in self.arrays.street_lanes]  # Python ints: cheap to index
        self.lengths = [float(length) for length in self.table.rows[:, L.LENGTH]]

    @classmethod
    def of(cls, road) -> TownSetup:
        """The set-up of the simulator's converted ``road`` (kept in ``road.cache["town_setup"]``).
        It reads ``road.table``, ``road.geometry``, ``road.config`` (TownEnv's), the vehicle
        constants and ``road.cache["town_arrays"]`` (the TownRoadArrays of the road's
        description, which the simulator's road conversion puts there)."""
        setup = road.cache.get("town_setup")
        if setup is None:
            arrays = road.cache["town_arrays"]
            config = road.config
            setup = road.cache["town_setup"] = cls(
                table=road.table,
                geometry=road.geometry,
                arrays=arrays,
                vehicles_count=int(config["vehicles_count"]),
                pedestrians_count=int(config["pedestrians_count"]),
                cycle_s=LightTimings(**config["light_timings"]).cycle_s,
                ego_start_speed=float(config["ego_start_speed"]),
                fixed_routes=bool(config["fixed_routes"]),
                target_speeds=np.asarray(road.target_speeds, dtype=float),
                ego_length=float(road.ego_length),
                ego_width=float(road.ego_width),
                npc_length=float(road.npc_length),
                npc_width=float(road.npc_width),
                lane_change_delay=float(road.lane_change_delay),
                idm_delta=float(road.idm_delta),
            )
        return setup

    def goals(self, start: int) -> np.ndarray:
        """Street indices (into ``arrays.street_lanes``) a random route from lane ``start`` may
        aim at, in ``street_lanes`` order: every street not ending where ``start`` ends."""
        goals = self._goals.get(start)
        if goals is None:
            goals = self._goals[start] = np.flatnonzero(self.arrays.route_length[start] != 1)
        return goals

    def route(self, start: int, street: int) -> np.ndarray:
        """(R,) lane rows of the shortest route from lane ``start`` to street ``street``'s stop
        line (empty when there is none)."""
        return self.arrays.routes[start, street, : self.arrays.route_length[start, street]]

    def random_route(self, start: int, rng: np.random.Generator) -> np.ndarray:
        """``town_env.random_route`` from lane ``start``: a shortest route to a random other
        street's stop line (at most ROUTE_GOAL_TRIES goals drawn), else the start lane alone."""
        goals = self.goals(start)
        for _ in range(ROUTE_GOAL_TRIES):
            route = self.route(start, int(goals[rng.integers(len(goals))]))
            if route.size:
                return route
        return np.array([start], dtype=np.int64)

    @property
    def fixed(self) -> np.ndarray:
        """(FIXED_ROUTE_COUNT, 2) ``town_env.fixed_routes``: (start street, goal street) indices
        into ``arrays.street_lanes``, drawn once from ``default_rng(0)`` as the reference draws
        them (start, then goal, kept when the goal is another stop line and reachable)."""
        if self._fixed is None:
            rng = np.random.default_rng(0)
            streets, lengths = self.arrays.street_lanes, self.arrays.route_length
            pairs = []
            while len(pairs) < FIXED_ROUTE_COUNT:
                start, goal = int(rng.integers(len(streets))), int(rng.integers(len(streets)))
                if lengths[streets[start], goal] > 1:  # 1: ends at the goal already; 0: unreachable
                    pairs.append((start, goal))
            self._fixed = np.array(pairs, dtype=np.int64)
        return self._fixed


def route_polyline(geometry: LaneGeometry, lanes) -> np.ndarray:
    """(K, 2) the centre line of ``lanes`` (lane rows), sampled as ``HighwayBackend.route_for``
    samples it: a straight lane's two ends, a curved one every <= 2 m (``np.linspace``), with the
    lane formulas' own bits."""
    from drivelab.envs.backends.highway import SAMPLE_SPACING_M  # the reference's sampling

    parts = []
    for lane in lanes:
        lane = int(lane)
        length = geometry.length(lane)
        if int(geometry.lanes[lane, L.KIND]) == L.STRAIGHT:
            stations = np.array([0.0, length])
        else:
            stations = np.linspace(0.0, length, max(int(np.ceil(length / SAMPLE_SPACING_M)), 1) + 1)
        lateral = np.float64(0.0)
        parts.append(np.array([geometry.position(lane, s, lateral) for s in stations]))
    return np.concatenate(parts)


def _write_route(row: np.ndarray, route: np.ndarray) -> None:
    """A planned route into a vehicle row: roads (one lane each: the road row is the lane row),
    lane id 0, ROUTED."""
    capacity = (row.size - T.ROUTE) // 2
    if route.size > capacity:
        raise NotImplementedError(f"the town's vehicle rows keep routes of at most {capacity} roads")
    row[T.ROUTED], row[T.ROUTE_START], row[T.ROUTE_END] = 1.0, 0.0, route.size
    row[T.ROUTE : T.ROUTE + 2 * route.size : 2] = route
    row[T.ROUTE + 1 : T.ROUTE + 2 * route.size : 2] = 0.0


def _nearest(x: np.ndarray, y: np.ndarray, px: float, py: float) -> float:
    """``min(town_env._distance(v, p) for v in vehicles)`` over points (x, y) (n,): the same
    sqrt(dx * dx + dy * dy), dx = x - p_x, as numpy element-wise operations (each correctly
    rounded, as a scalar's: the same bits whatever SIMD numpy uses)."""
    dx, dy = x - px, y - py
    return float(np.sqrt(dx * dx + dy * dy).min())


def town_episode(seed: int, setup: TownSetup, control: str) -> TownEpisode:
    """``TownEnv._reset`` of seed ``seed`` (the reference's ``HighwayBackend.reset(seed)``) as
    arrays: see the module docstring for the draws.

    :param setup: the road's TownSetup.
    :param control: "meta" (an MDPVehicle ego: CONTROLLED, routed) or "continuous" (a kinematic
        Vehicle: PLAIN, no route).
    """
    rng, _ = seeding.np_random(int(seed))
    arrays, geometry = setup.arrays, setup.geometry
    streets = arrays.street_lanes
    offsets = rng.uniform(0.0, setup.cycle_s, size=arrays.junction_count)

    # the ego (TownEnv._make_vehicles): its route, then its place on the start street
    if setup.fixed_routes:
        start_street, goal = setup.fixed[int(rng.integers(FIXED_ROUTE_COUNT))]
        start = int(streets[start_street])
        ego_route = setup.route(start, int(goal))
    else:
        start = int(streets[rng.integers(len(streets))])
        ego_route = setup.random_route(start, rng)
    length = geometry.length(start)
    longitudinal = rng.uniform(5.0, max(length - 20.0, 5.0))
    kind = ego_kind(control)
    vehicles = np.zeros((1 + setup.vehicles_count, T.TOWN_VEHICLE_COLUMNS))
    x, y = np.zeros(len(vehicles)), np.zeros(len(vehicles))  # the placed vehicles' positions
    ego = vehicles[0]
    ego[: T.ROUTE] = vehicle_row(
        setup,
        geometry.position(start, longitudinal, 0.0),
        geometry.heading_at(start, longitudinal),
        setup.ego_start_speed,
        kind,
    )[: T.ROUTE]
    if kind == T.CONTROLLED:  # a meta-action ego follows the planned route itself
        _write_route(ego, ego_route)
    x[0], y[0] = ego[T.X], ego[T.Y]
    count = 1

    street_list, lengths = setup.street_list, setup.lengths
    for _ in range(setup.vehicles_count):
        for _ in range(PLACEMENT_TRIES):
            lane = street_list[rng.integers(len(street_list))]
            position = geometry.position(lane, rng.uniform(5.0, lengths[lane] - 5.0), 0.0)
            if _nearest(x[:count], y[:count], position[0], position[1]) > NPC_SPACING_M:
                break
        else:
            continue
        s = geometry.local_coordinates(lane, position)[0]
        row = vehicles[count]
        speed = rng.uniform(4.0, 8.0)
        row[: T.ROUTE] = vehicle_row(setup, position, geometry.heading_at(lane, s), speed, T.IDM)[: T.ROUTE]
        row[T.KIND], row[T.TARGET_LANE] = T.TOWN, lane
        row[T.TARGET_SPEED] = geometry.speed_limit(lane)
        _write_route(row, setup.random_route(lane, rng))
        row[T.DELTA] = rng.uniform(low=DELTA_RANGE[0], high=DELTA_RANGE[1])  # randomize_behavior
        x[count], y[count] = row[T.X], row[T.Y]
        count += 1

    pedestrians = np.zeros((setup.pedestrians_count, R.PEDESTRIAN_COLUMNS))
    for walker in pedestrians:  # TownEnv._make_pedestrians and Pedestrian.__init__
        c = int(rng.integers(len(arrays.crossings)))
        crossing = arrays.crossings[c]
        side = int(rng.choice([-1, 1]))
        centre = np.asarray(crossing[:2], dtype=float)
        across = np.array([np.cos(crossing[2]), np.sin(crossing[2])])
        along = np.array([-across[1], across[0]]) * rng.uniform(-0.4, 0.4) * crossing[4]
        walker[R.P_PACE] = float(rng.uniform(1.0, 1.6))
        walker[R.P_X : R.P_Y + 1] = centre + along + side * PAVEMENT_M * across
        walker[R.P_HEADING], walker[R.P_SIDE] = crossing[2], side
        walker[R.P_WAIT_S] = float(rng.uniform(0.0, 2 * MEAN_WAIT_S))
        walker[R.P_CENTRE_X : R.P_CENTRE_Y + 1] = centre
        walker[R.P_ACROSS_X : R.P_ACROSS_Y + 1] = across
        walker[R.P_CROSSING] = c

    limit = np.inf
    if setup.fixed_routes:  # HighwayBackend.reset: (route length - progress) at 10 km/h, + 10 s
        from drivelab.envs.backends.highway import ROUTE_TIMEOUT_MPS

        route = RouteTracker(route_polyline(geometry, ego_route), has_goal=True)
        progress = route.project(ego[T.X : T.Y + 1])
        limit = (route.length_m - progress) / ROUTE_TIMEOUT_MPS + ROUTE_TIMEOUT_EXTRA_S
    return TownEpisode(
        vehicles=vehicles[:count],
        ego=0,
        pedestrians=pedestrians,
        light_offsets_s=offsets,
        ego_route=np.asarray(ego_route, dtype=np.int64),
        route_time_limit_s=float(limit),
        rng=rng,
        rng_state=pcg64.state_of(rng),
    )


def spawn_town(seed: int, road, control: str) -> tuple[np.ndarray, int, np.ndarray, TownEpisode]:
    """The ``Scenario.spawn`` hook: ``(vehicle rows, ego row, regulation (2,) zeros, episode)``,
    where the fourth item, what goes on between steps, is the whole ``TownEpisode`` (its ``rng``
    is the generator the frames draw from; pedestrians, light offsets, the ego's route and its
    time limit are the town's additions to the contract)."""
    episode = town_episode(seed, TownSetup.of(road), control)
    return episode.vehicles, episode.ego, np.zeros(2), episode
