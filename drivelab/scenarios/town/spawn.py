"""The signalised town's episode set-up for the compiled core (the RLAD paper; its preset is
``drivelab.scenarios.town``).

``town_episode`` sets up the reference's (``reference_env.py``) episode of a seed as arrays, in
one compiled call (``_town_rows``): the numbers ``TownEnv._reset`` draws, from a generator seeded
as gymnasium seeds ``env.np_random`` (``PCG64(SeedSequence(seed))``, words made by ``pcg64``), in
the same order, and highway-env's lane formulas operation for operation (every street is straight:
+, -, *, /, sqrt and %, correctly rounded; the crossings' cos / sin come from numpy). So a seed
gives bit for bit the reference's rows, light offsets, ego route, time limit and generator state.
The draws, in order:

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
``shortest_route`` from every lane to every street's stop line); a random route's goal is drawn
as the kernels draw it (``junctions.traffic.random_goal``), among the streets that do not end where
the start lane ends.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np
from gymnasium.utils import seeding
from numba import njit

from drivelab.sim.core import lanes as L
from drivelab.sim.core import pcg64
from drivelab.sim.core import traffic as T
from drivelab.sim.core.spawn import DELTA_RANGE, LaneGeometry, ego_kind, lane_distances, mdp_target_speed
from drivelab.sim.junctions import rows as R
from drivelab.sim.junctions.arrays import TownRoadArrays
from drivelab.sim.junctions.arrays_description import town_arrays
from drivelab.sim.junctions.rules import FIXED_ROUTE_COUNT, MEAN_WAIT_S, PAVEMENT_M, LightTimings
from drivelab.sim.junctions.traffic import random_goal, random_route
from drivelab.sim.roads.road_map import SAMPLE_SPACING_M
from drivelab.sim.route import RouteTracker

PLACEMENT_TRIES = 10  # TownEnv._make_vehicles: tries at a free spot per NPC
NPC_SPACING_M = 12.0  # an NPC is placed more than this from every vehicle already placed
ROUTE_TIMEOUT_EXTRA_S = 10.0  # NoCrash's time limit: the route at ROUTE_TIMEOUT_MPS, plus this


@dataclass(frozen=True)
class TownEpisode:
    """One town episode as set up from its seed (``town_episode``).

    :param vehicles: (N, TOWN_VEHICLE_COLUMNS) the ego (row ``ego``, 0) then the NPCs (KIND TOWN),
        laid out as ``vehicles_to_array(..., town_class=TownVehicle)`` lays them out.
    :param pedestrians: (P, PEDESTRIAN_COLUMNS) in spawn order; ``light_offsets_s`` (J,): every
        junction's cycle offset; ``ego_route`` (R,): the lane rows of the ego's planned route.
    :param route_time_limit_s: the NoCrash time limit with fixed routes, else inf.
    :param rng_state: (6,) uint64 PCG64 words of the episode's generator after the set-up.
    """

    vehicles: np.ndarray
    ego: int
    pedestrians: np.ndarray
    light_offsets_s: np.ndarray
    ego_route: np.ndarray
    route_time_limit_s: float
    rng_state: np.ndarray


@dataclass
class TownSetup:
    """What a town set-up reads from the road, once per road and configuration (``of``).

    :param road: the simulator's converted road: its LaneTable, lane formulas (``geometry``), the
        meta-action ego's allowed speeds and the vehicle classes' constants.
    :param arrays: the town's lane metadata, crossings and route table.
    :param vehicles_count, pedestrians_count: the traffic level's NPCs and pedestrians.
    :param cycle_s: the lights' cycle; ``ego_start_speed``: the ego's initial speed.
    :param fixed_routes: NoCrash's fixed routes (else a random start and route).
    :param timed_routes: each episode drives one route (``fixed_routes``, or no ``retarget``) and
        has NoCrash's time limit: the route at 10 km/h, plus 10 s.
    """

    road: object
    arrays: TownRoadArrays
    vehicles_count: int
    pedestrians_count: int
    cycle_s: float
    ego_start_speed: float
    fixed_routes: bool
    timed_routes: bool

    def __post_init__(self) -> None:
        self.geometry: LaneGeometry = self.road.geometry
        rows, streets = self.road.table.rows, self.arrays.street_lanes
        if np.any(rows[streets, L.KIND] != L.STRAIGHT):
            raise NotImplementedError("the town's set-up places vehicles on straight streets only")
        crossings = self.arrays.crossings
        # a pedestrian's walking direction, per crossing: the reference's np.cos / np.sin calls
        self.across = np.array([[np.cos(c[2]), np.sin(c[2])] for c in crossings]).reshape(-1, 2)
        self._polylines: dict[int, np.ndarray] = {}
        self._trackers: dict[tuple[int, ...], RouteTracker] = {}

    @functools.cached_property
    def ego_target_speed(self) -> float:
        """A meta-action ego's first target speed (MDPVehicle's: the allowed speed nearest its start
        speed)."""
        return float(mdp_target_speed(self.ego_start_speed, self.road.target_speeds))

    @classmethod
    def of(cls, road) -> TownSetup:
        """The set-up of the simulator's converted ``road`` (kept in ``road.cache["town_setup"]``),
        with the TownRoadArrays of the road's description (``road.cache["town_arrays"]``)."""
        setup = road.cache.get("town_setup")
        if setup is None:
            arrays = road.cache.get("town_arrays")
            if arrays is None:
                arrays = road.cache["town_arrays"] = town_arrays(road.description)
            config = road.config
            setup = road.cache["town_setup"] = cls(
                road=road,
                arrays=arrays,
                vehicles_count=int(config["vehicles_count"]),
                pedestrians_count=int(config["pedestrians_count"]),
                cycle_s=LightTimings(**config["light_timings"]).cycle_s,
                ego_start_speed=float(config["ego_start_speed"]),
                fixed_routes=bool(config["fixed_routes"]),
                timed_routes=bool(config["fixed_routes"]) or not config["retarget"],
            )
        return setup

    @functools.cached_property
    def fixed(self) -> np.ndarray:
        """(FIXED_ROUTE_COUNT, 2) ``town_env.fixed_routes``: (start street, goal street) indices
        into ``arrays.street_lanes``, drawn once from ``default_rng(0)`` as the reference draws
        them (start, then goal, kept when the goal is another stop line and reachable)."""
        rng = np.random.default_rng(0)
        streets, lengths = self.arrays.street_lanes, self.arrays.route_length
        pairs = []
        while len(pairs) < FIXED_ROUTE_COUNT:
            start, goal = int(rng.integers(len(streets))), int(rng.integers(len(streets)))
            if lengths[streets[start], goal] > 1:  # 1: ends at the goal already; 0: unreachable
                pairs.append((start, goal))
        return np.array(pairs, dtype=np.int64)


