"""The town's vehicle kernels (``sim/junctions/traffic.py``) against the reference town (L1).

A reference town (``TownEnv`` through ``HighwayBackend``) is read into compiled rows
(``tests/envs/town_reference.py``); its ``road.act()`` and the kernels' ``town_act`` then run on the
same state and must give the same controls, target lanes and speeds, routes and generator state.

Tolerance: the kernels do the reference's arithmetic in its order, but highway-env's numpy calls
round differently from libm where numpy dispatches to its own SIMD kernels (AVX-512 ``np.power``
differs from libm's ``pow`` by an ULP in ~5 % of calls on this CPU) and where the reference takes
``np.linalg.norm`` (BLAS) of a 2-vector. Single-act comparisons therefore allow ``ATOL`` = 1e-9 on
accelerations and steering (an ULP is 1e-16; a modelling error, such as a gap measured along the
lane instead of straight, moves them by 1e-2 or more), and discrete columns must be equal. Over
frames, a slow vehicle's steering amplifies an ULP (it divides by the speed), so the frame runs
re-read the reference's state each frame; the subprocess test lets the kernels run free for 60
steps with numpy's AVX-512 dispatch off and the reference's norm taken as scalars (as part C's
``town_env.py`` does) and requires bit-for-bit equality.
"""

from __future__ import annotations

import math
from collections import Counter

import numpy as np
import pytest
from highway_env.vehicle.behavior import IDMVehicle

from drivelab.scenarios.town.reference_env import Pedestrian, TownVehicle
from drivelab.scenarios.town.road import approach_of
from drivelab.sim.core import lanes as L
from drivelab.sim.core import pcg64
from drivelab.sim.core import traffic as T
from drivelab.sim.core.simulator import idm_parameters
from drivelab.sim.junctions import traffic as TT
from drivelab.sim.junctions.rows import P_CRASHED, P_X, P_Y, PEDESTRIAN_COLUMNS
from drivelab.world.state import LIGHT_GREEN, LIGHT_RED, LIGHT_YELLOW
from tests.envs.town_reference import reference_town, town_rows, town_tables
from tests.sim.test_fast import run_without_avx512

ATOL = 1e-9
DT = 0.1
CONTROLS = [T.ACCEL, T.STEER]
POSE = [T.X, T.Y, T.HEADING, T.SPEED]
DISCRETE = [T.LANE, T.TARGET_LANE, T.TARGET_SPEED, T.CRASHED, T.ROUTED, T.TIMER, T.KIND]
BEHAVIOURS = (
    "red_stop", "yellow_stop", "yellow_go", "left_turn_wait", "turn_speed", "route_draw",
    "pedestrian_leader", "connected_leader",
)  # fmt: skip


def town(layout: str, traffic: str, seed: int, ego_speed: float = 9.0, control: str = "meta"):
    """A reset reference town whose ego drives (its meta-action target speed is ``ego_speed``, so
    that it is oncoming traffic for left turns too), with every other pedestrian standing on the
    lane next to its pavement (a leader for the vehicles) and pedestrian 1 hit: crashed and off
    ``road.objects``, so no leader any more, as ``TownRoad._hit_pedestrians`` leaves it. Every
    third town vehicle's route is cut to its first lane, as it is once driven down to it: the
    vehicle draws a new random route in its next act. Town vehicle 2 has crashed (it still sets its
    target speed, then acts no more, and brakes to a stop)."""
    env = reference_town(layout, traffic, seed, control).env.unwrapped
    if control == "meta":
        env.vehicle.target_speed = ego_speed
    else:  # the continuous ego keeps its last action: a steady throttle
        env.vehicle.speed, env.vehicle.action = ego_speed, {"steering": 0.0, "acceleration": 1.0}
    for k, walker in enumerate(env.road.pedestrians):
        if k % 2 == 0 or k == 1:
            walker.position = walker.centre + 2.0 * walker.side * walker.across
        if k == 1:
            walker.crashed = True
            env.road.objects.remove(walker)
    for k, vehicle in enumerate(env.road.vehicles):
        if type(vehicle) is TownVehicle and k % 3 == 1:
            vehicle.route = vehicle.route[:1]
    env.road.vehicles[2].crashed = True
    return env


