"""The town's compiled pedestrian, light and wreck kernels (``sim/junctions/pedestrians.py``) against the
reference's own methods on the same state: ``light_state``, ``Pedestrian.walk`` / ``_gap_clear``,
``TownRoad._hit_pedestrians`` and ``TownRoad._clear_wrecks``.

Rows are read from a live reference ``TownEnv`` (``tests/envs/town_reference.py``); the kernel runs
on a copy, the reference method on its objects, and the rows read again must agree: discrete
columns (side, crashed, hit by the ego, crossing, walking or waiting, vehicle count and ego row)
equal, floats within 1e-9 (the reference still computes some norms and dots with numpy/BLAS, whose
summation may be fused differently from the kernel's scalar arithmetic: last-bit differences).

A pedestrian's wait is drawn as the contract's ``MEAN_WAIT_S * standard_exponential(method="inv")``:
the reference's pedestrians get a generator wrapper (``InverseWaits``) that draws so from the
env's generator, whichever of ``exponential(scale)`` or ``standard_exponential`` the reference calls.
The generator's state after each walk must equal the kernel's words.

Pinned cases make each event happen and assert that the reference shows it: a pedestrian waiting
for a gap, then crossing, then drawing a wait on the far pavement; hits by the ego and by an NPC
(and near misses); a wreck towed on its 101st frame.
"""

from __future__ import annotations

import functools

import numpy as np
import pytest
from highway_env.road.road import Road

from drivelab.sim.core import pcg64
from drivelab.sim.core import traffic as T
from drivelab.sim.junctions import rows as R
from drivelab.sim.junctions.pedestrians import (
    clear_wrecks,
    gap_clear,
    hit_pedestrians,
    light_states,
    walk_pedestrians,
)
from drivelab.sim.junctions.rules import (
    CROSSING_CLEAR_M,
    MOVING_MPS,
    PAVEMENT_M,
    LightTimings,
    light_state,
)
from tests.envs.town_reference import reference_town, town_rows, town_tables

DT = 0.1
ATOL = 1e-9
PEDESTRIAN_DISCRETE = [R.P_SIDE, R.P_CRASHED, R.P_HIT_EGO, R.P_CROSSING]


class InverseWaits:
    """The env's generator, drawing pedestrian waits as the contract says:
    ``MEAN_WAIT_S * standard_exponential(method="inv")`` (scale × the same draw)."""

    def __init__(self, generator: np.random.Generator) -> None:
        self.generator = generator

    def exponential(self, scale: float) -> float:
        return scale * self.generator.standard_exponential(method="inv")

    def standard_exponential(self, *args, **kwargs):
        return self.generator.standard_exponential(*args, **kwargs)


@functools.cache
def tables(layout: str = "train") -> tuple:
    return town_tables(layout)


def town(traffic: str = "regular", seed: int = 0, layout: str = "train"):
    """A reset reference TownEnv whose pedestrians draw inverse-method waits."""
    env = reference_town(layout, traffic, seed).env.unwrapped
    for walker in env.road.pedestrians:
        walker.rng = InverseWaits(env.np_random)
    return env


def rows(env) -> tuple[np.ndarray, np.ndarray, int]:
    return town_rows(env, *tables(env.config["layout"]))


def assert_pedestrians_equal(ours: np.ndarray, theirs: np.ndarray) -> None:
    assert ours.shape == theirs.shape
    np.testing.assert_array_equal(ours[:, PEDESTRIAN_DISCRETE], theirs[:, PEDESTRIAN_DISCRETE])
    np.testing.assert_array_equal(ours[:, R.P_SPEED] == 0.0, theirs[:, R.P_SPEED] == 0.0)  # waiting
    np.testing.assert_allclose(ours, theirs, rtol=0.0, atol=ATOL)


def assert_vehicles_equal(ours: np.ndarray, theirs: np.ndarray) -> None:
    assert ours.shape == theirs.shape
    discrete = [T.CRASHED, T.LANE, T.KIND, T.ROUTE_END]
    np.testing.assert_array_equal(ours[:, discrete], theirs[:, discrete])
    np.testing.assert_allclose(ours, theirs, rtol=0.0, atol=ATOL)


