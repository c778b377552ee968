"""Affordances on hand-built WorldStates with known answers."""

import dataclasses

import numpy as np
import pytest

from drivelab.envs.core import DriveEnv
from drivelab.perception.affordances import FIELDS, Affordances
from drivelab.world.state import LIGHT_GREEN, LIGHT_RED, LIGHT_YELLOW, Route
from tests.worlds import world


def _facts(state, **options):
    sensor = Affordances(**options)
    sensor.reset(state, np.random.default_rng(0))
    values = sensor.observe(state)
    assert values.shape == (len(FIELDS),) and sensor.space.contains(values)
    return dict(zip(FIELDS, values.tolist(), strict=True))


def test_nothing_ahead_reads_the_range():
    facts = _facts(world(speed_mps=4.0), range_m=40.0)
    assert facts["speed_mps"] == pytest.approx(4.0)
    for field in ("stop_line_m", "leader_m", "pedestrian_m", "oncoming_m"):
        assert facts[field] == 40.0
    assert facts["light_red"] == facts["light_yellow"] == 0.0


def test_light_leader_and_pedestrian_on_the_route():
    state = world(
        speed_mps=5.0,
        vehicles=[
            [15.0, 0.3, 0.0, 3.0, 5.0, 2.0],  # on the route, 15 m ahead, 3 m/s
            [8.0, 4.0, np.pi, 6.0, 5.0, 2.0],  # the opposite lane: not on the route
            [-6.0, 0.0, 0.0, 6.0, 5.0, 2.0],  # behind
        ],
    )
    state = dataclasses.replace(
        state,
        traffic_lights=np.array([[20.0, 0.5, 0.0, LIGHT_RED]]),
        pedestrians=np.array([[10.0, -2.5, np.pi / 2, 1.2, 0.8, 0.8], [5.0, -6.0, 0.0, 0.0, 0.8, 0.8]]),
    )
    facts = _facts(state)
    assert facts["stop_line_m"] == pytest.approx(20.0) and facts["light_red"] == 1.0
    assert facts["leader_m"] == pytest.approx(15.0) and facts["leader_speed_mps"] == pytest.approx(3.0)
    assert facts["pedestrian_m"] == pytest.approx(10.0)  # 2.5 m beside the route; the one 6 m off is not
    # one 6 m to the side counts only while it walks towards the route
    crossing = dataclasses.replace(state, pedestrians=np.array([[12.0, -6.0, np.pi / 2, 1.2, 0.8, 0.8]]))
    leaving = dataclasses.replace(state, pedestrians=np.array([[12.0, -6.0, -np.pi / 2, 1.2, 0.8, 0.8]]))
    assert _facts(crossing)["pedestrian_m"] == pytest.approx(12.0) and _facts(leaving)["pedestrian_m"] == 40.0
    yellow = dataclasses.replace(state, traffic_lights=np.array([[20.0, 0.5, 0.0, LIGHT_YELLOW]]))
    assert _facts(yellow)["light_yellow"] == 1.0 and _facts(yellow)["light_red"] == 0.0


def test_an_oncoming_vehicle_matters_only_before_a_left_turn_at_a_light():
    # the route goes 20 m straight, then turns left (−y is the ego's left)
    left = Route(np.array([[0.0, 0.0], [20.0, 0.0], [20.0, -40.0]]), 0.0, 60.0)
    oncoming = [[30.0, -2.0, np.pi, 5.0, 5.0, 2.0]]  # 30 m ahead in the other lane, coming at 5 m/s
    light = np.array([[14.0, 0.5, 0.0, LIGHT_GREEN]])
    state = dataclasses.replace(world(vehicles=oncoming), route=left, traffic_lights=light)
    assert _facts(state)["oncoming_m"] == pytest.approx(np.hypot(30.0, 2.0), abs=1e-4)
    straight = dataclasses.replace(state, route=Route(np.array([[0.0, 0.0], [100.0, 0.0]]), 0.0, 100.0))
    assert _facts(straight)["oncoming_m"] == 40.0
    stopped = dataclasses.replace(state, vehicles=np.array([[30.0, -2.0, np.pi, 0.0, 5.0, 2.0]]))
    assert _facts(stopped)["oncoming_m"] == 40.0
    # on a parallel street 70 m to the left, heading the other way: not oncoming traffic
    parallel = dataclasses.replace(state, vehicles=np.array([[30.0, -70.0, np.pi, 5.0, 5.0, 2.0]]))
    assert _facts(parallel)["oncoming_m"] == 40.0
    # in the opposite lane, 39.5 m ahead and 9 m left: farther than range_m, read as range_m (in the space)
    edge = dataclasses.replace(state, vehicles=np.array([[39.5, -9.0, np.pi, 5.0, 5.0, 2.0]]))
    assert _facts(edge)["oncoming_m"] == 40.0


def test_town_affordances_stay_in_their_space():
    # seed 192 once put a vehicle on a parallel street into oncoming_m (75 m, outside the space)
    env = DriveEnv("town", obs="affordances", traffic="regular")
    for seed in (192, 223, 227):
        obs, _ = env.reset(seed=seed)
        assert obs in env.observation_space


def test_route_gaps_equal_numpys_norm_and_argmin():
    """The compiled nearest-route-point search gives numpy's values bit for bit: the norm of the
    difference and argmin's first index on ties, a nan winning as argmin has it."""
    from drivelab.perception.affordances import _route_gaps

    rng = np.random.default_rng(5)
    bodies = rng.uniform(-30, 30, (7, 11, 6))
    path = np.round(rng.uniform(-30, 30, (7, 9, 2)))  # rounded: some equal distances
    path[:, 4] = path[:, 1]  # exact ties: the first index wins
    bodies[2, 3, :2] = path[2, 6]  # a body on a route point
    path[5, 3] = np.nan
    gaps = np.linalg.norm(bodies[:, :, None, :2] - path[:, None], axis=3)
    nearest = gaps.argmin(axis=2)
    gap, index = _route_gaps(bodies, path)
    np.testing.assert_array_equal(index, nearest)
    np.testing.assert_array_equal(gap, np.take_along_axis(gaps, nearest[..., None], axis=2)[..., 0])
    assert gap[2, 3] == 0.0 and (index[5] == 3).all()