def light_states(env) -> np.ndarray:
    """(M,) LIGHT_* of every light row at ``env.time`` (the reference's clock)."""
    lights = env.road.lights
    return np.array([lights.state(j, k, env.time) for j, k in lights.approaches], dtype=np.int64)


class Kernels:
    """``town_act`` / ``town_step`` on one world's arrays, with the frame cache made once."""

    def __init__(self, layout: str, vehicles: int, pedestrians: int) -> None:
        self.table, self.arrays = town_tables(layout)
        self.road = TT.road_arrays_tuple(self.arrays, self.table.rows)
        self.p = idm_parameters()
        self.cache = TT.town_frame_cache(vehicles, pedestrians, self.table.rows.shape[0])

    def rows(self, env):
        vehicles, pedestrians, _ = town_rows(env, self.table, self.arrays)
        return vehicles, pedestrians, pcg64.state_of(env.np_random)

    def act(self, v, peds, states, words) -> None:
        coords, done, trig = self.cache
        lanes = self.table.rows
        TT.town_act(v, len(v), peds, len(peds), lanes, self.p, coords, done, trig, *self.road, states, words)

    def step(self, v) -> None:
        TT.town_step(v, len(v), self.table.rows, DT)


def remaining_routes(rows: np.ndarray) -> list[tuple]:
    """Each row's route entries still to drive (the reference pops driven ones, the rows move
    ROUTE_START instead)."""
    return [
        tuple(row[T.ROUTE + 2 * int(row[T.ROUTE_START]) : T.ROUTE + 2 * int(row[T.ROUTE_END])])
        for row in rows
    ]


def assert_rows_match(reference: np.ndarray, mine: np.ndarray, continuous: list, atol: float) -> None:
    assert reference.shape == mine.shape
    np.testing.assert_allclose(mine[:, continuous], reference[:, continuous], rtol=0, atol=atol)
    np.testing.assert_array_equal(mine[:, DISCRETE], reference[:, DISCRETE])
    assert remaining_routes(mine) == remaining_routes(reference)


def leaders(env) -> Counter:
    """How many town vehicles have a pedestrian, or a vehicle on another lane, as the leader
    ``Road.neighbour_vehicles`` finds on their lane (before the act: positions do not change)."""
    seen = Counter()
    road = env.road
    for vehicle in road.vehicles:
        if type(vehicle) is TownVehicle and not vehicle.crashed:
            front, _ = road.neighbour_vehicles(vehicle, vehicle.lane_index)
            if isinstance(front, Pedestrian):
                seen["pedestrian_leader"] += 1
            elif front is not None and front.lane_index != vehicle.lane_index:
                seen["connected_leader"] += 1
    return seen


def decisions(env, routes_before: dict) -> Counter:
    """What the reference's town vehicles decided in the act just run: stops at red, at yellow,
    going through yellow, waiting at green for a left turn, slowing for a turn, new routes."""
    seen = Counter()
    for vehicle in env.road.vehicles:
        if type(vehicle) is not TownVehicle:
            continue
        seen["route_draw"] += vehicle.route is not routes_before[id(vehicle)]
        seen["turn_speed"] += vehicle.target_speed < vehicle.lane.speed_limit
        approach = approach_of(vehicle.lane_index)
        state = env.road.lights.state(*approach, env.time) if approach else None
        s = vehicle.lane.local_coordinates(vehicle.position)[0]
        if state is None or vehicle.crashed or vehicle.lane.length - s - vehicle.LENGTH / 2 < 0:
            continue
        stops = vehicle.stop_line_ahead() is not None
        seen["red_stop"] += state == LIGHT_RED and stops
        seen["yellow_stop"] += state == LIGHT_YELLOW and stops
        seen["yellow_go"] += state == LIGHT_YELLOW and not stops
        seen["left_turn_wait"] += state == LIGHT_GREEN and stops
    return seen