def walk_both(env) -> tuple[np.ndarray, np.ndarray]:
    """One walk of every pedestrian by the kernel (on rows) and by the reference; returns the
    (pedestrian rows before, after) and asserts that they and the generators agree."""
    vehicles, peds, _ = rows(env)
    before = peds.copy()
    words = pcg64.state_of(env.np_random)
    walk_pedestrians(peds, peds.shape[0], vehicles, vehicles.shape[0], DT, words)
    for walker in env.road.pedestrians:
        walker.walk(DT, env.road.vehicles)
    assert_pedestrians_equal(peds, rows(env)[1])
    np.testing.assert_array_equal(words, pcg64.state_of(env.np_random))
    return before, peds


def hit_both(env) -> np.ndarray:
    """``_hit_pedestrians`` by the kernel and the reference; returns the pedestrian rows after."""
    vehicles, peds, ego = rows(env)
    hit_pedestrians(peds, peds.shape[0], vehicles, vehicles.shape[0], ego)
    env.road._hit_pedestrians()
    theirs_vehicles, theirs_peds, _ = rows(env)
    assert_pedestrians_equal(peds, theirs_peds)
    assert_vehicles_equal(vehicles, theirs_vehicles)
    return peds


def clear_both(env) -> int:
    """``_clear_wrecks`` by the kernel and the reference; returns the vehicle count after."""
    vehicles, _, ego = rows(env)
    count, new_ego = clear_wrecks(vehicles, vehicles.shape[0], ego, DT)
    env.road._clear_wrecks(DT)
    theirs, _, theirs_ego = rows(env)
    assert (count, new_ego) == (theirs.shape[0], theirs_ego)
    assert_vehicles_equal(vehicles[:count], theirs)
    assert not vehicles[count:].any()  # freed rows are zeros
    return count


# --- lights -------------------------------------------------------------------------------------


@pytest.mark.parametrize("timings", [LightTimings(), LightTimings(7.0, 2.5, 1.5)])
def test_light_states_match_light_state(timings):
    """Every light row over a fine time grid (the env's accumulated clock), and at and next to
    every phase boundary, with random offsets and offsets 0: the states are light_state's."""
    _, arrays = tables("train")
    junction, arm = arrays.light_junction, arrays.light_arm
    rng = np.random.default_rng(4)
    offsets = rng.uniform(0.0, timings.cycle_s, size=arrays.junction_count)
    offsets[:2] = 0.0
    times = list(np.cumsum(np.full(600, 0.2)))  # 0.2, 0.4, ... accumulated as env.time is
    half = timings.green_s + timings.yellow_s + timings.all_red_s
    for offset in offsets:
        for start in (0.0, half, timings.cycle_s, 3 * timings.cycle_s):
            for edge in (0.0, timings.green_s, timings.green_s + timings.yellow_s, half):
                t = offset + start + edge
                times += [np.nextafter(t, -np.inf), t, np.nextafter(t, np.inf)]
    out = np.empty(len(arm), dtype=np.int64)
    seen = set()
    for t in times:
        light_states(junction, arm, offsets, timings.green_s, timings.yellow_s, timings.all_red_s, t, out)
        expected = [light_state(timings, int(k), t, offsets[j]) for j, k in zip(junction, arm, strict=True)]
        assert out.tolist() == expected, t
        seen.update(expected)
    assert seen == {0, 1, 2}


# --- pedestrians walking ------------------------------------------------------------------------


def test_gap_clear_matches_reference():
    """``_gap_clear`` against one to three vehicles placed at random around a crossing (every
    distance band, facing or not, standing or moving): the kernel's answers are the reference's,
    and every branch answers both ways."""
    env = town("regular", 3)
    walker, others = env.road.pedestrians[0], env.road.vehicles[:3]
    _, peds, _ = rows(env)
    rng = np.random.default_rng(0)
    outcomes = {"near": set(), "facing band": set(), "far": set()}
    for case in range(3000):
        chosen = others[: 1 + case % 3]
        vehicles = np.zeros((len(chosen), T.TOWN_VEHICLE_COLUMNS))
        for row, vehicle in zip(vehicles, chosen, strict=True):
            angle, radius = rng.uniform(-np.pi, np.pi), rng.uniform(0.0, 30.0)
            vehicle.position = walker.centre + radius * np.array([np.cos(angle), np.sin(angle)])
            # facing the crossing (± 60°) half of the time
            toward = angle + np.pi + rng.uniform(-1.0, 1.0)
            vehicle.heading = toward if rng.random() < 0.5 else rng.uniform(-np.pi, np.pi)
            vehicle.speed = float(rng.choice([0.0, -0.5, 1.0, 4.0, 9.0]))
            row[T.X], row[T.Y] = vehicle.position
            row[T.HEADING], row[T.SPEED] = vehicle.heading, vehicle.speed
        expected = walker._gap_clear(chosen)
        assert gap_clear(peds, 0, vehicles, len(chosen)) == expected, case
        if len(chosen) == 1:
            distance = np.linalg.norm(walker.centre - chosen[0].position)
            band = "near" if distance < CROSSING_CLEAR_M else "facing band" if distance < 15.0 else "far"
            outcomes[band].add(expected)
    assert outcomes == {"near": {False}, "facing band": {False, True}, "far": {False, True}}


