"""The signalised town: road network, light phases, NPCs stopping at red, red-light runs, routes,
pedestrians at zebra crossings."""

import dataclasses

import numpy as np
import pytest
from highway_env.road.road import Road

from drivelab.envs.core import DriveEnv
from drivelab.scenarios import SCENARIOS
from drivelab.scenarios.town.reference_env import (
    PAVEMENT_M,
    Pedestrian,
    TownRoad,
    TownVehicle,
    left_turn_must_wait,
    random_route,
)
from drivelab.scenarios.town.road import (
    LAYOUTS,
    LightTimings,
    TownLights,
    build_network,
    light_state,
    street_crossings,
)
from drivelab.sim.reference.highway import HighwayBackend
from drivelab.sim.roads import blocks
from drivelab.world.batch import WorldBatch
from drivelab.world.state import LIGHT_GREEN, LIGHT_RED, LIGHT_YELLOW


def arms(layout, junction: int) -> dict[int, int]:
    """{arm: neighbouring junction} of a layout's ``junction`` (in the order of its streets)."""
    return blocks.junction_arms(layout.junctions, layout.streets, junction)


def stop_line(layout, junction: int, arm: int) -> np.ndarray:
    """World position of the stop line at the end of ``arm``'s incoming lane."""
    return blocks.stop_line(blocks.cell_centre(layout.junctions[junction], layout.block_m), arm)


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
    degrees = {len(arms(town, j)) for j in range(len(town.junctions))}
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
    road = TownRoad(network=build_network(town), np_random=np.random.default_rng(0))
    road.neighbour_vehicles_connected_lanes = True
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
    env.vector.rules.route_deviation_m = None  # the ego is moved off its route
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


@pytest.mark.parametrize("backend", ["fast", "highway"])
def test_town_episode_exports_lights_and_route(backend):
    env = DriveEnv(
        "town", obs="waypoints", action="target_speed", reward="roach", traffic="regular", backend=backend
    )
    obs, _ = env.reset(seed=3)
    world = env.world
    assert (type(env.backend) is HighwayBackend) == (backend == "highway") and SCENARIOS["town"].fast_backend
    assert world.traffic_lights.shape == (16, 4) and np.isfinite(world.route.length_m)
    assert len(world.vehicles) == 15 and obs.shape == (10, 2)
    positions = {
        tuple(np.round(stop_line(LAYOUTS["train"], j, k), 6))
        for j in range(9)
        for k in arms(LAYOUTS["train"], j)
    }
    assert all(tuple(np.round(p, 6)) in positions for p in world.traffic_lights[:, :2])
    test_town = DriveEnv(
        "town", obs="kinematics", traffic="empty", backend_options={"layout": "test"}, backend=backend
    )
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
    env.vector.batch = WorldBatch.stack([state])
    assert env.traffic_light_label() == "red_or_yellow"


def test_leaving_the_route_and_being_blocked_end_the_episode():
    env = DriveEnv(
        "town", obs="kinematics", action="target_speed", reward="roach", traffic="empty", backend="highway"
    )
    env.reset(seed=1)
    _, _, terminated, _, info = env.step(np.array([0.0, 0.0]))  # standing still
    assert not terminated and info["traffic_light"] in ("none", "green", "red_or_yellow")
    env.vector.rules.blocked_after_s = 0.5
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
        "town",
        obs="kinematics",
        action="meta",
        traffic="empty",
        backend_options={"retarget": True},
        backend="highway",
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
    plain = DriveEnv(
        "town",
        obs="kinematics",
        action="meta",
        traffic="empty",
        backend_options={"retarget": False},
        backend="highway",
    )
    plain.reset(seed=2)
    plain.backend.env.vehicle.position = end.copy()
    plain.backend.env.vehicle.heading = hw.vehicle.heading
    plain.backend.env.vehicle.on_state_update()
    plain.backend.progress_m = route.length_m - 3.0
    _, _, terminated, _, _ = plain.step(1)
    assert terminated and plain.world.events.arrived
    # fixed routes: drawn from the town's list of 25, the same list every time
    from drivelab.scenarios.town.reference_env import FIXED_ROUTE_COUNT, fixed_routes

    network = plain.backend.env.road.network
    assert fixed_routes(network) == fixed_routes(network) and len(fixed_routes(network)) == FIXED_ROUTE_COUNT
    fixed = DriveEnv(
        "town", obs="kinematics", traffic="empty", backend_options={"fixed_routes": True}, backend="highway"
    )
    starts = {tuple(r[0]) for r in fixed_routes(network)}
    for seed in range(5):
        fixed.reset(seed=seed)
        assert fixed.backend.route_lanes[0] in starts


