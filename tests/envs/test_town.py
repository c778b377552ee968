"""The signalised town: road network, light phases, NPCs stopping at red, red-light runs, routes."""

import dataclasses

import numpy as np
import pytest
from highway_env.road.road import Road

from drivelab.envs.backends.highway import HighwayBackend
from drivelab.envs.core import DriveEnv
from drivelab.envs.scenarios import SCENARIOS
from drivelab.envs.town import (
    LAYOUTS,
    LightTimings,
    TownLights,
    build_network,
    light_state,
    stop_line,
)
from drivelab.envs.town_env import TownVehicle, random_route
from drivelab.envs.world import LIGHT_GREEN, LIGHT_RED, LIGHT_YELLOW


@pytest.mark.parametrize("layout", sorted(LAYOUTS))
def test_network_is_continuous_and_has_t_and_four_way_junctions(layout):
    town = LAYOUTS[layout]
    net = build_network(town)
    for _from, to in net.graph.items():
        for _to, (lane,) in to.items():
            for successor in net.graph.get(_to, {}).values():
                np.testing.assert_allclose(
                    successor[0].position(0, 0), lane.position(lane.length, 0), atol=1e-9
                )
                turn = np.angle(np.exp(1j * (successor[0].heading_at(0) - lane.heading_at(lane.length))))
                assert abs(turn) < 1e-9  # lanes join without a kink
    degrees = {len(town.arms(j)) for j in range(len(town.junctions))}
    assert 3 in degrees and min(degrees) >= 2
    if layout == "train":
        assert 4 in degrees


def test_light_phases():
    timings = LightTimings(green_s=10, yellow_s=3, all_red_s=1)  # cycle 28 s
    expected = {0.0: LIGHT_GREEN, 9.9: LIGHT_GREEN, 10.0: LIGHT_YELLOW, 12.9: LIGHT_YELLOW, 13.0: LIGHT_RED}
    for time_s, state in expected.items():
        assert light_state(timings, 0, time_s) == light_state(timings, 2, time_s) == state
    # the cross axis is red while arms 0 and 2 go, then green for 10 s from t = 14 s
    assert [light_state(timings, 1, t) for t in (0.0, 13.9, 14.0, 23.9, 24.0, 27.9, 28.0)] == [
        LIGHT_RED, LIGHT_RED, LIGHT_GREEN, LIGHT_GREEN, LIGHT_YELLOW, LIGHT_RED, LIGHT_RED,
    ]  # fmt: skip
    assert light_state(timings, 0, 5.0, offset_s=10.0) == light_state(timings, 0, 23.0)
    # no two crossing approaches of a junction are ever green together
    for t in np.arange(0, 56, 0.25):
        assert not (light_state(timings, 0, t) == LIGHT_GREEN and light_state(timings, 1, t) == LIGHT_GREEN)


def _town_road(layout="train", red_for_arm=0):
    town = LAYOUTS[layout]
    road = Road(network=build_network(town), np_random=np.random.default_rng(0))
    timings = LightTimings()
    offsets = np.full(len(town.junctions), 0.0 if red_for_arm % 2 == 1 else timings.cycle_s / 2)
    road.lights = TownLights(town, timings, offsets)
    road.clock = lambda: 2.0  # arms of the other axis are green at 2 s; ours is red
    return town, road


def test_npc_stops_before_a_red_stop_line():
    town, road = _town_road(red_for_arm=0)
    junction = 4  # the 4-way crossing
    street = next((f, t, 0) for f, to in road.network.graph.items() for t in to if t == f"J{junction}:ir0")
    lane = road.network.get_lane(street)
    assert road.lights.state(junction, 0, road.clock()) == LIGHT_RED
    vehicle = TownVehicle(road, lane.position(5.0, 0), lane.heading_at(5.0), speed=8.0)
    vehicle.target_lane_index, vehicle.target_speed = street, 10.0
    road.vehicles.append(vehicle)
    for _ in range(300):
        road.act()
        road.step(0.1)
    front_to_line = lane.length - lane.local_coordinates(vehicle.position)[0] - vehicle.LENGTH / 2
    assert 0.0 < front_to_line < 3.0 and abs(vehicle.speed) < 0.1
    road.clock = lambda: 2.0 + LightTimings().cycle_s / 2  # our axis turns green: it drives on
    for _ in range(60):
        road.act()
        road.step(0.1)
    assert vehicle.lane_index != street and vehicle.speed > 3.0  # through the junction