def reference_act(env) -> Counter:
    """One ``road.act()`` of the reference; the behaviours it showed."""
    seen = leaders(env)
    routes_before = {id(vehicle): getattr(vehicle, "route", None) for vehicle in env.road.vehicles}
    env.road.act()
    return seen + decisions(env, routes_before)


SINGLE_ACT_CASES = [
    ("train", "regular", 0, 0.0, "meta"),
    ("train", "regular", 5, 7.3, "meta"),
    ("train", "dense", 1, 11.0, "meta"),
    ("train", "dense", 2, 26.9, "meta"),
    ("test", "regular", 3, 0.0, "meta"),
    ("test", "regular", 4, 12.4, "meta"),
    ("test", "dense", 5, 3.1, "meta"),
    ("test", "dense", 6, 20.0, "meta"),
    ("train", "dense", 7, 5.0, "continuous"),
    ("test", "regular", 8, 15.5, "continuous"),
]


@pytest.mark.parametrize("layout, traffic, seed, time_s, control", SINGLE_ACT_CASES)
def test_one_act_matches_the_reference(layout, traffic, seed, time_s, control):
    """One frame's act from a reset town (lights at ``time_s``; a meta-action or a continuous
    ego): every vehicle's controls, target lane and speed and route, and the generator after the
    route draws."""
    env = town(layout, traffic, seed, control=control)
    env.time = time_s
    kernels = Kernels(layout, len(env.road.vehicles), len(env.road.pedestrians))
    v, peds, words = kernels.rows(env)
    kernels.act(v, peds, light_states(env), words)
    reference_act(env)
    reference, _, _ = kernels.rows(env)
    assert_rows_match(reference, v, CONTROLS, ATOL)
    np.testing.assert_array_equal(words, pcg64.state_of(env.np_random))


def run_frames(layout: str, traffic: str, seed: int, steps: int) -> Counter:
    """``steps`` policy steps of 2 frames (lights read at the step's end time, as
    ``HighwayBackend.step`` advances the clock first): the reference's act then its vehicles'
    ``step`` (pedestrians stand still, no collision pass), against ``town_act`` then ``town_step``
    from the reference's state of that frame. Returns the behaviours the reference showed."""
    env = town(layout, traffic, seed)
    kernels = Kernels(layout, len(env.road.vehicles), len(env.road.pedestrians))
    seen = Counter()
    for step in range(steps):
        env.time = (step + 1) * 2 * DT
        states = light_states(env)
        for _ in range(2):
            v, peds, words = kernels.rows(env)
            kernels.act(v, peds, states, words)
            seen += reference_act(env)
            reference, _, _ = kernels.rows(env)
            assert_rows_match(reference, v, CONTROLS, ATOL)
            np.testing.assert_array_equal(words, pcg64.state_of(env.np_random))
            v[:, CONTROLS] = reference[:, CONTROLS]  # step both from the same controls
            for vehicle in env.road.vehicles:
                vehicle.step(DT)
            kernels.step(v)
            reference, _, _ = kernels.rows(env)
            assert_rows_match(reference, v, POSE, ATOL)
    return seen


# (layout, traffic, seed, steps): pinned so that between them the reference shows every behaviour
FRAME_CASES = [
    ("train", "dense", 0, 60),
    ("test", "regular", 2, 60),
    ("train", "regular", 3, 60),
    ("train", "dense", 3, 120),  # going through on yellow is rare: three such moments in these runs
]


