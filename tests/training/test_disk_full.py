"""A full disk is one ``error:`` line naming it, exit 2, and no partial or temporary file left;
once space is freed the command (or a resume) works.

Before: training after its first checkpoint ended in a TensorBoard OSError traceback, evaluate left
a 0-byte eval.json.tmp (with --video, tracebacks and 0-byte videos), compare and resume gave
tracebacks (resume left learning_curve.tmp.png). The disk fills through ``FillingDisk``: the
kernel's own ENOSPC from /dev/full, for files already open and files opened later.
"""

import json
import os
import subprocess
import sys
from pathlib import Path

import imageio.v2 as imageio
import pytest
import yaml
from typer.testing import CliRunner

import drivelab
from drivelab.cli import app
from drivelab.training import checkpoints, plots
from drivelab.training import run as run_module
from drivelab.training.evaluate import load_run_config
from tests.training.filling_disk import FillingDisk
from tests.training.test_compare import fake_run
from tests.training.tiny_runs import tiny_config, tree

SOURCE = str(Path(drivelab.__file__).parents[1])  # the drivelab that these tests import
DISK_FULL = "no space left on device (the disk is full); free some space, then"
runner = CliRunner()


@pytest.fixture(scope="module")
def finished_run(tmp_path_factory) -> Path:
    """A finished tiny run with checkpoints (and a resume state) at step 128."""
    return run_module.train(tiny_config(), tmp_path_factory.mktemp("runs"))


@pytest.fixture
def disk(tmp_path):
    """Writes under ``tmp_path`` fail with ENOSPC once ``disk.fill()`` is called."""
    filling = FillingDisk(tmp_path).install()
    yield filling
    filling.uninstall()


def _copy(run_dir: Path, to: Path) -> Path:
    import shutil

    return Path(shutil.copytree(run_dir, to))


def disk_full_line(output: str, *fragments: str) -> str:
    """The last line of ``output``, its only ``error:`` line, naming a full disk and ``fragments``;
    the lines before it are progress bars; no traceback, no error printed while exiting."""
    lines = output.strip().splitlines()
    errors = [line for line in lines if "error" in line.lower() or "Traceback" in line or "Exception" in line]
    assert errors == [lines[-1]] and lines[-1].startswith("error: cannot write "), output
    for fragment in (DISK_FULL, *fragments):
        assert fragment in lines[-1], lines[-1]
    return lines[-1]


def _temporaries(root: Path) -> list[str]:
    return [str(path) for path in root.rglob("*") if ".tmp" in path.name]


def test_training_that_fills_the_disk_after_its_first_checkpoint(tmp_path):
    """In a process of its own, so that everything it prints until it exits is seen (a log file
    flushed at exit would print its failure after the error line). The run keeps its checkpoint and
    resumes once there is space."""
    runs, config = tmp_path / "runs", tmp_path / "config.yaml"
    config.write_text(yaml.safe_dump(tiny_config(name="full").to_dict()))
    script = f"""
import sys
from pathlib import Path
from tests.training.filling_disk import FillingDisk
from drivelab.training import run

disk = FillingDisk(Path({str(runs)!r})).install()
save_checkpoint = run.save_checkpoint

def save_then_fill(*args, **kwargs):
    path = save_checkpoint(*args, **kwargs)
    disk.fill()
    return path

run.save_checkpoint = save_then_fill
from drivelab.cli import main

sys.argv = ["drivelab", "train", "--config", {str(config)!r}, "--runs-dir", {str(runs)!r}]
main()
"""
    env = {**os.environ, "PYTHONPATH": SOURCE, "OMP_NUM_THREADS": "1"}
    command = [sys.executable, "-c", script]
    done = subprocess.run(command, capture_output=True, text=True, env=env, timeout=600)
    run_dir = runs / "full"
    assert done.returncode == 2, done.stderr
    disk_full_line(done.stderr, f"continue with `drivelab train --resume {run_dir}`")
    assert _temporaries(run_dir) == []
    assert checkpoints.verify_checkpoint(run_dir, load_run_config(run_dir))["steps"] == 64
    result = runner.invoke(app, ["train", "--resume", str(run_dir)])
    assert result.exit_code == 0, result.output
    assert (run_dir / "model.zip").is_file() and (run_dir / "learning_curve.png").is_file()