def route_polyline(geometry: LaneGeometry, lanes, parts: dict) -> np.ndarray:
    """(K, 2) the centre line of ``lanes`` (lane rows), sampled as ``HighwayBackend.route_for``
    samples it: a straight lane's two ends, a curved one every <= 2 m (``np.linspace``).
    ``parts``: a cache of each lane's samples."""
    for lane in lanes:
        lane = int(lane)
        if lane in parts:
            continue
        length = geometry.length(lane)
        if int(geometry.lanes[lane, L.KIND]) == L.STRAIGHT:
            stations = np.array([0.0, length])
        else:
            stations = np.linspace(0.0, length, max(int(np.ceil(length / SAMPLE_SPACING_M)), 1) + 1)
        lateral = np.float64(0.0)
        parts[lane] = np.array([geometry.position(lane, s, lateral) for s in stations])
    return np.concatenate([parts[int(lane)] for lane in lanes])


def route_tracker(setup: TownSetup, lanes) -> RouteTracker:
    """The RouteTracker of the route along ``lanes`` (``route_polyline``), made once per route:
    a tracker is read-only, so the episodes that drive the same route share it."""
    key = tuple(int(lane) for lane in lanes)
    tracker = setup._trackers.get(key)
    if tracker is None:
        if len(setup._trackers) >= TRACKER_CACHE_SIZE:
            setup._trackers.clear()
        tracker = setup._trackers[key] = RouteTracker(
            route_polyline(setup.geometry, key, setup._polylines), has_goal=True
        )
        arrays = tracker.polyline, tracker.stations, tracker._starts, tracker._segments, tracker._lengths2
        for array in arrays:
            array.setflags(write=False)  # shared by every episode on the route
    return tracker


