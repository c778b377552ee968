"""benchmarks/seed003_osx.py: the agents' observations and actions on "OSX" are the seed's (750-D
LiDAR + ego state with 18 actions, the 5×84×84 image, the fusion Dict), and the results table
summarises runs over seeds (means, intervals, per-block sums)."""

import importlib.util
from pathlib import Path

import numpy as np
import pytest
from gymnasium import spaces

from drivelab.config import build_config
from drivelab.envs.core import DriveEnv
from drivelab.yaml_io import load_yaml

SCRIPT = Path(__file__).parents[2] / "benchmarks" / "seed003_osx.py"


@pytest.fixture(scope="module")
def bench():
    spec = importlib.util.spec_from_file_location("seed003_osx", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _config(bench, agent: str):
    """The RunConfig the agent's ``drivelab train`` arguments give (the CLI's own option names)."""
    arguments = bench.AGENTS[agent][1] + bench.COMMON
    values = dict(zip(arguments[::2], arguments[1::2], strict=True))
    return build_config(
        {
            "algo": values["--algo"], "env": values["--env"], "obs": values["--obs"],
            "action": values["--action"], "reward": values["--reward"], "traffic": values["--traffic"],
            "backend": values["--backend"], **load_yaml(bench.MAP_CONFIG),
        }
    )  # fmt: skip


def test_observations_and_actions_are_the_seeds(bench):
    shapes = {}
    for agent in ("dueling_ddqn", "sb3_dqn", "ppo_topdown", "ppo_fusion"):
        env = DriveEnv(**_config(bench, agent).eval_env_kwargs())
        obs, _ = env.reset(seed=0)
        assert env.observation_space.contains(obs)
        assert env.simulator.map_of(0).pg.letters == "IOSX"
        shapes[agent] = (env.observation_space, env.action_space)
    ddqn_obs, ddqn_actions = shapes["dueling_ddqn"]
    assert sum(int(np.prod(space.shape)) for space in ddqn_obs.spaces.values()) == 750
    assert ddqn_actions == spaces.Discrete(18)
    assert shapes["sb3_dqn"][1] == spaces.Discrete(18)
    assert shapes["ppo_topdown"][0].shape == (5, 84, 84)
    fusion = shapes["ppo_fusion"][0]
    assert {key: space.shape for key, space in fusion.spaces.items()} == {
        "topdown": (5, 84, 84), "ego_state": (5,), "lidar": (120,)
    }  # fmt: skip
    assert shapes["ppo_fusion"][1].shape == (2,)


def _run(agent: str, seed: int, success: float, blocks: dict) -> dict:
    return {
        "agent": agent, "seed": seed, "steps": 100, "success_rate": success, "crash_rate": 0.0,
        "out_of_road_rate": 1.0 - success, "mean_speed_mps": 10.0 + seed, "mean_return": 5.0,
        "route_completion": 0.5, "train_wall_s": 60.0, "train_cpu_s": 30.0, "steering_share": 0.5,
        "mean_length": 40.0, "command": f"drivelab train --seed {seed}", "blocks": blocks,
        "training_returns": [1.0, 2.0], "training_lengths": [50, 50],
    }  # fmt: skip


def test_summary_and_markdown(bench, tmp_path):
    block = lambda speed, steps, failures: {  # noqa: E731  (a block never reached has no means)
        "steps": steps, "speed_mps": speed, "steering_rad": 0.1 if steps else None,
        "failures_end_here": failures,
    }  # fmt: skip
    runs = [
        _run("ppo_topdown", 0, 0.5, {"I": block(4.0, 10, 1), "O": block(None, 0, 0)}),
        _run("ppo_topdown", 1, 0.7, {"I": block(6.0, 20, 2), "O": block(None, 0, 0)}),
        _run("ppo_topdown", 2, 0.9, {"I": block(8.0, 30, 0), "O": block(None, 0, 0)}),
    ]
    (row,) = bench.summarise(runs)
    success = row["success_rate"]
    assert success["mean"] == pytest.approx(0.7) and success["n"] == 3
    assert 0.5 <= success["low"] < 0.7 < success["high"] <= 0.9
    assert row["blocks"]["I"]["speed_mps"]["mean"] == pytest.approx(6.0)
    assert (row["blocks"]["I"]["steps"], row["blocks"]["I"]["failures_end_here"]) == (60, 3)
    assert row["blocks"]["O"]["speed_mps"]["mean"] is None  # never reached: no speed there
    result = {
        "command": "python benchmarks/seed003_osx.py", "machine": "test", "date": "today", "episodes": 20,
        "runs": runs, "summary": [row], "findings": "## Findings\n\n1. held",
    }  # fmt: skip
    path = tmp_path / "results.md"
    bench.write_markdown(result, path)
    text = path.read_text()
    assert f"| 0.70 [{success['low']:.2f}, {success['high']:.2f}] |" in text
    assert "| 6.0 / 0.100 / 60 / 3 | – / – / 0 / 0 |" in text
    assert "drivelab train --seed 2" in text and text.rstrip().endswith("1. held")
