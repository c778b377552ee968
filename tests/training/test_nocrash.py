"""NoCrash-style evaluation of a town run (tiny budgets)."""

import json

import pytest

from drivelab.config import build_config
from drivelab.errors import UsageError
from drivelab.training import run as run_module
from drivelab.training.nocrash import LEVELS, nocrash


def _town_run(tmp_path):
    config = build_config(
        {"algo": "ppo", "env": "town", "obs": "waypoints", "action": "target_speed", "traffic": "empty",
         "steps": 16, "seed": 0, "name": "town", "eval_every": 16, "eval_episodes": 1,
         "hyperparams": {"n_steps": 16, "batch_size": 16, "n_epochs": 1}, "env_options": {"duration_s": 1}}
    )  # fmt: skip
    return run_module.train(config, tmp_path)


def test_nocrash_tables_for_every_traffic_level(tmp_path):
    run_dir = _town_run(tmp_path)
    report = nocrash(run_dir, town="test", episodes=2)
    assert set(report["levels"]) == set(LEVELS)
    for level in LEVELS:
        row = report["levels"][level]
        assert row["episodes"] == 2 and 0.0 <= row["success_rate"] <= 1.0
        assert {"red_lights_per_km", "blocked_per_km", "collisions_per_km", "route_completion"} <= set(row)
    saved = json.loads((run_dir / "nocrash.json").read_text())
    assert saved["town"] == "test" and saved["episodes_per_level"] == 2
    table = (run_dir / "nocrash.md").read_text()
    assert "| regular |" in table and "red lights run / km" in table
    # the same seeds and fixed routes: a second evaluation gives the same numbers
    assert nocrash(run_dir, town="test", episodes=2)["levels"] == report["levels"]


def test_nocrash_bad_input(tmp_path):
    run_dir = _town_run(tmp_path)
    with pytest.raises(UsageError, match="unknown town 'nowhere'"):
        nocrash(run_dir, town="nowhere")
    with pytest.raises(UsageError, match="episodes must be >= 1"):
        nocrash(run_dir, episodes=0)
    highway = run_module.train(
        build_config({"algo": "ppo", "steps": 16, "name": "hw", "traffic": "empty", "eval_episodes": 1,
                      "hyperparams": {"n_steps": 16, "batch_size": 16, "n_epochs": 1},
                      "env_options": {"duration_s": 2}}),
        tmp_path,
    )  # fmt: skip
    with pytest.raises(UsageError, match="NoCrash evaluates town runs"):
        nocrash(highway)
    assert not (run_dir / "nocrash.json").exists() and not (run_dir / "nocrash.md").exists()
