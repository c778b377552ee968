"""The compiled core's town set-up (``scenarios.town.town_episode``) gives the reference's episode
bit for bit: the same vehicle rows, pedestrian rows, light offsets, ego route, NoCrash time limit
and generator state after ``TownEnv._reset`` (design memo §3, L2).

Every float is compared exactly (``array_equal``), on any CPU. The set-up's compiled part
(``_town_rows``) makes its floats with +, -, *, /, sqrt and % only, on the reference's operands in
the reference's order (every street is straight), and each of these is correctly rounded, so numba
and numpy (SIMD or not) give the same bits. The transcendental values come from numpy, as the
reference calls it: a crossing's cos / sin (``TownSetup.across``), and the route polyline and
``RouteTracker`` of the NoCrash time limit. Checked both ways: on this AVX-512 CPU, and with its
AVX-512 dispatch off (``test_fast.run_without_avx512``, regular and dense traffic, both layouts,
route modes and controls, 3 seeds), every array equal. A closest lane is shortlisted by compiled
distances and decided by numpy's wherever two lanes are within 1e-6.
"""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from drivelab.scenarios import SCENARIOS
from drivelab.scenarios.town.reference_env import fixed_routes
from drivelab.scenarios.town.spawn import TownSetup, spawn_town, town_episode
from drivelab.sim.core import pcg64
from drivelab.sim.core import traffic as T
from drivelab.sim.core.spawn import LaneGeometry
from tests.envs.town_reference import reference_town, town_rows, town_tables

SEEDS = (0, 1, 2, 3)
LAYOUTS = ("train", "test")
TRAFFIC = ("empty", "regular", "dense")
_TABLES: dict = {}


def rng_of(words: np.ndarray) -> np.random.Generator:
    """A numpy Generator in the state of an episode's PCG64 ``words``."""
    generator = np.random.Generator(np.random.PCG64())
    pcg64.set_state(generator, words)
    return generator


def tables(layout: str) -> tuple:
    """(LaneTable, TownRoadArrays) of a layout, built once per test session."""
    if layout not in _TABLES:
        _TABLES[layout] = town_tables(layout)
    return _TABLES[layout]


def town_road(backend, layout: str) -> SimpleNamespace:
    """The fields of the simulator's converted road that the town's set-up reads, taken from a
    reference backend (its config and vehicle classes)."""
    from highway_env.vehicle.behavior import IDMVehicle

    table, arrays = tables(layout)
    env = backend.env
    return SimpleNamespace(
        table=table,
        geometry=LaneGeometry(table),
        config=dict(env.config),
        target_speeds=np.asarray(getattr(env.action_type, "target_speeds", [0.0]), dtype=float),
        ego_length=float(env.vehicle.LENGTH),
        ego_width=float(env.vehicle.WIDTH),
        npc_length=float(IDMVehicle.LENGTH),
        npc_width=float(IDMVehicle.WIDTH),
        lane_change_delay=float(IDMVehicle.LANE_CHANGE_DELAY),
        idm_delta=float(IDMVehicle.DELTA),
        cache={"town_arrays": arrays},
    )


