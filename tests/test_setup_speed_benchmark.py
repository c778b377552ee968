"""benchmarks/setup_speed.py: a reference tree is checked before anything is timed or written."""

import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).parents[1]
SCRIPT = ROOT / "benchmarks" / "setup_speed.py"
RESULTS = ROOT / "benchmarks" / "results"


def _run(*arguments, env=None):
    return subprocess.run(
        [sys.executable, str(SCRIPT), *arguments], capture_output=True, text=True, env=env, cwd=ROOT
    )


def _results():
    return {p.name: p.read_bytes() for p in RESULTS.glob("setup_speed.*")}


@pytest.mark.parametrize(
    ("against", "message"),
    [("missing", "no drivelab package"), ("empty", "no drivelab package"), (".", "this checkout")],
)
def test_a_reference_that_is_not_another_drivelab_tree_is_one_error_line(tmp_path, against, message):
    (tmp_path / "empty").mkdir()
    path = ROOT if against == "." else tmp_path / against
    before = _results()
    done = _run("--against", str(path), "--seeds", "1", "--repeats", "1")
    assert done.returncode == 2 and done.stdout == ""
    assert done.stderr.startswith("error: --against") and len(done.stderr.splitlines()) == 1
    assert message in done.stderr
    assert _results() == before


@pytest.mark.parametrize("folder", [True, False])
def test_a_pass_refuses_to_time_a_drivelab_other_than_its_trees(tmp_path, folder):
    """A reference tree whose drivelab does not import from it (a folder that is no package, or
    none, so that the installed drivelab is imported) would time some other tree."""
    if folder:
        (tmp_path / "drivelab").mkdir()
    env = {**os.environ, "PYTHONPATH": str(tmp_path)}
    done = _run("--pass", "1", env=env)
    assert done.returncode == 2 and done.stdout == ""
    assert done.stderr.startswith("error: ") and "has no drivelab of its own" in done.stderr
    assert len(done.stderr.splitlines()) == 1