def test_running_a_red_light_is_detected_exactly_once():
    env = DriveEnv(
        "town", obs="kinematics", action="continuous", traffic="empty", backend="highway", duration_s=30
    )
    env.reset(seed=0)
    env.scenario = dataclasses.replace(env.scenario, route_deviation_m=None)  # the ego is moved off its route
    backend = env.backend
    hw = backend.env
    lights = backend.lights
    lights.offsets_s[:] = 0.0
    lights.timings = LightTimings(green_s=0.0, yellow_s=0.0, all_red_s=100.0)  # red everywhere, always
    # put the ego 20 m before a stop line, heading for it at 8 m/s
    street = next((f, t, 0) for f, to in hw.road.network.graph.items() for t in to if t == "J4:ir0")
    lane = hw.road.network.get_lane(street)
    hw.vehicle.position = lane.position(lane.length - 20.0, 0.0)
    hw.vehicle.heading, hw.vehicle.speed = lane.heading_at(0.0), 8.0
    hw.vehicle.on_state_update()
    runs, steps = 0, 0
    while steps < 30:
        _, _, terminated, truncated, info = env.step(np.array([0.0, 0.0]))
        runs += int(env.world.events.red_light_crossed)
        steps += 1
        if terminated or truncated:
            break
    assert runs == 1 and terminated and env.world.events.red_light_crossed
    assert info["episode_metrics"]["red_lights"] == 1


@pytest.mark.parametrize("layout", sorted(LAYOUTS))
def test_planner_routes_are_connected_and_reach_their_target(layout):
    road = Road(network=build_network(LAYOUTS[layout]), np_random=np.random.default_rng(1))
    streets = [(f, t, 0) for f, to in road.network.graph.items() for t in to if ":ir" in t]
    for start in streets:
        route = random_route(road, start)
        assert route[0] == start and len(route) >= 2
        for (_, a_to, _), (b_from, _, _) in zip(route[:-1], route[1:], strict=True):
            assert a_to == b_from and b_from in road.network.graph
        assert ":ir" in route[-1][1] and route[-1][1] != start[1]


def test_town_episode_exports_lights_and_route():
    env = DriveEnv("town", obs="waypoints", action="target_speed", reward="roach", traffic="regular")
    obs, _ = env.reset(seed=3)
    world = env.world
    assert type(env.backend) is HighwayBackend and SCENARIOS["town"].fast_backend is False
    assert world.traffic_lights.shape == (16, 4) and np.isfinite(world.route.length_m)
    assert len(world.vehicles) == 15 and obs.shape == (10, 2)
    positions = {
        tuple(np.round(stop_line(LAYOUTS["train"], j, k), 6))
        for j in range(9)
        for k in LAYOUTS["train"].arms(j)
    }
    assert all(tuple(np.round(p, 6)) in positions for p in world.traffic_lights[:, :2])
    test_town = DriveEnv("town", obs="kinematics", traffic="empty", backend_options={"layout": "test"})
    test_town.reset(seed=0)
    assert test_town.world.traffic_lights.shape == (6, 4)


def test_light_ahead_and_its_label():
    from tests.worlds import world

    lights = np.array(
        [[10.0, 0.5, 0.0, LIGHT_RED], [30.0, 0.0, 0.0, LIGHT_GREEN], [5.0, 0.0, np.pi, LIGHT_GREEN]]
    )
    state = dataclasses.replace(world(), traffic_lights=lights)
    assert state.light_ahead(18.0) == (LIGHT_RED, 10.0)  # the opposite approach's light is not ours
    behind = dataclasses.replace(world(position=np.array([12.0, 0.0])), traffic_lights=lights)
    assert behind.light_ahead(18.0) == (LIGHT_GREEN, 18.0)
    assert behind.light_ahead(10.0) is None and world().light_ahead(18.0) is None
    env = DriveEnv("town", obs="kinematics", action="target_speed", traffic="empty")
    env.reset(seed=0)
    env.world = state
    assert env.traffic_light_label() == "red_or_yellow"


