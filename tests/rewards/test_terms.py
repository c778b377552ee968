"""Reward terms on hand-built WorldStates with known answers."""

import dataclasses

import numpy as np
import pytest

from drivelab.rewards import terms
from drivelab.world.state import LIGHT_GREEN, LIGHT_RED, Events
from tests.rewards.one_world import one
from tests.worlds import world


def test_progress_lateral_is_seed_formula():
    prev = world(progress_m=10.0)
    now = world(progress_m=14.0, lateral_offset_m=1.0, lane_width_m=4.0)  # lateral = 0.5
    assert one(terms.progress_lateral, prev, now, None) == pytest.approx(4.0 * (1 - 0.5**3))


def test_progress_lateral_zero_at_lane_edge():
    now = world(progress_m=5.0, lateral_offset_m=2.5, lane_width_m=4.0)
    assert one(terms.progress_lateral, world(), now, None) == pytest.approx(0.0)


def test_speed_halved_in_intersections():
    outside = world(speed_mps=14.0)  # 14 / (0.7 * 40) = 0.5
    inside = world(speed_mps=14.0, in_intersection=True)
    assert one(terms.speed, outside, outside, None) == pytest.approx(0.5)
    assert one(terms.speed, inside, inside, None) == pytest.approx(0.25)
    assert one(terms.speed, outside, world(speed_mps=39.0), None) == 1.0


def test_highway_terms():
    now = world(speed_mps=25.0, target_lane_id=1, lane_count=3)
    assert one(terms.high_speed, now, now, None) == pytest.approx(0.5)
    assert one(terms.right_lane, now, now, None) == pytest.approx(0.5)
    assert one(terms.collision, now, world(events=Events(collided=True)), None) == 1.0
    assert one(terms.on_road, now, world(on_road=False), None) == 0.0


def test_cruise_speed_pays_up_to_five_sixths_of_the_limit():
    # highway's limit is 30 m/s: 0 at 20, 0.5 at 22.5, 1 from 25 m/s on
    speeds = {20.0: 0.0, 22.5: 0.5, 25.0: 1.0, 30.0: 1.0, 15.0: 0.0}
    for speed, value in speeds.items():
        now = world(speed_mps=speed)
        assert one(terms.cruise_speed, now, now, None) == pytest.approx(value), speed
    cruising = world(speed_mps=25.0)  # where high_speed pays half, cruise_speed pays all
    assert one(terms.high_speed, cruising, cruising, None) == pytest.approx(0.5)


def test_lane_change_is_one_for_the_lane_change_meta_actions():
    now = world()
    # META_ACTIONS: LANE_LEFT, IDLE, LANE_RIGHT, FASTER, SLOWER
    assert [one(terms.lane_change, now, now, action) for action in range(5)] == [1.0, 0.0, 1.0, 0.0, 0.0]
    assert one(terms.lane_change, now, now, np.array([0.5, -1.0], dtype=np.float32)) == 0.0
    assert one(terms.lane_change, now, now, None) == 0.0


def test_safety_table_values():
    calm = world(lateral_offset_m=0.2, speed_mps=5.0)
    assert one(terms.centered, calm, calm, None) == 0.3
    assert one(terms.centered, calm, world(lateral_offset_m=0.7), None) == 0.0
    assert one(terms.overspeed, calm, calm, None) == 0.0
    assert one(terms.overspeed, calm, world(speed_mps=6.0), None) == -1.0
    assert one(terms.sidewalk_crash, calm, world(events=Events(off_road=True)), None) == -4.0
    assert one(terms.steering_smoothness, world(steering=0.0), world(steering=0.01), None) == 0.1
    assert one(terms.steering_smoothness, world(steering=0.0), world(steering=0.3), None) == -0.2
    assert one(terms.steering_smoothness, world(steering=0.0), world(steering=0.1), None) == 0.0


def test_curve_control():
    curve = dict(lane_curvature=0.02)  # safe speed sqrt(3 / 0.02) = 12.2 m/s
    assert one(terms.curve_control, world(**curve), world(speed_mps=10.0, **curve), None) == 0.2
    assert (
        one(terms.curve_control, world(speed_mps=15.0, **curve), world(speed_mps=16.0, **curve), None) == -0.5
    )
    assert (
        one(terms.curve_control, world(speed_mps=17.0, **curve), world(speed_mps=16.0, **curve), None) == 0.2
    )
    assert one(terms.curve_control, world(), world(speed_mps=30.0), None) == 0.0


def test_intersection_heading():
    aligned = world(in_intersection=True, heading=0.1, lane_heading=0.0)
    crooked = world(in_intersection=True, heading=0.5, lane_heading=0.0)
    assert one(terms.intersection_heading, aligned, aligned, None) == 0.3
    assert one(terms.intersection_heading, crooked, crooked, None) == -0.5
    assert one(terms.intersection_heading, world(), world(heading=1.0), None) == 0.0


