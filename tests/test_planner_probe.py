"""benchmarks/planner_probe.py: the planner's worlds start from the episode's state, and the
actions it takes, played again in one DriveEnv as ``drivelab evaluate`` plays the episode, give
the outcome it planned (``play`` raises otherwise)."""

import importlib.util
import sys
from pathlib import Path

import numpy as np
import pytest

SCRIPT = Path(__file__).parents[1] / "benchmarks" / "planner_probe.py"


def _probe():
    spec = importlib.util.spec_from_file_location("planner_probe", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    sys.modules["planner_probe"] = module
    spec.loader.exec_module(module)
    return module


@pytest.mark.parametrize(("scenario", "actions", "decisions"), [("intersection", 3, 13), ("highway", 5, 30)])
def test_the_planners_outcomes_are_those_of_its_actions_played_again(scenario, actions, decisions):
    probe = _probe()
    row = probe.play(scenario, 1 if scenario == "highway" else 2, 2)
    assert row["episodes"] == 2 and len(row["outcomes"]) == 2
    for outcome in row["outcomes"]:
        assert not (outcome["success"] and outcome["crash"])
        assert 1 <= len(outcome["actions"]) <= decisions
        assert set(map(int, outcome["actions"])) <= set(range(actions))
    assert row["success"] == sum(o["success"] for o in row["outcomes"])


def test_worlds_given_one_episode_seed_and_the_same_actions_stay_one_state():
    from drivelab.envs.vector import VectorDriveEnv

    probe = _probe()
    env = VectorDriveEnv(3, "intersection", **probe.SCENARIOS["intersection"])
    env.reset(options={"episode_seeds": np.full(3, 12345)})
    for action in (2, 2, 0, 1):
        env.step(np.full(3, action))
    ego = env.batch.ego
    assert np.all(ego.position == ego.position[0]) and np.all(ego.speed_mps == ego.speed_mps[0])