def test_leaving_the_route_and_being_blocked_end_the_episode():
    env = DriveEnv("town", obs="kinematics", action="target_speed", reward="roach", traffic="empty")
    env.reset(seed=1)
    _, _, terminated, _, info = env.step(np.array([0.0, 0.0]))  # standing still
    assert not terminated and info["traffic_light"] in ("none", "green", "red_or_yellow")
    env.scenario = dataclasses.replace(env.scenario, blocked_after_s=0.5)
    steps = 0
    while not terminated and steps < 10:
        _, reward, terminated, _, info = env.step(np.array([0.0, 0.0]))
        steps += 1
    assert steps == 2  # stopped 0.2 s before, 0.6 s > 0.5 s after two more steps of 0.2 s
    assert terminated and env.world.events.blocked and info["episode_metrics"]["blocked"] == 1
    assert info["reward_terms"]["roach_terminal"] == -1.0
    env.reset(seed=1)
    hw = env.backend.env
    hw.vehicle.position = hw.vehicle.position + 5.0 * np.array(
        [-np.sin(hw.vehicle.heading), np.cos(hw.vehicle.heading)]
    )
    hw.vehicle.on_state_update()
    _, _, terminated, _, _ = env.step(np.array([0.0, 0.0]))
    assert terminated and env.world.events.off_route and not env.world.events.blocked


def test_training_retargets_on_arrival_and_evaluation_uses_fixed_routes():
    env = DriveEnv(
        "town", obs="kinematics", action="meta", traffic="empty", backend_options={"retarget": True}
    )
    env.reset(seed=2)
    hw, route = env.backend.env, env.world.route
    lanes_before = len(env.backend.route_lanes)
    end = route.polyline[-1] - 0.5 * (route.polyline[-1] - route.polyline[-2]) / np.linalg.norm(
        route.polyline[-1] - route.polyline[-2]
    )
    hw.vehicle.position = end.copy()
    hw.vehicle.heading = float(np.arctan2(*(route.polyline[-1] - route.polyline[-2])[::-1]))
    hw.vehicle.on_state_update()
    env.backend.progress_m = route.length_m - 3.0  # as if it had driven there
    _, _, terminated, _, _ = env.step(1)
    assert not terminated and not env.world.events.arrived
    assert len(env.backend.route_lanes) > lanes_before and env.world.route.length_m > route.length_m
    assert env.backend.route_lanes[:lanes_before] == env.backend.env.ego_route[:lanes_before]
    # evaluation: without retarget the same arrival ends the episode
    plain = DriveEnv("town", obs="kinematics", action="meta", traffic="empty")
    plain.reset(seed=2)
    plain.backend.env.vehicle.position = end.copy()
    plain.backend.env.vehicle.heading = hw.vehicle.heading
    plain.backend.env.vehicle.on_state_update()
    plain.backend.progress_m = route.length_m - 3.0
    _, _, terminated, _, _ = plain.step(1)
    assert terminated and plain.world.events.arrived
    # fixed routes: drawn from the town's list of 25, the same list every time
    from drivelab.envs.town_env import FIXED_ROUTE_COUNT, fixed_routes

    network = plain.backend.env.road.network
    assert fixed_routes(network) == fixed_routes(network) and len(fixed_routes(network)) == FIXED_ROUTE_COUNT
    fixed = DriveEnv("town", obs="kinematics", traffic="empty", backend_options={"fixed_routes": True})
    starts = {tuple(r[0]) for r in fixed_routes(network)}
    for seed in range(5):
        fixed.reset(seed=seed)
        assert fixed.backend.route_lanes[0] in starts
