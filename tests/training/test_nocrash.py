"""NoCrash-style evaluation of a town run (tiny budgets)."""

import hashlib
import json

import pytest

from drivelab.config import build_config
from drivelab.errors import UsageError
from drivelab.training import run as run_module
from drivelab.training.nocrash import LEVELS, NOCRASH_SEED, nocrash


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
    assert saved["model"] == "model.zip" and saved["seed"] == NOCRASH_SEED
    assert saved["model_sha256"] == hashlib.sha256((run_dir / "model.zip").read_bytes()).hexdigest()
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


def test_the_expert_trains_and_is_evaluated_like_any_algorithm(tmp_path):
    config = build_config(
        {"algo": "expert", "env": "town", "obs": "waypoints,affordances", "action": "target_speed",
         "traffic": "empty", "steps": 20, "seed": 0, "name": "expert", "eval_every": 20, "eval_episodes": 1,
         "env_options": {"duration_s": 2}}
    )  # fmt: skip
    run_dir = run_module.train(config, tmp_path)
    assert (run_dir / "model.zip").is_file() and (run_dir / "evaluations.csv").is_file()
    report = nocrash(run_dir, town="test", episodes=1)
    assert report["algo"] == "expert" and set(report["levels"]) == set(LEVELS)
    assert "collisions with pedestrians / km" in (run_dir / "nocrash.md").read_text()


def test_fixed_routes_get_the_corl2017_time_limit():
    from drivelab.envs.core import DriveEnv

    options = {"layout": "test", "fixed_routes": True, "retarget": False}
    env = DriveEnv("town", obs="waypoints", action="target_speed", traffic="empty", backend_options=options)
    env.reset(seed=3)
    route = env.world.route
    assert env.time_limit_s == pytest.approx((route.length_m - route.progress_m) / (10 / 3.6) + 10.0)
    capped = DriveEnv("town", obs="waypoints", action="target_speed", traffic="empty", duration_s=5,
                      backend_options=options)  # fmt: skip
    capped.reset(seed=3)
    assert capped.time_limit_s == 5.0