def town_episode(seed: int, setup: TownSetup, control: str) -> TownEpisode:
    """``TownEnv._reset`` of seed ``seed`` (the reference's ``HighwayBackend.reset(seed)``) as
    arrays: see the module docstring for the draws, made by ``_town_rows`` in one compiled call.

    :param setup: the road's TownSetup.
    :param control: "meta" (an MDPVehicle ego: CONTROLLED, routed) or "continuous" (a kinematic
        Vehicle: PLAIN, no route).
    """
    seed = int(seed)
    if 0 <= seed < 2**63:  # gymnasium's PCG64(SeedSequence(seed)), its words made compiled
        words = pcg64.seeded_states(seed)[0]
    else:  # gymnasium's own error for a bad seed, or a seed too wide for the compiled words
        words = pcg64.state_of(seeding.np_random(seed)[0])
    arrays, geometry = setup.arrays, setup.geometry
    kind = ego_kind(control)
    vehicles = np.zeros((1 + setup.vehicles_count, T.TOWN_VEHICLE_COLUMNS))
    pedestrians = np.zeros((setup.pedestrians_count, R.PEDESTRIAN_COLUMNS))
    offsets = np.empty(arrays.junction_count)
    ego_route = np.empty(arrays.routes.shape[2] + 1, dtype=np.int64)
    ambiguous = np.zeros(len(vehicles), dtype=bool)
    target_speed = setup.ego_target_speed if kind == T.CONTROLLED else 0.0
    road = setup.road
    count, route_size = _town_rows(
        words, road.table.rows, arrays.street_lanes, setup.fixed if setup.fixed_routes else _NO_FIXED,
        arrays.routes, arrays.route_length, arrays.crossings, setup.across, setup.cycle_s, kind,
        setup.ego_start_speed, target_speed, road.ego_length, road.ego_width, road.npc_length,
        road.npc_width, road.lane_change_delay, road.idm_delta, vehicles, pedestrians, offsets, ego_route,
        ambiguous,
    )  # fmt: skip
    for row in np.flatnonzero(ambiguous[:count]):  # lanes within 1e-6: numpy's distances decide
        lane = geometry.closest_lane(vehicles[row, T.X : T.Y + 1].copy(), vehicles[row, T.HEADING])
        vehicles[row, T.LANE] = lane
        if row == 0:
            vehicles[row, T.TARGET_LANE] = lane
    ego_route = ego_route[:route_size].copy()

    limit = np.inf
    if setup.timed_routes:  # HighwayBackend.reset: (route length - progress) at 10 km/h, + 10 s
        from drivelab.sim.reference.highway import ROUTE_TIMEOUT_MPS

        route = route_tracker(setup, ego_route)
        progress = route.project(vehicles[0, T.X : T.Y + 1])
        limit = (route.length_m - progress) / ROUTE_TIMEOUT_MPS + ROUTE_TIMEOUT_EXTRA_S
    return TownEpisode(
        vehicles=vehicles[:count], ego=0, pedestrians=pedestrians, light_offsets_s=offsets,
        ego_route=ego_route, route_time_limit_s=float(limit), rng_state=words,
    )  # fmt: skip


TRACKER_CACHE_SIZE = 4096  # routes whose trackers a set-up keeps (a retargeted ego's grow without end)
_NO_FIXED = np.zeros((0, 2), dtype=np.int64)


@njit(cache=True)
def _place(row, lanes, x, y, heading, speed, idm_delta) -> bool:
    """``vehicle_row``'s common part: pose, speed, the closest lane (compiled distances; True when
    another lane is within 1e-6 of it, for numpy's distances to decide), DELTA, collisions."""
    row[T.X], row[T.Y], row[T.HEADING], row[T.SPEED] = x, y, heading, speed
    distances = lane_distances(lanes, x, y, heading)
    best = int(np.argmin(distances))
    near = 0
    for lane in range(distances.shape[0]):
        if distances[lane] <= distances[best] + 1e-6:
            near += 1
    row[T.LANE] = row[T.TARGET_LANE] = best
    row[T.DELTA], row[T.CHECK_COLLISIONS] = idm_delta, 1.0
    return near > 1


@njit(cache=True)
def _write_route_rows(row, route, n) -> None:
    """A planned route into a vehicle row: roads (one lane each: the road row is the lane row),
    lane id 0, ROUTED."""
    if n > (row.shape[0] - T.ROUTE) // 2:
        raise ValueError("a town route is longer than the vehicle row's route capacity")
    row[T.ROUTED], row[T.ROUTE_START], row[T.ROUTE_END] = 1.0, 0.0, n
    for k in range(n):
        row[T.ROUTE + 2 * k], row[T.ROUTE + 2 * k + 1] = route[k], 0.0


