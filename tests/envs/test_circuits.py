"""follow-line / follow-lane circuits: closed tracks of the right length, the pedal ego, lane keeping."""

import numpy as np
import pytest

from drivelab.agents.qlearning import build_qlearning
from drivelab.envs.actions import make_action
from drivelab.envs.core import DriveEnv
from drivelab.errors import UsageError
from drivelab.scenarios.circuits.reference_env import DRAG_PER_S, FOLLOW_LINE_TRACK, PedalVehicle


def _track_length(track):
    return sum(v[0] if k == "straight" else v[0] * np.radians(abs(v[1])) for k, *v in track)


def test_follow_line_circuit_is_closed_with_a_guide_line():
    env = DriveEnv(
        "follow-line",
        obs="kinematics",
        action="seed_line",
        reward="line_follow",
        traffic="empty",
        seed=0,
        backend="highway",
    )
    world = env.world
    (guide,) = world.road.guide_lines
    np.testing.assert_allclose(guide[0], guide[-1], atol=1e-6)  # one whole lap
    length = np.sum(np.hypot(*np.diff(guide, axis=0).T))
    assert length == pytest.approx(_track_length(FOLLOW_LINE_TRACK), rel=5e-3)  # 467 m, arcs as 2 m chords
    assert world.ego.lane_count == 1 and len(world.vehicles) == 0
    assert world.ego.lane_width_m == 7.0


def test_follow_lane_leaving_the_lane_ends_the_episode():
    env = DriveEnv(
        "follow-lane",
        obs="kinematics",
        action="seed_lane",
        reward="lane_follow",
        traffic="empty",
        seed=1,
        backend="highway",
    )
    assert env.world.ego.lane_count == 3 and not env.world.road.guide_lines
    steps = 0
    while steps < 60:  # hard right (0.08 · 45° = 3.6°) until the ego crosses a line
        _, _, terminated, truncated, info = env.step(4)
        steps += 1
        if terminated:
            break
    assert terminated and info["off_road"] and steps < 40


def test_seed_tables():
    assert make_action("seed_lane").to_control(3).tolist() == pytest.approx([0.6, 0.0])
    assert make_action("seed_line").to_control(4).tolist() == pytest.approx([0.2, 0.4])
    with pytest.raises(UsageError, match="cannot take action 'seed_line'"):
        DriveEnv("highway", obs="kinematics", action="seed_line")


def test_pedal_speed_levels_off():
    from highway_env.road.lane import StraightLane
    from highway_env.road.road import Road, RoadNetwork

    network = RoadNetwork()
    network.add_lane("a", "b", StraightLane([0, 0], [10_000, 0]))
    vehicle = PedalVehicle(Road(network), np.zeros(2), 0.0, 0.0)
    vehicle.act({"acceleration": 5.0 * 0.35, "steering": 0.0})
    for _ in range(600):  # 30 s at 20 Hz: six time constants of the drag
        vehicle.act()  # as highway-env's road does before every frame
        vehicle.step(0.05)
    assert (
        vehicle.speed == pytest.approx(5.0 * 0.35 / DRAG_PER_S, rel=0.01) == pytest.approx(30 / 3.6, rel=0.01)
    )


def test_qlearning_on_camera_pixels_is_refused():
    env = DriveEnv(
        "follow-line",
        obs="camera",
        action="seed_line",
        reward="line_follow",
        traffic="empty",
        backend="highway",
    )
    with pytest.raises(UsageError, match="qlearning needs a discrete observation"):
        build_qlearning("qlearning", env, 0, {}, None)
