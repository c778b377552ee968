"""The CLI: bad input gives a one-line error, exit code 2, and writes nothing."""

import subprocess
import sys

import pytest
from typer.testing import CliRunner

from drivelab.cli import app

runner = CliRunner()


def _run(args, tmp_path):
    return runner.invoke(app, args, catch_exceptions=False)


@pytest.mark.parametrize(
    "args, message",
    [
        (["--algo", "magic"], "unknown algorithm 'magic'"),
        (["--algo", "ppo", "--env", "moon"], "unknown scenario 'moon'"),
        (["--algo", "ppo", "--obs", "sonar"], "unknown sensor 'sonar'"),
        (["--algo", "ppo", "--reward", "nice"], "unknown reward preset 'nice'"),
        (["--algo", "dqn", "--action", "continuous"], "algorithm 'dqn' cannot take 'continuous' actions"),
        (["--algo", "sac", "--action", "meta"], "algorithm 'sac' cannot take 'meta' actions"),
        (["--algo", "ppo", "-H", "learning_rate"], "must look like key=value"),
    ],
)
def test_train_bad_input(tmp_path, args, message):
    runs = tmp_path / "runs"
    result = runner.invoke(app, ["train", *args, "--runs-dir", str(runs), "--steps", "10"])
    assert result.exit_code == 2
    assert message in result.output
    assert len(result.output.strip().splitlines()) == 1
    assert not runs.exists()


def test_train_malformed_yaml(tmp_path):
    config = tmp_path / "run.yaml"
    config.write_text("algo: ppo\nobs: [lidar\n")
    runs = tmp_path / "runs"
    result = runner.invoke(app, ["train", "--config", str(config), "--runs-dir", str(runs)])
    assert result.exit_code == 2
    assert "malformed YAML" in result.output
    assert not runs.exists()


def test_bad_hyperparameter_leaves_nothing(tmp_path):
    runs = tmp_path / "runs"
    result = runner.invoke(
        app, ["train", "--algo", "ppo", "-H", "bogus_option=1", "--runs-dir", str(runs), "--steps", "10"]
    )
    assert result.exit_code == 2
    assert "unknown hyperparameter 'bogus_option' for 'ppo'" in result.output
    assert not runs.exists()  # not even an empty runs root


@pytest.mark.parametrize(
    "command",
    [["evaluate", "nowhere"], ["train", "--resume", "nowhere"], ["benchmark", "nocrash", "nowhere"]],
)
def test_missing_run_directory(tmp_path, command):
    result = runner.invoke(app, [*command[:-1], str(tmp_path / command[-1])])
    assert result.exit_code == 2
    assert "does not exist" in result.output


def test_envs_lists_one_line_each():
    result = runner.invoke(app, ["envs"])
    assert result.exit_code == 0
    lines = result.output.strip().splitlines()
    kinds = {line.split()[0] for line in lines}
    assert kinds == {"scenario", "sensor", "action", "reward", "algo"}
    names = {line.split()[1] for line in lines}
    assert {
        "highway",
        "racetrack",
        "lidar",
        "topdown",
        "grid",
        "metadrive_course",
        "safety_dqn",
        "sac",
    } <= names


def test_console_script_exit_code():
    result = subprocess.run(
        [sys.executable, "-m", "drivelab.cli", "train", "--algo", "nope"], capture_output=True, text=True
    )
    assert result.returncode == 2
    assert result.stderr.strip() == (
        "error: unknown algorithm 'nope' "
        "(choose from dqn, ppo, a2c, sac, dueling_ddqn, a2c_own, ppo_own, rlad, drq, qlearning, expert, bc, "
        "dagger)"
    )


def test_console_script_usage_error_is_one_line():
    """click's own parsing errors (a value of the wrong type) through the console script's path."""
    result = subprocess.run(
        [sys.executable, "-m", "drivelab.cli", "train", "--seed", "abc"], capture_output=True, text=True
    )
    assert result.returncode == 2 and result.stdout == ""
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: invalid value for '--seed'")
    assert lines[0].endswith("train --help`)")


