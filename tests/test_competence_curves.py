"""benchmarks/competence_curves.py: a curve stops one run at its periodic evaluations and resumes it,
so its last point is the recipe's own uninterrupted run, value for value."""

import importlib.util
import os
import sys
from pathlib import Path

import pytest

BENCHMARKS = Path(__file__).parents[1] / "benchmarks"


@pytest.fixture(scope="module")
def curves():
    """The script as a module; the thread counts it sets for its own process are put back."""
    saved = {key: os.environ.get(key) for key in ("OMP_NUM_THREADS", "NUMBA_NUM_THREADS")}
    sys.path.insert(0, str(BENCHMARKS))
    try:
        spec = importlib.util.spec_from_file_location(
            "competence_curves", BENCHMARKS / "competence_curves.py"
        )
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
    finally:
        sys.path.remove(str(BENCHMARKS))
        for key, value in saved.items():
            if value is None:
                os.environ.pop(key, None)
            else:
                os.environ[key] = value
    return module


def test_chunks_are_whole_rollouts_ending_at_the_budget(curves):
    assert curves.chunk_steps(1536, 256, 3) == [512, 1024, 1536]
    assert curves.chunk_steps(1000, 256, 8) == [256, 512, 768, 1000]  # never a chunk under a rollout


def test_a_curve_is_the_uninterrupted_run(curves, tmp_path, monkeypatch):
    from drivelab.cli import train_config
    from drivelab.config import build_config
    from drivelab.training.run import train
    from drivelab.training.zoo import model_differences

    board = curves.leaderboard
    entry = board.Entry(
        "highway", "tiny", "a tiny annealed recipe",
        tuple("--env highway --algo ppo_own --obs kinematics --action meta --traffic regular --n-envs 8 "
              "--steps 1536 --eval-episodes 1 -H n_steps=32 -H batch_size=128 -H n_epochs=1 "
              "-H linear_lr=true".split()),
    )  # fmt: skip
    monkeypatch.setattr(curves, "RUNS", tmp_path / "curves")
    monkeypatch.chdir(curves.ROOT)  # curve() works from the repository, as the recipes' paths need
    record = curves.curve(entry, points=3, episodes=1)
    steps = [point["steps"] for point in record["points"]]
    assert steps[-1] == 1536 and steps == sorted(set(steps)) and len(steps) >= 3
    walls = [point["train_wall_s"] for point in record["points"]]
    assert walls == sorted(walls) and walls[0] > 0

    config = train_config(entry.command(0)[1:])
    train(build_config({**config.to_dict(), "name": "whole"}), tmp_path)
    stopped = tmp_path / "curves" / "highway-tiny-s0" / "model.zip"
    assert model_differences(stopped, tmp_path / "whole" / "model.zip") == {}