def test_frames_match_the_reference_and_cover_every_behaviour():
    """Frame after frame, act and step agree with the reference; the pinned runs show every town
    behaviour (so that a change of the reference or of the seeds cannot make one vanish)."""
    seen = Counter()
    for case in FRAME_CASES:
        seen += run_frames(*case)
    missing = [name for name in BEHAVIOURS if seen[name] == 0]
    assert not missing, f"the pinned runs no longer show {missing}: {dict(seen)}"


def scalar_lane_distance_to(self, other, lane=None) -> float:
    """``TownVehicle.lane_distance_to`` with the norm as scalars (part C's reference change)."""
    along = IDMVehicle.lane_distance_to(self, other, lane)
    dx, dy = other.position[0] - self.position[0], other.position[1] - self.position[1]
    return math.copysign(math.sqrt(dx * dx + dy * dy), along)


def free_run(layout: str, traffic: str, seed: int, steps: int) -> float:
    """The kernels run on their own rows for ``steps`` policy steps next to the reference; the
    largest difference over every frame (continuous columns), discrete columns and generator
    states being equal throughout. The reference measures gaps as part C's does (scalar norm)."""
    original = TownVehicle.lane_distance_to
    TownVehicle.lane_distance_to = scalar_lane_distance_to
    try:
        return _free_run(layout, traffic, seed, steps)
    finally:
        TownVehicle.lane_distance_to = original


def _free_run(layout: str, traffic: str, seed: int, steps: int) -> float:
    env = town(layout, traffic, seed)
    kernels = Kernels(layout, len(env.road.vehicles), len(env.road.pedestrians))
    v, peds, words = kernels.rows(env)
    worst = 0.0
    for step in range(steps):
        env.time = (step + 1) * 2 * DT
        states = light_states(env)
        for _ in range(2):
            kernels.act(v, peds, states, words)
            reference_act(env)
            for vehicle in env.road.vehicles:
                vehicle.step(DT)
            kernels.step(v)
            reference, _, _ = kernels.rows(env)
            assert_rows_match(reference, v, POSE + CONTROLS, np.inf)
            np.testing.assert_array_equal(words, pcg64.state_of(env.np_random))
            worst = max(worst, float(np.abs(reference[:, POSE + CONTROLS] - v[:, POSE + CONTROLS]).max()))
    return worst


def test_without_avx512_dispatch_free_frames_agree_bit_for_bit():
    """60 steps of the kernels on their own state (no re-reading of the reference) agree with the
    reference exactly where numpy rounds like libm: the frame tolerance above is rounding only."""
    script = (
        "from tests.sim.test_town_kernels import free_run\n"
        "print(max(free_run('train', 'dense', 0, 60), free_run('test', 'regular', 2, 60)))\n"
    )
    assert float(run_without_avx512(script).split()[-1]) == 0.0


def _literal_front(v, peds, lanes, search, offset, size, i, lane) -> int:
    """The leader as ``neighbour_vehicles_connected_lanes`` scans for it: each object in order
    (vehicles, then pedestrians not crashed), placed on the first of the connected lanes it lies
    on; the nearest at or ahead of vehicle i, the last of equals."""
    count = len(v)
    s = L.local_coordinates(lanes, lane, v[i, T.X], v[i, T.Y])[0]
    front, s_front = -1, 0.0
    for j in range(count + len(peds)):
        if j == i or (j >= count and peds[j - count, P_CRASHED] > 0):
            continue
        x, y = (v[j, T.X], v[j, T.Y]) if j < count else (peds[j - count, P_X], peds[j - count, P_Y])
        for k in range(size[lane]):
            other = search[lane, k]
            s_j, r_j = L.local_coordinates(lanes, other, x, y)
            if L.on_lane(lanes, other, s_j, r_j, 1.0):
                if s <= s_j + offset[lane, k] and (front < 0 or s_j + offset[lane, k] <= s_front):
                    front, s_front = j, s_j + offset[lane, k]
                break
    return front


