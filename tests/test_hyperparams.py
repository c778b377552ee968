"""Shipped hyper-parameter files: lookup by scenario, overrides, and what a new run records."""

from importlib import resources

import yaml
from typer.testing import CliRunner

from drivelab.agents.registry import ALGORITHMS
from drivelab.cli import app
from drivelab.hyperparams import resolve_hyperparams, shipped_hyperparams, with_shipped_hyperparams


def test_scenario_entry_default_and_overrides():
    assert shipped_hyperparams("ppo", "racetrack")["gamma"] == 0.9  # highway-env's racetrack example
    assert shipped_hyperparams("ppo", "highway")["gamma"] == 0.8
    assert shipped_hyperparams("dqn", "no_such_scenario") == shipped_hyperparams("dqn", "default")
    assert shipped_hyperparams("no_such_algo", "highway") == {}
    merged = resolve_hyperparams("dqn", "merge", {"gamma": 0.95, "tau": 0.5})
    assert merged["gamma"] == 0.95 and merged["tau"] == 0.5 and merged["buffer_size"] == 15_000


def test_highway_files_hold_the_documented_defaults():
    # highway-env's scripts/sb3_highway_dqn.py and sb3_highway_ppo.py; every SB3 algorithm has a file
    dqn, ppo = shipped_hyperparams("dqn", "default"), shipped_hyperparams("ppo", "default")
    assert (dqn["learning_rate"], dqn["buffer_size"], dqn["gamma"], dqn["target_update_interval"]) == (
        5e-4, 15_000, 0.8, 50)  # fmt: skip
    assert (ppo["n_steps"], ppo["batch_size"], ppo["n_epochs"], ppo["gamma"]) == (256, 64, 10, 0.8)
    for algo, spec in ALGORITHMS.items():
        if spec.family == "sb3":
            assert shipped_hyperparams(algo, "highway") == shipped_hyperparams(algo, "default") != {}, algo


def test_every_file_names_a_registered_algorithm():
    files = [f.name for f in resources.files("drivelab.hyperparams").iterdir() if f.name.endswith(".yaml")]
    assert files and all(name.removesuffix(".yaml") in ALGORITHMS for name in files), files


def test_sb3_models_start_from_the_files_default_entry():
    import gymnasium

    from drivelab.agents.sb3 import build_sb3

    model = build_sb3("dqn", gymnasium.make("CartPole-v1"), 0, {"learning_starts": 7}, None)
    assert (model.gamma, model.buffer_size, model.learning_starts) == (0.8, 15_000, 7)


def test_lookups_are_independent_copies():
    first = shipped_hyperparams("ppo", "highway")
    first["policy_kwargs"]["net_arch"]["pi"].append(1)
    assert shipped_hyperparams("ppo", "highway")["policy_kwargs"]["net_arch"]["pi"] == [256, 256]


def test_with_shipped_hyperparams_uses_the_scenario():
    values = with_shipped_hyperparams({"algo": "a2c", "env": "racetrack", "hyperparams": {"n_steps": 5}})
    assert values["hyperparams"] == {"n_steps": 5, "learning_rate": 7e-4, "gamma": 0.9}
    assert with_shipped_hyperparams({"env": "highway"}) == {"env": "highway"}


def test_cli_train_records_resolved_hyperparams(tmp_path):
    config = tmp_path / "run.yaml"
    config.write_text(yaml.safe_dump({"env_options": {"duration_s": 8}, "traffic": "empty"}))
    result = CliRunner().invoke(
        app,
        ["train", "--algo", "ppo", "--steps", "32", "--eval-every", "32", "--eval-episodes", "1",
         "-H", "n_steps=16", "-H", "batch_size=16", "-H", "n_epochs=1", "-H", "gamma=0.5",
         "--config", str(config), "--name", "hp", "--runs-dir", str(tmp_path / "runs")],
    )  # fmt: skip
    assert result.exit_code == 0, result.output
    saved = yaml.safe_load((tmp_path / "runs" / "hp" / "config.yaml").read_text())["hyperparams"]
    assert saved["gamma"] == 0.5 and saved["n_steps"] == 16  # command line wins
    assert saved["learning_rate"] == 5e-4  # from drivelab/hyperparams/ppo.yaml
    assert saved["policy_kwargs"] == {"net_arch": {"pi": [256, 256], "vf": [256, 256]}}