@pytest.mark.parametrize("video", ["no video", "video", "video written by ffmpeg"])
def test_evaluating_on_a_full_disk_writes_nothing(finished_run, tmp_path, disk, monkeypatch, video):
    run_dir = _copy(finished_run, tmp_path / "run")
    if video == "video":  # the encoder writes through Python: it meets the full disk itself

        def mimwrite(path, frames, **options):
            with open(path, "wb") as handle:
                handle.write(b"\0" * 4096)

        monkeypatch.setattr(imageio, "mimwrite", mimwrite)
    before = tree(tmp_path)
    disk.fill()
    command = ["evaluate", str(run_dir), "--episodes", "1"] + (["--video"] if video != "no video" else [])
    result = runner.invoke(app, command)
    assert result.exit_code == 2, result.output
    written = "videos/evaluate.mp4" if video == "video" else "eval.json"
    disk_full_line(result.output, str(run_dir / written), "run the command again")
    assert tree(tmp_path) == before  # with ffmpeg's video: removed with the report it belongs to
    disk.uninstall()
    result = runner.invoke(app, command)
    assert result.exit_code == 0, result.output
    assert json.loads((run_dir / "eval.json").read_text())["model_steps"] == 128


def test_a_comparison_on_a_full_disk_writes_nothing(tmp_path, disk):
    fake_run(tmp_path / "runs", "ppo-s0", seed=0, final_return=0.0)
    fake_run(tmp_path / "runs", "ppo-s1", seed=1, final_return=1.0)
    before = tree(tmp_path)
    disk.fill()
    command = ["compare", "--runs", str(tmp_path / "runs" / "*"), "-o", str(tmp_path / "report")]
    result = runner.invoke(app, command)
    assert result.exit_code == 2, result.output
    disk_full_line(result.output, f"cannot write a report in {str(tmp_path / 'report')!r}")
    assert tree(tmp_path) == before
    disk.uninstall()
    assert runner.invoke(app, command).exit_code == 0


def test_a_resume_on_a_full_disk_changes_nothing(finished_run, tmp_path, disk):
    run_dir = _copy(finished_run, tmp_path / "run")
    before = tree(tmp_path)
    disk.fill()
    result = runner.invoke(app, ["train", "--resume", str(run_dir), "--steps", "192"])
    assert result.exit_code == 2, result.output
    disk_full_line(result.output, str(run_dir / "config.yaml"), f"drivelab train --resume {run_dir}")
    assert tree(tmp_path) == before


def test_a_resume_that_fills_the_disk_with_its_learning_curve(finished_run, tmp_path, disk, monkeypatch):
    """The model and its curve go together: a curve that cannot be drawn takes the model with it,
    and the resume that follows, once there is space, writes both from the final checkpoint."""
    run_dir = _copy(finished_run, tmp_path / "run")
    plot = plots.plot_learning_curve

    def fill_then_plot(folder):
        disk.fill()
        return plot(folder)

    monkeypatch.setattr(plots, "plot_learning_curve", fill_then_plot)
    result = runner.invoke(app, ["train", "--resume", str(run_dir), "--steps", "192"])
    assert result.exit_code == 2, result.output
    disk_full_line(result.output, str(run_dir / "learning_curve.png"), f"drivelab train --resume {run_dir}")
    assert _temporaries(tmp_path) == [] and not (run_dir / "model.zip").exists()
    disk.uninstall()
    monkeypatch.undo()
    result = runner.invoke(app, ["train", "--resume", str(run_dir)])
    assert result.exit_code == 0, result.output
    assert (run_dir / "model.zip").is_file() and (run_dir / "learning_curve.png").is_file()
    assert json.loads((run_dir / "checkpoints" / "latest.json").read_text())["steps"] == 192