def test_ctrl_c_saves_a_checkpoint_and_says_how_to_resume(tmp_path):
    import json
    import signal
    import time

    run_dir = tmp_path / "runs" / "interrupted"
    process = subprocess.Popen(
        [sys.executable, "-m", "drivelab.cli", "train", "--algo", "ppo", "--traffic", "empty",
         "--steps", "1000000", "--checkpoint-every", "1000000", "--eval-every", "1000000",
         "--runs-dir", str(tmp_path / "runs"), "--name", "interrupted"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    deadline = time.monotonic() + 180  # generous: start-up is slow on a loaded machine
    monitor = run_dir / "monitor.csv"  # two header lines, then one line per finished episode
    while time.monotonic() < deadline and not (
        monitor.exists() and len(monitor.read_text().splitlines()) > 2
    ):
        time.sleep(0.2)
    process.send_signal(signal.SIGINT)
    _, stderr = process.communicate(timeout=60)
    assert process.returncode == 130
    manifest = json.loads((run_dir / "checkpoints" / "latest.json").read_text())
    # the state at the start of the rollout the signal fell in (PPO's rollouts: 256 steps), from
    # which a resume continues exactly as the uninterrupted run (tests/training/test_resume.py)
    assert manifest["steps"] % 256 == 0 and manifest["steps"] < 1_000_000
    assert (run_dir / "checkpoints" / f"resume-{manifest['steps']}.json").is_file()
    assert f"drivelab train --resume {run_dir}" in stderr.strip().splitlines()[-1]


def test_version_through_the_script_and_python_dash_m():
    """``drivelab --version`` and ``python -m drivelab --version`` print the package's version, the
    one pyproject.toml declares; the licence is declared there and shipped as LICENSE."""
    import tomllib
    from pathlib import Path

    import drivelab

    root = Path(__file__).resolve().parents[1]
    expected = f"drivelab {drivelab.__version__}"
    assert runner.invoke(app, ["--version"]).output.strip() == expected
    done = subprocess.run([sys.executable, "-m", "drivelab", "--version"], capture_output=True, text=True)
    assert done.returncode == 0 and done.stdout.strip() == expected
    project = tomllib.loads((root / "pyproject.toml").read_text())["project"]
    assert project["version"] == drivelab.__version__
    assert project["license"] == "MIT" and (root / "LICENSE").read_text().startswith("MIT License")


def _option_help(command: str) -> dict[str, str]:
    import typer

    params = typer.main.get_command(app).get_command(None, command).params
    return {param.name: param.help or "" for param in params}


def test_help_shows_the_defaults_a_new_run_takes():
    """train's run options are None unless given (the --config file's value comes next), so typer
    showed no default for them: each help now ends in what a run takes, as build_config fills it."""
    from drivelab.config import build_config

    config = build_config({"algo": "ppo"})
    train_help, ablate_help = _option_help("train"), _option_help("ablate")
    for field in ("env", "steps", "seed", "traffic", "backend", "eval_every", "eval_episodes",
                  "checkpoint_every", "n_envs"):  # fmt: skip
        assert train_help[field].endswith(f"(default: {getattr(config, field)})"), field
    for helps in (train_help, ablate_help):
        assert helps["obs"].endswith(f"(default: {','.join(config.obs)})")
        assert helps["action"].endswith(f"highway: {config.action})")
        assert helps["traffic"].endswith(f"(default: {config.traffic})")
    assert train_help["reward"].endswith(f"highway: {config.reward})")
    result = runner.invoke(app, ["train", "--help"], env={"COLUMNS": "200"})
    assert result.exit_code == 0
    assert "total environment steps (default: 10000)" in result.output
    assert "[default: runs]" in result.output  # typer's own, for an option with a default value


def test_train_ends_by_printing_its_last_evaluation(tmp_path):
    import csv

    from drivelab.yaml_io import dump_yaml
    from tests.training.tiny_runs import tiny_config

    config = tmp_path / "tiny.yaml"
    config.write_text(dump_yaml({**tiny_config().to_dict(), "name": "tiny"}))
    result = runner.invoke(
        app, ["train", "--config", str(config), "--runs-dir", str(tmp_path / "runs")], env={"COLUMNS": "200"}
    )
    assert result.exit_code == 0, result.output
    with (tmp_path / "runs" / "tiny" / "evaluations.csv").open() as handle:
        last = list(csv.DictReader(handle))[-1]
    table = result.output[result.output.index("ppo on highway at step 128: 1 episodes") :]
    assert f"{float(last['mean_return']):.3f} ± {float(last['std_return']):.3f}" in table
    assert f"{float(last['mean_speed_mps']):.3f}" in table
    assert "success rate (no goal here: the time limit reached" in table and "route completion" in table
    assert result.output.rstrip().endswith(f"run directory: {tmp_path / 'runs' / 'tiny'}")
