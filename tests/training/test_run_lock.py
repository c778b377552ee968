"""One command at a time in a run directory (``safe_files.locked_run``, ``run._make_run_dir``).

Two ``drivelab train`` of one run name started together both trained into one folder (tracebacks,
evaluations.csv rows doubled, monitor.csv interleaved), and ``evaluate`` during training wrote an
eval.json of that moment's checkpoint. Now the second training is refused with one line and the
first one's files are whole; evaluate and resume of a run being trained are refused naming its
pid; and a run whose training was killed resumes (the kernel drops a dead process's lock).
"""

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pandas as pd
import pytest
import yaml
from typer.testing import CliRunner

import drivelab
from drivelab.cli import app
from drivelab.errors import UsageError
from drivelab.training import run as run_module
from drivelab.training.safe_files import IN_USE
from tests.training.tiny_runs import error_line, tiny_config

SOURCE = str(Path(drivelab.__file__).parents[1])  # the drivelab that these tests import
runner = CliRunner()


def _train_command(tmp_path: Path, **overrides) -> list[str]:
    """``drivelab train`` of ``tiny_config(**overrides)`` (run name "same") into ``tmp_path/runs``."""
    config = tmp_path / f"config-{len(list(tmp_path.glob('config-*')))}.yaml"
    config.write_text(yaml.safe_dump({**tiny_config(name="same", **overrides).to_dict()}))
    runs = tmp_path / "runs"
    return [sys.executable, "-m", "drivelab.cli", "train", "--config", str(config), "--runs-dir", str(runs)]


def _start(command: list[str]) -> subprocess.Popen:
    environment = {**os.environ, "PYTHONPATH": SOURCE, "OMP_NUM_THREADS": "1"}
    return subprocess.Popen(
        command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=environment
    )


def _assert_whole(run_dir: Path, steps: int, evaluations: list[int]) -> None:
    """A finished run of ``steps`` steps written by one process: its model, a checkpoint of its
    last step, one evaluation row per evaluation, one monitor.csv header, no lock file."""
    assert (run_dir / "model.zip").is_file() and not (run_dir / IN_USE).exists()
    assert json.loads((run_dir / "checkpoints" / "latest.json").read_text())["steps"] == steps
    assert pd.read_csv(run_dir / "evaluations.csv")["step"].tolist() == evaluations
    monitor = (run_dir / "monitor.csv").read_text().splitlines()
    assert sum(line.startswith("#") for line in monitor) == 1 and monitor[1] == "r,l,t"
    assert pd.read_csv(run_dir / "monitor.csv", skiprows=1)["l"].sum() <= steps


def test_two_trainings_of_one_run_started_together(tmp_path):
    """Each finds the folder missing; one makes it, the other's ``mkdir`` then fails: refused with
    one line (or, started later, refused as an existing run), the first one's run whole. The
    second asks for other settings, as when two people picked one name."""
    first = _start(_train_command(tmp_path, eval_every=64))
    second = _start(_train_command(tmp_path, eval_every=64, seed=2))
    outcomes = [process.communicate(timeout=600) for process in (first, second)]
    codes = [first.returncode, second.returncode]
    assert sorted(codes) == [0, 2], outcomes
    _, refused_err = outcomes[codes.index(2)]
    run_dir = tmp_path / "runs" / "same"
    error_line(refused_err, f"run directory {str(run_dir)!r} already exists")
    seed = yaml.safe_load((run_dir / "config.yaml").read_text())["seed"]
    assert seed == (1 if codes[0] == 0 else 2)  # the config of the run that trained
    _assert_whole(run_dir, 128, [64, 128])


def test_a_run_made_while_another_command_checked_its_config_is_left_alone(tmp_path, monkeypatch):
    """The race made certain: the other command makes and trains the run while this one builds its
    agent (``check_config``), after this one found no folder."""
    config, theirs = tiny_config(steps=64, eval_every=64), []
    check_config = run_module.check_config

    def slow_check(checked):
        spec = check_config(checked)
        if checked.seed == 2:  # this command's check: theirs runs meanwhile
            theirs.append(run_module.train(config, tmp_path))
        return spec

    monkeypatch.setattr(run_module, "check_config", slow_check)
    with pytest.raises(UsageError, match="already exists"):
        run_module.train(tiny_config(steps=64, eval_every=64, seed=2), tmp_path)
    assert theirs == [tmp_path / "r"]
    _assert_whole(tmp_path / "r", 64, [64])


def test_a_run_being_trained_is_not_evaluated_or_resumed_and_resumes_after_a_kill(tmp_path):
    """While ``drivelab train`` runs, evaluate and resume are refused naming its pid, and change
    nothing; killed (SIGKILL: no cleanup), its run resumes from its last checkpoint."""
    training = _start(_train_command(tmp_path, steps=4096, eval_every=4096, checkpoint_every=64))
    run_dir = tmp_path / "runs" / "same"
    try:
        deadline = time.monotonic() + 300
        while not (run_dir / "checkpoints" / "latest.json").is_file():
            assert training.poll() is None and time.monotonic() < deadline, training.communicate()
            time.sleep(0.2)
        config = (run_dir / "config.yaml").read_bytes()
        for command in (["evaluate", str(run_dir), "--episodes", "1"], ["train", "--resume", str(run_dir)]):
            result = runner.invoke(app, command)
            assert result.exit_code == 2, result.output
            error_line(result.output, f"is in use by another drivelab process (pid {training.pid})")
        assert not (run_dir / "eval.json").exists() and (run_dir / "config.yaml").read_bytes() == config
    finally:
        training.send_signal(signal.SIGKILL)
        training.communicate(timeout=60)
    steps = json.loads((run_dir / "checkpoints" / "latest.json").read_text())["steps"]
    result = runner.invoke(app, ["train", "--resume", str(run_dir), "--steps", str(steps + 64)])
    assert result.exit_code == 0, result.output
    assert json.loads((run_dir / "checkpoints" / "latest.json").read_text())["steps"] == steps + 64
    assert (run_dir / "model.zip").is_file() and not (run_dir / IN_USE).exists()