@njit(cache=True)
def _town_rows(
    words, lanes, streets, fixed, routes, route_length, crossings, across, cycle_s, kind, ego_speed,
    ego_target_speed, ego_length, ego_width, npc_length, npc_width, delay, idm_delta,
    vehicles, peds, offsets, ego_route, ambiguous,
):  # fmt: skip
    """``town_episode``'s draws and rows (see the module docstring), on the PCG64 ``words``:
    fills the zeroed ``vehicles`` (ego, then NPCs), ``peds``, ``offsets`` and ``ego_route``;
    ``ambiguous[i]``: row i's closest lane is to be decided by numpy. Returns (vehicle count,
    ego route length). ``fixed``: NoCrash's routes, or (0, 2) for random ones."""
    for j in range(offsets.shape[0]):
        offsets[j] = pcg64.uniform(words, 0.0, cycle_s)
    if fixed.shape[0]:
        pick = pcg64.bounded_int(words, fixed.shape[0])
        start, goal = streets[fixed[pick, 0]], fixed[pick, 1]
    else:
        start = streets[pcg64.bounded_int(words, streets.shape[0])]
        goal = random_goal(lanes, start, streets, route_length, words)
    route_size = route_length[start, goal] if goal >= 0 else 1
    if goal >= 0:
        ego_route[:route_size] = routes[start, goal, :route_size]
    else:
        ego_route[0] = start
    longitudinal = pcg64.uniform(words, 5.0, max(lanes[start, L.LENGTH] - 20.0, 5.0))
    ego = vehicles[0]
    x, y = L.position(lanes, start, longitudinal, 0.0)  # LaneGeometry.position's order
    ambiguous[0] = _place(ego, lanes, x, y, lanes[start, L.HEADING], ego_speed, idm_delta)
    ego[T.KIND], ego[T.LEN], ego[T.WID] = kind, ego_length, ego_width
    if kind == T.CONTROLLED:  # an MDPVehicle: the allowed speed nearest its own; its route
        ego[T.TARGET_SPEED] = ego_target_speed
        _write_route_rows(ego, ego_route, route_size)
    count = 1
    for _ in range(vehicles.shape[0] - 1):
        placed = False
        for _ in range(PLACEMENT_TRIES):
            lane = streets[pcg64.bounded_int(words, streets.shape[0])]
            x, y = L.position(lanes, lane, pcg64.uniform(words, 5.0, lanes[lane, L.LENGTH] - 5.0), 0.0)
            nearest = np.inf
            for other in range(count):
                dx, dy = vehicles[other, T.X] - x, vehicles[other, T.Y] - y
                nearest = min(nearest, np.sqrt(dx * dx + dy * dy))
            if nearest > NPC_SPACING_M:
                placed = True
                break
        if not placed:
            continue
        row = vehicles[count]
        speed = pcg64.uniform(words, 4.0, 8.0)
        ambiguous[count] = _place(row, lanes, x, y, lanes[lane, L.HEADING], speed, idm_delta)
        row[T.TIMER] = ((x + y) * np.pi) % delay  # IDMVehicle: (np.sum(position) * pi) % delay
        row[T.LEN], row[T.WID] = npc_length, npc_width
        row[T.KIND], row[T.TARGET_LANE], row[T.TARGET_SPEED] = T.TOWN, lane, lanes[lane, L.SPEED_LIMIT]
        random_route(vehicles, lanes, count, lane, streets, routes, route_length, words)
        row[T.DELTA] = pcg64.uniform(words, DELTA_RANGE[0], DELTA_RANGE[1])  # randomize_behavior
        count += 1

    for walker in peds:  # TownEnv._make_pedestrians and Pedestrian.__init__
        c = pcg64.bounded_int(words, crossings.shape[0])
        side = -1.0 if pcg64.bounded_int(words, 2) == 0 else 1.0  # choice([-1, 1])
        u = pcg64.uniform(words, -0.4, 0.4)
        along_x, along_y = -across[c, 1] * u * crossings[c, 4], across[c, 0] * u * crossings[c, 4]
        walker[R.P_PACE] = pcg64.uniform(words, 1.0, 1.6)
        walker[R.P_X] = crossings[c, 0] + along_x + side * PAVEMENT_M * across[c, 0]
        walker[R.P_Y] = crossings[c, 1] + along_y + side * PAVEMENT_M * across[c, 1]
        walker[R.P_HEADING], walker[R.P_SIDE] = crossings[c, 2], side
        walker[R.P_WAIT_S] = pcg64.uniform(words, 0.0, 2 * MEAN_WAIT_S)
        walker[R.P_CENTRE_X], walker[R.P_CENTRE_Y] = crossings[c, 0], crossings[c, 1]
        walker[R.P_ACROSS_X], walker[R.P_ACROSS_Y] = across[c, 0], across[c, 1]
        walker[R.P_CROSSING] = c
    return count, route_size


def spawn_town(seed: int, road, control: str) -> tuple[np.ndarray, int, np.ndarray, TownEpisode]:
    """The ``Scenario.spawn`` hook: ``(vehicle rows, ego row, regulation (2,) zeros, episode)``, the
    whole ``TownEpisode`` going on between steps."""
    episode = town_episode(seed, TownSetup.of(road), control)
    return episode.vehicles, episode.ego, np.zeros(2), episode
