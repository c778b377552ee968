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
    assert obs.shape == (7, 5)  # highway-env's (V, F): 7 rows of its 5 default features
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
        (
            {"observation": {"type": "OccupancyGrid"}},
            "type .OccupancyGrid. has no drivelab sensor: the nearest",
        ),
        ({"observation": {"type": "Kinematics", "absolute": True}}, "'absolute' True: .* in the ego frame"),
        (
            {"observation": {"type": "Kinematics", "order": "shuffled"}},
            "'order' 'shuffled': .* nearest first",
        ),
        ({"observation": {"type": "Kinematics", "see_behind": False}}, "'see_behind' False"),
        ({"observation": {"type": "Kinematics", "features": ["x", "heading"]}}, "not 'heading'"),
        ({"observation": {"type": "Kinematics", "features": ["x", "accel"]}}, "'accel' .accel is drivelab"),
        (
            {"observation": {"type": "Kinematics", "features": ["x", "cos_d", "sin_d"]}},
            "cos_d, sin_d without observe_intentions: .*set observe_intentions: true",
        ),
        ({"observation": {"type": "Kinematics", "observe_intentions": "yes"}}, "'observe_intentions' must"),
        ({"observation": {"type": "Kinematics", "features_range": {"x": [-50, 100]}}}, "features_range"),
        (
            {"observation": {"type": "Kinematics", "features_range": {"x": [-9, 9], "y": [-9, 9]}}},
            "features_range",
        ),
        ({"action": {"type": "MultiAgentAction"}}, "'action' must be a dict with a type"),
        (
            {"action": {"type": "DiscreteMetaAction", "target_speeds": [0, 9]}},
            r"step through highway's speeds",
        ),
        ({"action": {"type": "ContinuousAction", "longitudinal": False}}, "'longitudinal' False"),
        ({"screen_width": 1200}, "viewer settings screen_width"),
        ({"controlled_vehicles": 2}, "one ego vehicle"),
        ({"action": {"type": "ContinuousAction", "clip": False}}, r"options \['clip'\]"),
        ({"normalize_reward": 0.5}, "'normalize_reward' must be true or false"),
        ({"reward_speed_range": [10, 20]}, r"'reward_speed_range' \[10, 20\]: .* \[20, 30\] m/s"),
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


# each of highway-env's environments' own default config: accepted, or one line naming what differs
DEFAULT_CONFIGS = [
    ("highway", "HighwayEnv", None),
    ("highway", "HighwayEnvFast", None),
    ("merge", "MergeEnv", r"reward keys .*merging_speed_reward.*: MergeEnv adds merging_speed_reward"),
    ("roundabout", "RoundaboutEnv", r"'absolute' True: .*ego frame.*; reward keys .*RoundaboutEnv rewards"),
    ("intersection", "IntersectionEnv", r"'absolute' True: .*; reward keys .*arrived_reward"),
    ("racetrack", "RacetrackEnv", r"'OccupancyGrid' has no drivelab sensor: the nearest are topdown"),
]


@pytest.mark.parametrize(("scenario", "name", "refused"), DEFAULT_CONFIGS)
def test_highway_envs_default_configs(scenario, name, refused):
    import highway_env.envs

    config = getattr(highway_env.envs, name).default_config()
    if refused is None:
        env = drivelab.make(scenario, config=config)
        obs, _ = env.reset(seed=0)
        assert obs.shape == env.observation_space.shape == (5, 5)  # highway-env's Kinematics
        assert env.time_limit_s == config["duration"]
        assert env.vector.simulator.count[0] == 1 + config["vehicles_count"]
        assert env.vector.rules.offroad_terminal is False  # HighwayEnv's offroad_terminal
        return
    with pytest.raises(UsageError, match=refused) as error:
        drivelab.make(scenario, config=config)
    assert "\n" not in str(error.value) and str(error.value).startswith(
        f"highway-env config for {scenario!r}"
    )


def test_the_highway_snippet_reproduces_highway_envs_settings():
    from highway_env.envs import HighwayEnvFast

    env = drivelab.make("highway", config=HighwayEnvFast.default_config())
    assert env.vector.env_spec.obs == "kinematics:features=presence+x+y+vx+vy:flatten=false"
    assert env.reward_shaper.spec == drivelab.envs.highway_config.PRESETS["highway"]  # its own reward
    assert env.adapter.names == ("LANE_LEFT", "IDLE", "LANE_RIGHT", "FASTER", "SLOWER")
    obs, _ = env.reset(seed=3)
    flat = drivelab.make("highway", obs="kinematics", offroad_terminal=False).reset(seed=3)[0]
    # the same rows as drivelab's own kinematics, highway-env's five columns in its (V, F) layout
    np.testing.assert_array_equal(obs, flat.reshape(5, 7)[:, :5])
    assert obs[0, 0] == 1 and obs[1:, 0].sum() >= 1


