"""benchmarks/intersection_imitation_probe.py and intersection_choice_probe.py: the planner labels
and scores the state the policy is in (its worlds, given the episode's seed and the policy's
actions, reach the policy's state); each labelled episode records one observation and one label per
decision; the choice probe's counts agree with the planner's scores."""

import importlib.util
import sys
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

BENCHMARKS = Path(__file__).parents[1] / "benchmarks"


def _probe(name: str = "intersection_imitation_probe"):
    sys.path.insert(0, str(BENCHMARKS))
    spec = importlib.util.spec_from_file_location(name, BENCHMARKS / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_the_planners_worlds_reach_the_state_the_student_drove_into():
    from drivelab.envs.core import DriveEnv
    from drivelab.envs.vector import VectorDriveEnv

    probe = _probe()
    options = probe.SCENARIOS["intersection"]
    single, worlds = DriveEnv("intersection", **options), VectorDriveEnv(3, "intersection", **options)
    single.reset(options={"episode_seed": 77})
    worlds.reset(options={"episode_seeds": np.full(3, 77)})
    for action in (2, 0, 0, 1, 2):
        single.step(action)
        worlds.step(np.full(3, action))
    world, batch = single.world, worlds.batch
    for k in range(3):
        assert np.array_equal(batch.ego.position[k], world.ego.position)
        assert np.array_equal(batch.vehicles[k][batch.vehicle_valid[k]], world.vehicles)


class _Idle:
    def predict(self, obs, deterministic=True):
        return np.array(1), None


def test_a_labelled_episode_has_one_observation_and_one_planner_label_per_decision():
    from drivelab.envs.core import DriveEnv
    from drivelab.envs.vector import VectorDriveEnv

    probe = _probe()
    options = probe.SCENARIOS["intersection"]
    student = DriveEnv("intersection", obs=["kinematics:flatten=false", "clock:horizon_s=13"], action="meta",
                       traffic="regular", action_options={"lateral": False})  # fmt: skip
    planner = VectorDriveEnv(3, "intersection", **options)
    args = SimpleNamespace(horizon=1, futures=0)
    data = probe.Data()
    metrics = probe.labelled_episode(planner, student, 5, args, data, agent=_Idle())
    decisions = len(data)
    assert 1 <= decisions <= 13 and data.episodes == [5] * decisions
    assert set(data.actions) <= {0, 1, 2}
    assert data.obs["kinematics"][0].shape == student.observation_space["kinematics"].shape
    student.reset(options={"episode_seed": 5})  # the student's own actions, played again
    for step in range(decisions):
        _, _, terminated, truncated, info = student.step(1)
        assert (terminated or truncated) == (step == decisions - 1)
    assert info["episode_metrics"] == metrics


def test_each_action_scores_as_the_best_sequence_that_starts_with_it():
    from drivelab.envs.vector import VectorDriveEnv

    choice = _probe("intersection_choice_probe")
    planner = VectorDriveEnv(9, "intersection", **choice.SCENARIOS["intersection"])
    sequences, collided, score = choice.sequence_scores(planner, "intersection", 9, [1, 1], 2)
    scores = choice.action_scores(planner, 9, [1, 1], 2)
    assert sequences.shape == (9, 2) and collided.shape == score.shape == (1, 9)
    for action in range(3):
        assert scores[action] == score[0][sequences[:, 0] == action].max()
    assert (score[0] < choice.UNSAFE).tolist() == collided[0].tolist()


def test_the_choice_probes_counts_of_a_shipped_policy_hold_together():
    choice = _probe("intersection_choice_probe")
    row = choice.judge(
        "intersection-ppo_own", choice.load_policy("intersection-ppo_own"), episodes=2, horizon=1
    )
    assert row["episodes"] == 2 and row["success"] + row["crash"] <= 2
    assert 2 <= row["decisions"] <= 26
    assert 0 <= row["best"] <= row["decisions"]
    assert 0 <= row["unsafe"] <= row["critical"] <= row["decisions"]
    assert row["best"] + row["slower_than_needed"] <= row["decisions"]


def test_a_policy_of_another_scenario_or_none_is_one_error_line_and_exit_2(capsys, tmp_path):
    choice = _probe("intersection_choice_probe")
    for target in ("highway-ppo_own", str(tmp_path / "no-such-run")):
        with pytest.raises(SystemExit) as stop:
            choice.load_policy(target)
        error = capsys.readouterr().err
        assert stop.value.code == 2 and error.startswith("error: ") and len(error.splitlines()) == 1