@pytest.mark.parametrize("layout", ["train", "test"])
def test_connected_front_is_the_literal_scan(layout):
    """``connected_front`` reads per-lane object lists made once per frame (only objects inside a
    lane's disc, and on a circular lane within its lateral reach, are measured); it must name the
    leader the literal scan names, for every vehicle and each of its connected lanes: objects
    scattered along and beside random lanes (many on two connected lanes at once), some at the
    very same spot as another (exact ties), and a crashed pedestrian."""
    table, arrays = town_tables(layout)
    lanes = table.rows
    search, offset, size, discs = TT.connected_lanes(lanes)
    rng = np.random.default_rng(7)
    checked = 0
    for _ in range(20):
        n, m = 16, 8
        points = []
        for _ in range(n + m):
            lane = int(rng.integers(len(lanes)))
            s = rng.uniform(-6.0, lanes[lane, L.LENGTH] + 6.0)
            points.append((lane, *L.position(lanes, lane, s, rng.uniform(-3.0, 3.0))))
        for a, b in rng.integers(n + m, size=(5, 2)):  # exact ties: one object where another is
            points[a] = points[b]
        v = np.zeros((n, T.TOWN_VEHICLE_COLUMNS))
        v[:, T.LANE] = [lane for lane, _, _ in points[:n]]
        v[:, T.X], v[:, T.Y] = [x for _, x, _ in points[:n]], [y for _, _, y in points[:n]]
        peds = np.zeros((m, PEDESTRIAN_COLUMNS))
        peds[:, P_X], peds[:, P_Y] = [x for _, x, _ in points[n:]], [y for _, _, y in points[n:]]
        peds[0, P_CRASHED] = 1.0
        coords = np.empty((len(lanes), n + m, 4))
        seen = np.full((len(lanes), n + m), -1, dtype=np.int8)
        near = np.empty((len(lanes), n + m), dtype=np.int64)
        near_count = np.full(len(lanes), -1, dtype=np.int64)
        for i in range(n):
            for lane in search[int(v[i, T.LANE]), : size[int(v[i, T.LANE])]]:
                got = TT.connected_front(
                    v, peds, lanes, coords, seen, near, near_count, search, offset, size, discs, i, int(lane)
                )
                assert got == _literal_front(v, peds, lanes, search, offset, size, i, int(lane))
                checked += got >= 0
    assert checked > 200  # most searches find a leader


def test_the_stop_line_reads_no_frame_cache():
    """``blocks_traffic`` calls ``town_acceleration`` without a leader on ``traffic``'s frame
    cache, whose per-object flags are not reset each frame (its ``done`` flags are per lane): the
    stop line's distance must not come from the cache. Every town vehicle's acceleration with a
    fresh cache equals the one with a cache full of stale values."""
    env = town("train", "dense", 3)
    env.time = 7.3
    kernels = Kernels("train", len(env.road.vehicles), len(env.road.pedestrians))
    v, peds, _ = kernels.rows(env)
    lanes, states = kernels.table.rows, light_states(env)
    coords, done, trig = (np.array(a, copy=True) for a in kernels.cache)
    T.start_frame(v, done, trig)
    stale = coords.copy()
    stale[..., :2], stale[..., 2] = 1e3, 1.0  # "measured, on the lane, 1 km along"
    coords[..., 2] = -1.0
    seen = {
        "fresh": np.full(coords.shape[:2], -1, dtype=np.int8),
        "stale": np.ones(coords.shape[:2], np.int8),
    }
    stops = 0
    for i in range(len(v)):
        if v[i, T.KIND] != T.TOWN:
            continue
        fresh_a, stale_a = (
            TT.town_acceleration(
                v, peds, lanes, kernels.p, cache, done, trig, seen[name], i, -1, *kernels.road[:7], states
            )
            for name, cache in (("fresh", coords), ("stale", stale))
        )
        assert fresh_a == stale_a
        stops += TT.stop_line_ahead(v, lanes, kernels.p, i, *kernels.road[:7], states) != TT.NO_STOP
    assert stops > 0  # some vehicles have a stop line to stop at
