"""The fixed evaluation set: every run is evaluated on the same episodes, none of them a training
episode (issue 19: consecutive run seeds used to share 18 of 20 evaluation episodes)."""

import numpy as np
import pytest

from drivelab.envs.core import DriveEnv
from drivelab.envs.vector import (
    EVALUATION_SEED_BASE,
    TRAINING_SEED_LIMIT,
    VectorDriveEnv,
    evaluation_seeds,
)
from drivelab.errors import UsageError
from drivelab.training import evaluate


def test_evaluation_seeds_lie_above_every_training_seed():
    seeds = evaluation_seeds(100)
    assert seeds[0] == EVALUATION_SEED_BASE and len(set(seeds.tolist())) == 100
    assert seeds.min() >= TRAINING_SEED_LIMIT  # training draws integers(TRAINING_SEED_LIMIT): below it
    env = DriveEnv("highway", obs="kinematics")
    drawn = [env.reset(seed=s)[1]["episode_seed"] for s in range(50)]
    assert max(drawn) < TRAINING_SEED_LIMIT


def test_a_given_episode_seed_plays_that_episode_and_leaves_the_generator_alone():
    env = DriveEnv("highway", obs="kinematics")
    env.reset(seed=3)
    expected_next = DriveEnv("highway", obs="kinematics")
    expected_next.reset(seed=3)
    next_seed = expected_next.reset()[1]["episode_seed"]

    seed = int(evaluation_seeds(1, start=7)[0])
    obs, info = env.reset(options={"episode_seed": seed})
    assert info["episode_seed"] == seed
    vector = VectorDriveEnv(2, scenario="highway", obs="kinematics")
    vector_obs, vector_info = vector.reset(options={"episode_seeds": [seed, seed + 1]})
    np.testing.assert_array_equal(vector_info["episode_seed"], [seed, seed + 1])
    np.testing.assert_array_equal(obs, vector_obs[0])  # the same episode in either env
    assert env.reset()[1]["episode_seed"] == next_seed  # the training stream goes on untouched


@pytest.mark.parametrize("bad", [[1.5, 2.0], [-1, 2], [1], [True, False]])
def test_bad_episode_seeds_are_refused(bad):
    vector = VectorDriveEnv(2, scenario="highway", obs="kinematics")
    with pytest.raises(UsageError, match="episode_seeds"):
        vector.reset(options={"episode_seeds": bad})


def test_run_episodes_plays_the_evaluation_set_whatever_the_env_seed():
    seen = []

    class Recording(DriveEnv):
        def reset(self, *, seed=None, options=None):
            obs, info = super().reset(seed=seed, options=options)
            seen.append(info["episode_seed"])
            return obs, info

    for env_seed in (0, 1):
        env = Recording("highway", obs="kinematics", duration_s=2)
        env.reset(seed=env_seed)
        seen.clear()
        space = env.action_space
        results, _ = evaluate.run_episodes(lambda obs, space=space: space.sample(), env, 3)
        assert len(results) == 3
        assert seen == evaluation_seeds(3).tolist()
