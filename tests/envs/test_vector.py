"""Vector envs: K worlds stepped together behave exactly as K separate DriveEnvs."""

import numpy as np
import pytest
from gymnasium.utils.env_checker import data_equivalence
from stable_baselines3 import PPO

from drivelab.envs.core import DriveEnv
from drivelab.envs.vector import DriveVectorEnv, SB3VecEnv, make_vec
from drivelab.errors import UsageError

KWARGS = {"obs": "kinematics", "traffic": "regular", "duration_s": 6}


@pytest.mark.parametrize("scenario", ["highway", "roundabout", "intersection"])
def test_batched_worlds_match_separate_envs(scenario):
    """The one-kernel batch gives every sub-env the same transitions as its own DriveEnv,
    across autoresets (episodes of 6 s end inside the 15 steps)."""
    k = 4
    vector = make_vec(scenario, num_envs=k, **KWARGS)
    assert vector.batch is not None
    singles = [DriveEnv(scenario, backend="fast", **KWARGS) for _ in range(k)]
    obs, _ = vector.reset(seed=10)
    for i, env in enumerate(singles):
        single_obs, _ = env.reset(seed=10 + i)
        np.testing.assert_array_equal(obs[i], single_obs)
    rng = np.random.default_rng(0)
    ends = 0
    for _ in range(15):
        actions = rng.integers(5, size=k)
        obs, rewards, terminations, truncations, infos = vector.step(actions)
        for i, env in enumerate(singles):
            single_obs, reward, terminated, truncated, info = env.step(int(actions[i]))
            assert (terminated, truncated) == (terminations[i], truncations[i])
            assert reward == rewards[i]
            if terminated or truncated:
                ends += 1
                assert data_equivalence(infos["final_obs"][i], single_obs)
                single_obs, _ = env.reset()
            np.testing.assert_array_equal(obs[i], single_obs)
    assert ends >= k  # every world finished at least one episode and was reset


def test_highway_backend_vector_env_steps_each_world():
    vector = DriveVectorEnv(2, scenario="highway", backend="highway", obs="kinematics", duration_s=2)
    assert vector.batch is None
    obs, _ = vector.reset(seed=0)
    assert obs.shape == (2, *vector.single_observation_space.shape)
    obs, rewards, *_ = vector.step(np.array([1, 1]))
    assert vector.observation_space.contains(obs) and rewards.shape == (2,)


def test_sb3_ppo_trains_on_the_vec_env():
    venv = SB3VecEnv(make_vec("highway", num_envs=4, obs="kinematics", traffic="regular", duration_s=4))
    model = PPO("MlpPolicy", venv, n_steps=16, batch_size=32, n_epochs=1, seed=0, device="cpu")
    model.learn(64)
    assert model.num_timesteps == 64
    venv.seed(3)
    obs = venv.reset()
    venv.step_async(np.array([1, 1, 1, 1]))
    obs, rewards, dones, infos = venv.step_wait()
    assert obs.shape == (4, *venv.observation_space.shape) and len(infos) == 4
    assert venv.get_attr("duration_s") == [4.0] * 4


def test_bad_num_envs():
    with pytest.raises(UsageError, match="num_envs must be >= 1"):
        DriveVectorEnv(0, scenario="highway")