def compare_setups(layout: str, traffic: str, control: str, fixed: bool, seeds=SEEDS) -> list[int]:
    """Set up each seed both ways and assert everything equal. Returns the NPC counts placed."""
    config = {"fixed_routes": True, "retarget": False} if fixed else {}
    backend = reference_town(layout, traffic, seeds[0], control, **config)
    road = town_road(backend, layout)
    setup = TownSetup.of(road)
    table, arrays = tables(layout)
    placed = []
    for seed in seeds:
        backend.reset(seed)
        env = backend.env
        vehicles, pedestrians, ego = town_rows(env, table, arrays)
        episode = town_episode(seed, setup, control)
        message = f"{layout} {traffic} {control} fixed={fixed} seed {seed}"
        assert episode.vehicles.shape == vehicles.shape, message
        np.testing.assert_array_equal(episode.vehicles, vehicles, err_msg=message)
        assert episode.ego == ego == 0, message
        assert episode.pedestrians.shape == pedestrians.shape, message
        np.testing.assert_array_equal(episode.pedestrians, pedestrians, err_msg=message)
        np.testing.assert_array_equal(episode.light_offsets_s, env.road.lights.offsets_s, err_msg=message)
        route = [table.row_of[index] for index in env.ego_route]
        np.testing.assert_array_equal(episode.ego_route, route, err_msg=message)
        limit = np.inf if backend.route_time_limit_s is None else backend.route_time_limit_s
        assert episode.route_time_limit_s == limit, message
        np.testing.assert_array_equal(episode.rng_state, pcg64.state_of(env.np_random), err_msg=message)
        assert rng_of(episode.rng_state).bit_generator.state == env.np_random.bit_generator.state, message
        placed.append(len(vehicles) - 1)
    return placed


@pytest.mark.parametrize("layout", LAYOUTS)
@pytest.mark.parametrize("traffic", TRAFFIC)
@pytest.mark.parametrize("fixed", [False, True], ids=["retarget", "fixed_routes"])
def test_setup_gives_the_reference_episode_with_a_meta_ego(layout, traffic, fixed):
    compare_setups(layout, traffic, "meta", fixed)


@pytest.mark.parametrize("layout", LAYOUTS)
@pytest.mark.parametrize("traffic", TRAFFIC)
@pytest.mark.parametrize("fixed", [False, True], ids=["retarget", "fixed_routes"])
def test_setup_gives_the_reference_episode_with_a_continuous_ego(layout, traffic, fixed):
    """A kinematic ego: a PLAIN row without a route (the episode's route is still planned)."""
    compare_setups(layout, traffic, "continuous", fixed, seeds=SEEDS[:2])


def test_dense_test_town_skips_npcs_without_a_free_spot():
    """The 10 placement tries run out on the small test town at 30 NPCs (its 14 streets hold
    about 15 at 12 m spacing): the set-up skips those NPCs as the reference does."""
    placed = compare_setups("test", "dense", "meta", False, seeds=(0, 1))
    assert all(10 < count < 30 for count in placed)  # 14 and 14 of 30


@pytest.mark.parametrize("layout", LAYOUTS)
def test_fixed_routes_are_the_references(layout):
    """The 25 NoCrash routes from the route table equal ``town_env.fixed_routes`` of the network."""
    from drivelab.scenarios.town.road import LAYOUTS as TOWN_LAYOUTS
    from drivelab.scenarios.town.road import build_network

    backend = reference_town(layout, "empty", 0, "meta", fixed_routes=True, retarget=False)
    setup = TownSetup.of(town_road(backend, layout))
    table, arrays = tables(layout)
    network = build_network(TOWN_LAYOUTS[layout])
    expected = [(table.row_of[start], goal) for start, goal in fixed_routes(network)]
    got = [(int(arrays.street_lanes[a]), table.indices[arrays.street_lanes[b]][1]) for a, b in setup.fixed]
    assert got == expected and len(got) == 25
    assert len({tuple(pair) for pair in setup.fixed.tolist()}) > 1


def test_spawn_hook_returns_the_episode():
    """``Scenario.spawn``'s (rows, ego row, regulation, between-steps state) for the town: the
    vehicle rows and ego row of the TownEpisode, zeros, and the TownEpisode itself."""
    assert SCENARIOS["town"].spawn is spawn_town
    backend = reference_town("train", "regular", 5, "meta")
    road = town_road(backend, "train")
    rows, ego, regulation, episode = spawn_town(5, road, "meta")
    assert rows is episode.vehicles and ego == episode.ego == 0
    np.testing.assert_array_equal(regulation, np.zeros(2))
    assert rows.shape == (16, T.TOWN_VEHICLE_COLUMNS) and episode.pedestrians.shape[0] == 10
    assert TownSetup.of(road) is road.cache["town_setup"]  # built once per road
    again = spawn_town(5, road, "meta")[3]
    np.testing.assert_array_equal(again.rng_state, episode.rng_state)
    np.testing.assert_array_equal(again.vehicles, episode.vehicles)
    other = spawn_town(6, road, "meta")[3]
    assert not np.array_equal(other.vehicles[:, T.X], episode.vehicles[:, T.X])


