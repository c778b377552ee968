"""highway-env's config dict and gymnasium ids, as highway-env's users write them."""

import gymnasium
import numpy as np
import pytest

import drivelab
from drivelab.config import build_config
from drivelab.envs.highway_config import env_kwargs_from_config
from drivelab.errors import UsageError


def test_a_highway_env_config_builds_the_env_it_describes():
    config = {
        "observation": {"type": "Kinematics", "vehicles_count": 7},
        "action": {"type": "DiscreteMetaAction"},
        "lanes_count": 4,
        "vehicles_count": 10,
        "duration": 12,
        "collision_reward": -2,
    }
    env = drivelab.make("drivelab/Highway-v0", config=config)
    obs, _ = env.reset(seed=0)
    assert obs.shape == (7 * 7,)  # 7 rows of highway-env's 7 features
    assert env.action_space.n == 5
    assert env.time_limit_s == 12
    assert env.vector.batch[0].ego.lane_count == 4
    assert env.vector.simulator.count[0] == 11  # the ego and 10 others
    assert env.reward_shaper.spec.weights["collision"] == -2.0
    assert env.reward_shaper.spec.normalize == (-2.0, 0.5)  # [collision, speed + lane]
    same = gymnasium.make("drivelab/Highway-v0", config=config).unwrapped
    np.testing.assert_array_equal(same.reset(seed=0)[0], obs)


def test_the_intersections_longitudinal_meta_actions():
    """highway-env's intersection config: DiscreteMetaAction without the lane changes."""
    config = {"action": {"type": "DiscreteMetaAction", "lateral": False, "longitudinal": True}}
    env = drivelab.make("intersection", config=config)
    assert env.action_space.n == 3 and env.adapter.names == ("SLOWER", "IDLE", "FASTER")
    given = drivelab.make("intersection", config=config, action_options={"lateral": True})
    assert given.action_space.n == 5  # the keyword beside the config wins


def test_keyword_arguments_beside_the_config_win():
    lidar = {"observation": {"type": "LidarObservation", "cells": 64}}
    assert env_kwargs_from_config(lidar, obs="kinematics")["obs"] == "kinematics"
    assert env_kwargs_from_config(lidar)["obs"] == "lidar:beams=64"


@pytest.mark.parametrize(
    ("config", "message"),
    [
        ({"observation": {"type": "OccupancyGrid"}}, "type .OccupancyGrid. has no drivelab sensor"),
        ({"observation": {"type": "Kinematics", "absolute": True}}, "option 'absolute'"),
        ({"action": {"type": "MultiAgentAction"}}, "'action' must be a dict with a type"),
        ({"action": {"type": "DiscreteMetaAction", "target_speeds": [0, 9]}}, r"options \['target_speeds'\]"),
        ({"action": {"type": "ContinuousAction", "lateral": False}}, r"options \['lateral'\]"),
        ({"normalize_reward": False}, "'normalize_reward'"),
        ({"reward_speed_range": [10, 20]}, "'reward_speed_range'"),
        ("lanes_count=4", "config must be a dict"),
    ],
)
def test_what_drivelab_does_not_reproduce_is_refused(config, message):
    with pytest.raises(UsageError, match=message):
        env_kwargs_from_config(config)


def test_gymnasium_ids_name_their_scenarios():
    assert build_config({"algo": "ppo", "env": "drivelab/FollowLine-v0"}).env == "follow-line"
    env = drivelab.make("drivelab/Town-v0", obs="waypoints")
    assert env.scenario.name == "town"
