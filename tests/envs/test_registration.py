import gymnasium
import numpy as np
import pytest

import drivelab
from drivelab.errors import UsageError


def test_make_and_gymnasium_make_give_the_same_env():
    kwargs = dict(obs=["lidar", "topdown"], reward="metadrive_course", traffic="regular", duration_s=5)
    ours = drivelab.make("highway", seed=0, **kwargs)
    theirs = gymnasium.make("drivelab/Highway-v0", seed=0, **kwargs)
    obs_a, _ = ours.reset(seed=0)
    obs_b, _ = theirs.reset(seed=0)
    for key in ("lidar", "topdown"):
        np.testing.assert_array_equal(obs_a[key], obs_b[key])
    for _ in range(3):
        step_a, step_b = ours.step(1), theirs.step(1)
        np.testing.assert_array_equal(step_a[0]["lidar"], step_b[0]["lidar"])
        assert step_a[1] == step_b[1]


@pytest.mark.parametrize(
    "scenario",
    ["Highway", "Merge", "Roundabout", "Intersection", "Racetrack", "Town", "FollowLine", "FollowLane"],
)
def test_every_scenario_is_registered(scenario):
    assert f"drivelab/{scenario}-v0" in gymnasium.registry


def test_gymnasium_make_of_a_circuit_takes_its_default_action():
    env = gymnasium.make("drivelab/FollowLine-v0", obs="kinematics", duration_s=1)
    assert env.unwrapped.adapter.name == "seed_line"


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"scenario": "moon"}, "unknown scenario 'moon'"),
        ({"obs": "sonar"}, "unknown sensor 'sonar'"),
        ({"reward": "nice"}, "unknown reward preset 'nice'"),
        ({"action": "teleport"}, "unknown action kind 'teleport'"),
        ({"traffic": "jammed"}, "unknown traffic level 'jammed'"),
        ({"scenario": "racetrack", "action": "meta"}, "cannot take action 'meta'"),
        ({"obs": "lidar:beams"}, "must look like key=value"),
        ({"obs": "lidar:colour=3"}, "unknown option 'colour' for sensor 'lidar'"),
    ],
)
def test_bad_arguments_name_the_problem(kwargs, message):
    with pytest.raises(UsageError, match=message):
        drivelab.make(**{"scenario": "highway", **kwargs})


@pytest.mark.parametrize(
    ("scenario", "action", "reward"),
    [("highway", "meta", "highway"), ("racetrack", "grid", "highway"), ("town", "meta", "roach"),
     ("follow-line", "seed_line", "line_follow"), ("follow-lane", "seed_lane", "lane_follow")],
)  # fmt: skip
def test_make_takes_the_scenario_default_action_and_reward_as_train_does(scenario, action, reward):
    from drivelab.rewards.shapers import parse_reward

    env = drivelab.make(scenario, obs="kinematics", duration_s=1)
    assert env.adapter.name == action
    assert env.reward_shaper.spec == parse_reward(reward)
