"""Every scenario × sensor passes gymnasium's and stable-baselines3's environment checkers."""

import warnings

import pytest
from gymnasium.utils.env_checker import check_env as gym_check_env
from stable_baselines3.common.env_checker import check_env as sb3_check_env

from drivelab.envs.core import DriveEnv
from drivelab.errors import UsageError
from drivelab.perception.sensors import SENSORS
from drivelab.scenarios import SCENARIOS


@pytest.mark.parametrize("sensor", sorted(SENSORS))
@pytest.mark.parametrize("scenario", sorted(SCENARIOS))
def test_scenario_sensor_passes_checkers(scenario, sensor):
    """... and a sensor that cannot observe the scenario (the line and lane perception off their
    circuits: ``Sensor.scenario_problem``) is refused when the environment is built."""
    action = SCENARIOS[scenario].action_kinds[0]
    own_circuit = {"line": "follow-line", "lane": "follow-lane"}.get(sensor, scenario)
    if own_circuit != scenario:
        with pytest.raises(UsageError, match=f"sensor {sensor!r} cannot observe scenario {scenario!r}"):
            DriveEnv(scenario, obs=sensor, action=action, traffic="regular", duration_s=4)
        return
    env = DriveEnv(scenario, obs=sensor, action=action, traffic="regular", duration_s=4)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        gym_check_env(env, skip_render_check=True)
        sb3_check_env(env, warn=False)


def test_dict_observation_passes_checkers():
    env = DriveEnv("highway", obs="lidar,topdown,kinematics", action="continuous", duration_s=3)
    assert set(env.observation_space.spaces) == {"lidar", "topdown", "kinematics"}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        gym_check_env(env, skip_render_check=True)
        sb3_check_env(env, warn=False)


@pytest.mark.parametrize("backend", ["fast", "highway"])
def test_every_action_kind_passes_checkers(backend):
    for action in SCENARIOS["roundabout"].action_kinds:
        env = DriveEnv(
            "roundabout",
            obs="waypoints,measurements",
            action=action,
            reward="roach",
            backend=backend,
            duration_s=3,
        )
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            gym_check_env(env, skip_render_check=True)
            sb3_check_env(env, warn=False)