def test_a_pedestrians_next_wait_is_the_inverse_transform_exponential():
    """The reference's wait on reaching the far pavement is MEAN_WAIT_S * -log1p(-U) of the next
    53-bit double U of its generator (``standard_exponential(method="inv")``): one draw, which
    the compiled kernels reproduce from the PCG64 words (note log1p: ``-log(1 - U)`` differs)."""
    from drivelab.scenarios.town.reference_env import MEAN_WAIT_S, PAVEMENT_M, Pedestrian, TownRoad
    from drivelab.scenarios.town.road import LAYOUTS as TOWN_LAYOUTS
    from drivelab.scenarios.town.road import build_network, street_crossings

    layout = TOWN_LAYOUTS["test"]
    road = TownRoad(network=build_network(layout), np_random=np.random.default_rng(0), record_history=False)
    for seed in range(20):
        rng = np.random.default_rng(seed)
        walker = Pedestrian(road, street_crossings(layout)[seed % 7], -1, rng)
        walker.speed = walker.pace_mps  # walking towards pavement +1, one step from it
        walker.position = walker.centre + (PAVEMENT_M - 0.05) * walker.across
        words = pcg64.state_of(rng)
        walker.walk(0.1, [])
        assert walker.side == 1 and walker.speed == 0.0
        u = float(pcg64.next_uint64(words) >> np.uint64(11)) * 2.0**-53
        assert walker.wait_s == MEAN_WAIT_S * -math.log1p(-u)
        np.testing.assert_array_equal(pcg64.state_of(rng), words)


def test_lanes_within_a_micrometre_are_decided_by_numpy(monkeypatch):
    """Where the compiled distances put another lane within 1e-6 of the closest, the set-up asks
    ``LaneGeometry.closest_lane`` (numpy's distances, the reference's) for that row: with every
    row marked so, the episode is still the reference's; and ``_place`` marks a point equally far
    from two lanes."""
    from drivelab.scenarios.town import spawn as town_spawn
    from drivelab.sim.core import lanes as L

    calls = []
    compiled = town_spawn._town_rows

    def every_row_ambiguous(*args):
        count, size = compiled(*args)
        args[-1][:count] = True
        calls.append(count)
        return count, size

    monkeypatch.setattr(town_spawn, "_town_rows", every_row_ambiguous)
    compare_setups("train", "regular", "meta", False, seeds=(0, 1))
    assert calls and all(count > 1 for count in calls)

    twins = np.zeros((2, L.LANE_COLUMNS))
    twins[:, L.KIND], twins[:, L.LENGTH], twins[:, L.WIDTH] = L.STRAIGHT, 50.0, 4.0
    twins[:, L.DIR_X], twins[1, L.START_Y] = 1.0, 2.0  # two parallel lanes, 2 m apart
    row = np.zeros(T.TOWN_VEHICLE_COLUMNS)
    assert town_spawn._place(row, twins, 10.0, 1.0, 0.0, 5.0, 4.0)  # midway: both 1 m off
    assert row[T.LANE] == 0
    assert not town_spawn._place(row, twins, 10.0, 0.5, 0.0, 5.0, 4.0)


def test_seeds_wider_than_the_compiled_words_give_the_reference_episode():
    """Seeds below 2**63 are hashed into PCG64 words by compiled code (``pcg64.seeded_states``);
    wider ones go through gymnasium's own seeding: both give the reference's episode."""
    compare_setups("train", "regular", "meta", False, seeds=(2**63 - 1, 2**63, 2**70 + 5))