def test_the_world_of_the_highway_has_the_speed_limit_the_reward_range_assumes():
    from drivelab.envs.highway_config import HIGHWAY_SPEED_LIMIT_MPS

    env = drivelab.make("highway", seed=0)
    assert env.world.speed_limit_mps == HIGHWAY_SPEED_LIMIT_MPS


def test_observed_intentions_are_the_kinematics_destination_features():
    features = ["presence", "x", "cos_d", "sin_d"]
    config = {"type": "Kinematics", "features": features, "observe_intentions": True}
    env = drivelab.make("intersection", config={"observation": config})
    assert env.sensors[0].features == ("presence", "x", "cos_d", "sin_d")
    obs, _ = env.reset(seed=0)
    seen = obs[:, 0] == 1
    assert obs.shape == (5, 4) and seen[1:].any()
    np.testing.assert_allclose(np.hypot(obs[seen, 2], obs[seen, 3]), 1.0, atol=1e-6)  # unit directions


def test_kinematics_options_map_to_the_sensor():
    config = {
        "type": "Kinematics", "vehicles_count": 4, "features": ["presence", "vx", "x"], "order": "sorted",
        "features_range": {"x": [-50, 50], "y": [-50, 50], "vx": [-20, 20], "vy": [-20, 20]},
        "absolute": False, "clip": True, "see_behind": True, "observe_intentions": False, "flatten": False,
    }  # fmt: skip
    env = drivelab.make("highway", config={"observation": config})
    sensor = env.sensors[0]
    assert (sensor.vehicles_count, sensor.features, sensor.flatten) == (4, ("presence", "vx", "x"), False)
    assert (sensor.perception_distance_m, sensor.speed_scale_mps) == (50.0, 20.0)
    obs, _ = env.reset(seed=0)
    raw = drivelab.make("highway", config={"observation": {**config, "normalize": False}}).reset(seed=0)[0]
    assert raw.shape == obs.shape == (4, 3) and np.abs(raw).max() > 1  # metres and m/s
    seen = obs[:, 0] == 1
    np.testing.assert_allclose(obs[seen, 1:], np.clip(raw[seen, 1:] / [20.0, 50.0], -1, 1), atol=1e-6)
    flat = drivelab.make("highway", config={"observation": {"type": "Kinematics", "flatten": True}})
    assert flat.observation_space.shape == (25,)


def test_highway_reward_keys():
    env = drivelab.make("highway", config={"collision_reward": -2, "normalize_reward": False})
    assert env.reward_shaper.spec.normalize is None and env.reward_shaper.spec.weights["collision"] == -2
    # HighwayEnv reads no lane_change_reward, and [20, 30] is what high_speed rewards there
    same = drivelab.make("highway", config={"lane_change_reward": -0.5, "reward_speed_range": [20.0, 30]})
    assert same.reward_shaper.spec == drivelab.envs.highway_config.PRESETS["highway"]


def test_every_difference_is_said_in_one_line():
    config = {"observation": {"type": "Kinematics", "absolute": True}, "screen_width": 9, "cars": 3}
    with pytest.raises(UsageError) as error:
        drivelab.make("highway", config=config)
    message = str(error.value)
    assert "\n" not in message
    assert "'absolute' True" in message and "screen_width" in message and "'cars'" in message


def test_configure_changes_the_env_from_the_next_reset():
    env = drivelab.make("highway", obs="kinematics", backend_options={"vehicles_count": 5})
    first, _ = env.reset(seed=0)
    env.configure(
        {"observation": {"type": "Kinematics", "vehicles_count": 3}, "lanes_count": 2, "duration": 7}
    )
    assert env.observation_space.shape == (35,)  # the running episode is unchanged
    env.step(1)
    obs, _ = env.reset(seed=0)
    assert obs.shape == env.observation_space.shape == (3, 5)
    assert env.world.ego.lane_count == 2 and env.time_limit_s == 7
    assert env.vector.simulator.count[0] == 6  # vehicles_count given before is kept
    with pytest.raises(UsageError, match="'absolute' True"):
        env.configure({"observation": {"type": "Kinematics", "absolute": True}})
    env.configure({"collision_reward": -3})  # configurations add up, as highway-env's
    env.reset(seed=0)
    assert env.observation_space.shape == (3, 5) and env.reward_shaper.spec.weights["collision"] == -3