def test_walk_waits_for_a_gap_crosses_and_draws_a_wait():
    """Pinned story of pedestrian 0 (the others walk too): its wait runs out while a vehicle
    stands next to its crossing, so it waits for the gap; once the vehicle is gone it crosses at
    its pace, and on the far pavement it turns round and draws its next wait. Every frame the
    kernel's rows and generator equal the reference's."""
    env = town("regular", 5)
    road = env.road
    ego, blocker = road.vehicles[0], road.vehicles[1]
    road.vehicles[:] = [ego, blocker]  # the others would block the crossings at random
    walker = road.pedestrians[0]
    street = np.array([-walker.across[1], walker.across[0]])
    blocker.position, blocker.speed = walker.centre + 5.0 * street, 0.0
    ego.position = walker.centre + 200.0 * street
    walker.wait_s, side = 0.25, walker.side
    rng = np.random.default_rng(1)
    for other in road.pedestrians[1:]:
        other.wait_s = float(rng.uniform(0.0, 3.0))
    waited = started = arrived = None
    draws = 0
    for frame in range(160):
        if frame == 30:
            blocker.position = walker.centre + 150.0 * street  # the gap opens
        before, after = walk_both(env)
        draws += int(np.sum((before[:, R.P_SPEED] > 0) & (after[:, R.P_SPEED] == 0)))
        if waited is None and walker.wait_s <= 0.0 and walker.speed == 0.0:
            waited = frame
        if started is None and walker.speed > 0.0:
            started = frame
        if arrived is None and started is not None and walker.speed == 0.0:
            arrived = (
                frame,
                walker.side,
                walker.wait_s,
                np.dot(walker.position - walker.centre, walker.across),
            )
    # the reference shows the events, in order
    assert waited == 2 and started == 30, (waited, started)
    assert arrived is not None and arrived[0] > started
    _, new_side, drawn_wait_s, across_m = arrived
    assert new_side == -side and drawn_wait_s > 0.0
    assert PAVEMENT_M <= side * -across_m < PAVEMENT_M + 0.2  # on the far pavement
    assert draws >= 5  # other pedestrians reached their far pavement too


def test_crashed_pedestrians_stand_still():
    env = town("regular", 2)
    for walker in env.road.pedestrians[:4]:
        walker.crashed, walker.speed, walker.wait_s = True, 1.3, -1.0
    before, after = walk_both(env)
    assert (after[:4, R.P_SPEED] == 0).all()
    np.testing.assert_array_equal(
        after[:4, [R.P_X, R.P_Y, R.P_WAIT_S]], before[:4, [R.P_X, R.P_Y, R.P_WAIT_S]]
    )


# --- pedestrian hits ----------------------------------------------------------------------------


def test_hits_by_the_ego_and_an_npc():
    """Pinned: pedestrian 0 just in front of the moving ego, 1 in front of a moving NPC, 2 in front
    of an NPC rolling at MOVING_MPS (not moving), 3 beside an NPC inside the reach but outside its
    box, 4 in front of two moving NPCs (the first in list order hits it). The reference marks
    exactly 0 (by the ego), 1 and 4 (by NPCs), and the kernel agrees."""
    env = town("dense", 1)
    road = env.road
    ego, npcs, walkers = road.ego, road.vehicles[1:], road.pedestrians
    for vehicle in road.vehicles:  # everyone far apart first
        vehicle.position = vehicle.position + np.array([1000.0, 0.0]) * road.vehicles.index(vehicle)
        vehicle.speed = 0.0
    for walker in walkers:
        walker.position = walker.position + np.array([0.0, 5000.0])

    def place(walker, vehicle, ahead_m, side_m=0.0):
        walker.position = (
            vehicle.position
            + ahead_m * vehicle.direction
            + side_m * np.array([-vehicle.direction[1], vehicle.direction[0]])
        )
        walker.heading = vehicle.heading  # square to the vehicle's box: the near misses are clear

    ego.speed, npcs[0].speed, npcs[1].speed, npcs[2].speed = 4.0, 6.0, MOVING_MPS, 3.0
    npcs[3].speed, npcs[4].speed = 5.0, 2.0
    npcs[4].position = npcs[3].position + 0.5 * npcs[3].direction
    npcs[4].heading = npcs[3].heading
    place(walkers[0], ego, 2.7)
    place(walkers[1], npcs[0], 2.6, 0.5)
    place(walkers[2], npcs[1], 2.5)
    place(walkers[3], npcs[2], 1.0, 1.45)  # inside (diagonals)/2 ≈ 3.1 m, outside the 1 m half width
    place(walkers[4], npcs[3], 2.0)
    peds = hit_both(env)
    assert walkers[0].crashed and walkers[0].hit_by is ego and ego.crashed
    assert walkers[1].crashed and walkers[1].hit_by is npcs[0] and npcs[0].crashed
    assert not walkers[2].crashed and not npcs[1].crashed
    assert not walkers[3].crashed and not npcs[2].crashed
    assert walkers[4].crashed and walkers[4].hit_by is npcs[3] and not npcs[4].crashed
    assert peds[:5, R.P_HIT_EGO].tolist() == [1.0, 0.0, 0.0, 0.0, 0.0]
    assert walkers[0] not in road.objects  # taken off the street
    hit_both(env)  # hit pedestrians are not hit again