def _street_vehicle(road, street, s_m, speed):
    lane = road.network.get_lane(street)
    vehicle = TownVehicle(road, lane.position(s_m, 0), lane.heading_at(s_m), speed=speed)
    vehicle.target_lane_index, vehicle.target_speed = street, 10.0
    road.vehicles.append(vehicle)
    return vehicle


def _crossing_of(road, town, street):
    """The crossing on ``street`` and the arc length of its centre along the street's lane."""
    lane = road.network.get_lane(street)
    crossings = street_crossings(town)
    local = np.array([lane.local_coordinates(c[:2]) for c in crossings])
    distances = np.abs(local[:, 1]) + np.abs(local[:, 0] - lane.length / 2)
    crossing = crossings[int(np.argmin(distances))]
    return crossing, lane.local_coordinates(crossing[:2])[0]


def _pedestrian(road, crossing, side=-1):
    walker = Pedestrian(road, crossing, side, np.random.default_rng(0))
    walker.wait_s = 0.0
    road.pedestrians.append(walker)
    road.objects.append(walker)
    return walker


def _run(road, seconds):
    for _ in range(int(seconds * 10)):
        road.act()
        road.step(0.1)


def test_crossings_lie_across_the_middle_of_every_street():
    town = LAYOUTS["train"]
    crossings = street_crossings(town)
    assert crossings.shape == (len(town.streets), 5)
    road = TownRoad(network=build_network(town), np_random=np.random.default_rng(0))
    for crossing, (a, b) in zip(crossings, town.streets, strict=True):
        street = next((f, t, 0) for f, to in road.network.graph.items() for t in to
                      if f.startswith(f"J{a}:il") and t.startswith(f"J{b}:ir"))  # fmt: skip
        lane = road.network.get_lane(street)
        s_m, lateral = lane.local_coordinates(crossing[:2])
        assert s_m == pytest.approx(lane.length / 2) and abs(lateral) == pytest.approx(2.0)  # on the axis
        assert abs(np.cos(crossing[2] - lane.heading_at(s_m))) < 1e-9  # walked across the street


def test_a_pedestrian_waits_for_a_gap_then_crosses_to_the_other_pavement():
    town, road = _town_road(red_for_arm=1)
    street = next((f, t, 0) for f, to in road.network.graph.items() for t in to if t == "J4:ir0")
    crossing, crossing_s = _crossing_of(road, town, street)
    walker = _pedestrian(road, crossing, side=-1)
    _street_vehicle(road, street, crossing_s - 20.0, speed=8.0)  # 20 m out at 8 m/s: inside 6 m + 2.5 s
    road.step(0.1)
    assert walker.speed == 0.0  # waits
    _run(road, 6.0)  # the vehicle has passed
    assert walker.speed > 0.0
    for _ in range(150):  # 11 m at 1.0-1.6 m/s
        _run(road, 0.1)
        if walker.side == 1:
            break
    across = np.array([np.cos(crossing[2]), np.sin(crossing[2])])
    assert walker.side == 1 and walker.speed == 0.0 and not walker.crashed  # arrived, waits again
    assert np.dot(walker.position - crossing[:2], across) == pytest.approx(PAVEMENT_M, abs=0.2)


