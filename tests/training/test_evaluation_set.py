"""The fixed evaluation set: every run is evaluated on the same episodes, none of them a training
episode (issue 19: consecutive run seeds used to share 18 of 20 evaluation episodes)."""

import numpy as np
import pytest

from drivelab.envs.core import DriveEnv
from drivelab.envs.vector import TRAINING_SEED_LIMIT, VectorDriveEnv
from drivelab.errors import UsageError
from drivelab.training import evaluate
from drivelab.training.seeds import EVALUATION_SEED_BASE, VALIDATION_START, evaluation_seeds


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


def _recording_env(seen: list):
    class Recording(DriveEnv):
        def reset(self, *, seed=None, options=None):
            obs, info = super().reset(seed=seed, options=options)
            seen.append(info["episode_seed"])
            return obs, info

    return Recording("highway", obs="kinematics", duration_s=2)


def test_run_episodes_plays_the_evaluation_set_whatever_the_env_seed():
    seen = []
    for env_seed in (0, 1):
        env = _recording_env(seen)
        env.reset(seed=env_seed)
        seen.clear()
        space = env.action_space
        results, _ = evaluate.run_episodes(lambda obs, space=space: space.sample(), env, 3)
        assert len(results) == 3
        assert seen == evaluation_seeds(3).tolist()


def test_validation_episodes_are_not_test_episodes():
    """Tuning's episodes (``first=VALIDATION_START``) follow on from the test episodes every
    report plays, and share none with the leaderboard's 100 (or any report's first 10,000)."""
    seen = []
    env = _recording_env(seen)
    space = env.action_space
    evaluate.run_episodes(lambda obs: space.sample(), env, 3, first=VALIDATION_START)
    assert seen == evaluation_seeds(3, start=VALIDATION_START).tolist()
    assert min(seen) > max(evaluation_seeds(10_000).tolist())


def test_a_tuning_trial_is_judged_on_validation_episodes(tmp_path, monkeypatch):
    """run_cell (a sweep cell, a tuning trial) passes ``eval_first`` to the periodic evaluations
    and to the final one, whose report says where its episodes start."""
    import json

    from drivelab.training.sweep import run_cell

    played = []
    original = evaluate.run_episodes

    def recording(*args, first=0, **kwargs):
        played.append(first)
        return original(*args, first=first, **kwargs)

    monkeypatch.setattr(evaluate, "run_episodes", recording)
    monkeypatch.setattr("drivelab.training.run.run_episodes", recording)
    values = {
        "name": "trial", "algo": "ppo", "env": "highway", "obs": "kinematics", "traffic": "empty",
        "backend": "fast", "env_options": {"duration_s": 2}, "steps": 32, "eval_every": 16,
        "eval_episodes": 1, "hyperparams": {"n_steps": 16, "batch_size": 16, "n_epochs": 1},
    }  # fmt: skip
    outcome = run_cell(values, str(tmp_path), "train", 2, eval_first=VALIDATION_START)
    assert outcome["ok"], outcome["error"]
    assert played == [VALIDATION_START] * 3  # evaluations at steps 16 and 32, then the final one
    report = json.loads((tmp_path / "trial" / "eval.json").read_text())
    assert report["first_episode"] == VALIDATION_START and report["episodes"] == 2