def test_hits_match_reference_at_random():
    """Pedestrians scattered around the vehicles of a dense town (within a few metres, random
    headings and speeds): the kernel marks the same pedestrians and vehicles as the reference."""
    env = town("dense", 7)
    road = env.road
    rng = np.random.default_rng(3)
    hits = 0
    for _ in range(40):
        for vehicle in road.vehicles:
            vehicle.crashed = False
            vehicle.speed = float(rng.choice([0.0, 0.5, 0.51, 3.0, 8.0]))
            vehicle.heading = float(rng.uniform(-np.pi, np.pi))
        road.objects[:] = list(road.pedestrians)
        for walker in road.pedestrians:
            walker.crashed, walker.hit_by = bool(rng.random() < 0.1), None
            near = road.vehicles[rng.integers(len(road.vehicles))]
            walker.position = near.position + rng.uniform(-3.5, 3.5, size=2)
            walker.heading = float(rng.uniform(-np.pi, np.pi))
        before = sum(w.crashed for w in road.pedestrians)
        hit_both(env)
        hits += sum(w.crashed for w in road.pedestrians) - before
    assert hits > 50


# --- wrecks -------------------------------------------------------------------------------------


def test_wrecks_towed_on_frame_101():
    """Crashed NPCs (one of them before the ego's row, one crashing 5 frames later) are towed on
    their 101st frame at dt 0.1 (100 × 0.1 < 10 in floating point), the rows closing up and the
    ego's row following; the crashed ego stays."""
    env = town("regular", 4)
    road = env.road
    ego = road.ego
    road.vehicles.remove(ego)
    road.vehicles.insert(5, ego)
    first, second = road.vehicles[2], road.vehicles[8]
    first.crashed = ego.crashed = True
    count = len(road.vehicles)
    towed = {}
    for frame in range(1, 112):
        if frame == 6:
            second.crashed = True
        new_count = clear_both(env)
        for vehicle in (first, second):
            if vehicle not in road.vehicles and vehicle not in towed.values():
                towed[frame] = vehicle
        assert new_count == len(road.vehicles)
    assert towed == {101: first, 106: second}
    assert ego in road.vehicles and road.vehicles.index(ego) == 4 and len(road.vehicles) == count - 2


# --- whole frames -------------------------------------------------------------------------------


@pytest.mark.parametrize(("layout", "traffic", "seed"), [("train", "regular", 11), ("test", "dense", 2)])
def test_frames_match_reference(layout, traffic, seed):
    """Reference frames (act, walk, step, hits, wrecks; the ego speeding up): at each stage the
    kernel, given the reference's rows, gives the reference's next rows and generator state."""
    env = town(traffic, seed, layout)
    road = env.road
    for walker in road.pedestrians:  # let them start crossing within the episode
        walker.wait_s = min(walker.wait_s, 1.5)
    walking = 0
    for frame in range(24):
        if frame % 2 == 0:
            env.action_type.act(3)  # FASTER
            env.time += 2 * DT
        road.act()
        _, after = walk_both(env)
        walking += int((after[:, R.P_SPEED] > 0).sum())
        Road.step(road, DT)
        hit_both(env)
        clear_both(env)
    assert walking > 0 and env.vehicle.speed > 1.0