def test_destination_proximity():
    assert (
        one(terms.destination_proximity, world(), world(progress_m=160.0, route_length_m=200.0), None) == 0.4
    )
    assert (
        one(terms.destination_proximity, world(), world(progress_m=100.0, route_length_m=200.0), None) == 0.0
    )
    assert one(terms.destination_proximity, world(), world(progress_m=1e6), None) == 0.0


def test_overtaking_rewards_clean_pass_and_punishes_close_one():
    # a vehicle in the left lane (y = -4) 5 m ahead, then 5 m behind
    ahead = world(vehicles=[[5.0, -4.0, 0.0, 15.0, 5.0, 2.0]])
    behind = world(vehicles=[[-5.0, -4.0, 0.0, 15.0, 5.0, 2.0]])
    assert one(terms.overtaking, ahead, behind, None) == 0.2
    close = world(vehicles=[[-2.0, -2.0, 0.0, 15.0, 5.0, 2.0]])  # 2.8 m away
    assert one(terms.overtaking, ahead, close, None) == -0.5
    assert one(terms.overtaking, behind, ahead, None) == 0.0


def test_every_registered_term_returns_a_float():
    now = world()
    for name, fn in terms.TERMS.items():
        assert np.isfinite(one(fn, now, now, None)), name


def test_roach_desired_speed_hazards():
    free = world(speed_mps=6.0)
    assert terms.roach_desired_speed(free) == 6.0
    assert one(terms.roach_speed, free, free, None) == pytest.approx(1.0)
    # a vehicle 9 m straight ahead: 6 * clip(9 - 8, 0, 5) / 5 = 1.2 m/s
    car = world(speed_mps=3.6, vehicles=[[9.0, 0.0, 0.0, 0.0, 5.0, 2.0]])
    assert terms.roach_desired_speed(car) == pytest.approx(1.2)
    assert one(terms.roach_speed, car, car, None) == pytest.approx(1 - 2.4 / 6)
    # one 9 m away but 60° to the side is no hazard
    side = world(vehicles=[[4.5, 9.0 * np.sin(np.pi / 3), 0.0, 0.0, 5.0, 2.0]])
    assert terms.roach_desired_speed(side) == 6.0
    # a red light 7 m ahead on the ego's approach: 6 * (7 - 5) / 5 = 2.4; green or opposite: none
    red = dataclasses.replace(world(), traffic_lights=np.array([[7.0, 0.5, 0.0, LIGHT_RED]]))
    assert terms.roach_desired_speed(red) == pytest.approx(2.4)
    green = dataclasses.replace(world(), traffic_lights=np.array([[7.0, 0.5, 0.0, LIGHT_GREEN]]))
    opposite = dataclasses.replace(world(), traffic_lights=np.array([[7.0, 0.5, np.pi, LIGHT_RED]]))
    assert terms.roach_desired_speed(green) == terms.roach_desired_speed(opposite) == 6.0
    # a pedestrian 8 m ahead in the path: 6 * (8 - 6) / 5 = 2.4; one 3 m to the side is no hazard
    walker = dataclasses.replace(world(), pedestrians=np.array([[8.0, 1.0, 1.57, 1.2, 0.8, 0.8]]))
    assert terms.roach_desired_speed(walker) == pytest.approx(2.4)
    aside = dataclasses.replace(world(), pedestrians=np.array([[8.0, 3.0, 1.57, 1.2, 0.8, 0.8]]))
    assert terms.roach_desired_speed(aside) == 6.0


def test_roach_route_and_action_terms():
    state = world(progress_m=10.0, position=np.array([10.0, 1.0]), heading=0.3)
    assert one(terms.roach_position, state, state, None) == pytest.approx(-0.5)
    assert one(terms.roach_rotation, state, state, None) == pytest.approx(-0.3)
    steady, turned = world(steering=0.1), world(steering=0.1 + 0.02)  # 0.02 rad = 0.025 of ±45°
    assert one(terms.roach_action, steady, turned, None) == -0.1
    assert one(terms.roach_action, steady, world(steering=0.105), None) == 0.0


def test_roach_terminal():
    crash = world(speed_mps=5.0, events=Events(collided=True, collision_with="vehicle"))
    assert one(terms.roach_terminal, world(), crash, None) == pytest.approx(-6.0)
    red = world(speed_mps=3.0, events=Events(red_light_crossed=True))
    assert one(terms.roach_terminal, world(), red, None) == pytest.approx(-4.0)
    assert one(terms.roach_terminal, world(), world(events=Events(off_road=True)), None) == -1.0
    assert one(terms.roach_terminal, world(), world(), None) == 0.0