def test_a_vehicle_stops_for_a_pedestrian_on_the_crossing():
    town, road = _town_road(red_for_arm=1)
    street = next((f, t, 0) for f, to in road.network.graph.items() for t in to if t == "J4:ir0")
    crossing, crossing_s = _crossing_of(road, town, street)
    walker = _pedestrian(road, crossing, side=-1)
    walker.pace_mps = 0.3  # slow: it is still on the vehicle's lane when the vehicle arrives
    road.step(0.1)
    assert walker.speed > 0.0  # the street is empty: it starts across
    vehicle = _street_vehicle(road, street, crossing_s - 30.0, speed=8.0)
    _run(road, 8.0)
    assert not vehicle.crashed and not walker.crashed and vehicle.speed < 0.5
    assert vehicle.lane.local_coordinates(vehicle.position)[0] < crossing_s - vehicle.LENGTH / 2


def test_a_left_turn_waits_for_oncoming_traffic():
    town, road = _town_road(red_for_arm=1)  # arms 0 and 2 green
    into_0 = next((f, t, 0) for f, to in road.network.graph.items() for t in to if t == "J4:ir0")
    into_2 = next((f, t, 0) for f, to in road.network.graph.items() for t in to if t == "J4:ir2")
    left_from_0 = ("J4:ir0", "J4:il1", 0)
    straight_from_0 = ("J4:ir0", "J4:il2", 0)
    lane_2 = road.network.get_lane(into_2)
    assert not left_turn_must_wait(road, left_from_0)
    oncoming = _street_vehicle(road, into_2, lane_2.length - 20.0, speed=8.0)
    assert left_turn_must_wait(road, left_from_0) and not left_turn_must_wait(road, straight_from_0)
    turner = _street_vehicle(road, into_0, road.network.get_lane(into_0).length - 25.0, speed=6.0)
    turner.route = [into_0, left_from_0]
    road.act()
    assert turner.stop_line_ahead() is not None  # it plans to stop at the line
    oncoming.speed = 0.0
    assert not left_turn_must_wait(road, left_from_0)


def test_hitting_a_pedestrian_is_a_pedestrian_collision():
    env = DriveEnv(
        "town", obs="measurements", action="target_speed", traffic="regular", duration_s=20, backend="highway"
    )
    env.reset(seed=0)
    world = env.world
    assert world.pedestrians.shape == (10, 6) and world.road.crossings.shape == (12, 5)
    hw = env.backend.env
    walker = hw.road.pedestrians[0]
    hw.vehicle.speed = 6.0
    walker.position = hw.vehicle.position + 4.0 * hw.vehicle.direction
    walker.wait_s, walker.crashed = 1e9, False
    for other in hw.road.vehicles[1:]:
        other.position = other.position + 1000.0  # nobody else nearby
    for _ in range(5):
        _, _, terminated, _, info = env.step(np.array([1.0, 0.0], dtype=np.float32))
        if terminated:
            break
    assert terminated and env.world.events.collision_with == "pedestrian"
    assert info["episode_metrics"]["pedestrian_collisions"] == 1


@pytest.mark.parametrize("backend", ["fast", "highway"])
def test_an_episode_without_retarget_has_nocrash_time_limit_on_a_random_route_too(backend):
    """Evaluation (no retarget: the episode ends on arrival) gives a random route the time limit
    NoCrash gives its fixed routes, the route at 10 km/h plus 10 s, so that the evaluation set and
    NoCrash judge success alike; training (retarget) keeps the scenario's 60 s; a given duration
    still caps the route's limit."""
    from drivelab.sim.reference.highway import ROUTE_TIMEOUT_MPS

    def limits(duration_s=None, **options):
        env = DriveEnv("town", obs="kinematics", traffic="empty", backend=backend, backend_options=options,
                       **({} if duration_s is None else {"duration_s": duration_s}))  # fmt: skip
        found = []
        for seed in range(4):
            env.reset(seed=seed)
            route = env.world.route
            found.append((env.time_limit_s, (route.length_m - route.progress_m) / ROUTE_TIMEOUT_MPS + 10.0))
        return found

    evaluation = limits(retarget=False)
    for limit, route in evaluation:
        assert limit == pytest.approx(route, rel=1e-12)
    assert len({round(limit, 6) for limit, _ in evaluation}) > 1  # one per route, not one for all
    assert all(limit == 60.0 for limit, _ in limits(retarget=True))
    for limit, route in limits(50.0, retarget=False):
        assert limit == pytest.approx(min(route, 50.0), rel=1e-12)
