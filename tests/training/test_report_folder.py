"""``compare -o`` deletes only what a drivelab report wrote (``compare.publish_dir``).

A ``report-manifest.json`` listing ``thesis.tex`` and ``data`` made compare delete that file and
that whole folder (the manifest was trusted, not checked to be drivelab's own), and a user's folder
named ``.report.tmp-notes`` was deleted as a stale temporary. Now a manifest naming anything but a
report's files is refused with one line, and only a folder holding nothing but a report's files
counts as a report's temporary folder.
"""

import json

import pytest
from typer.testing import CliRunner

from drivelab.cli import app
from drivelab.training.compare import compare
from tests.training.test_compare import fake_run
from tests.training.tiny_runs import error_line, tree

runner = CliRunner()


@pytest.fixture
def runs(tmp_path):
    root = tmp_path / "runs"
    fake_run(root, "ppo-s0", seed=0, final_return=0.0)
    fake_run(root, "ppo-s1", seed=1, final_return=1.0)
    return root


def _refused(runs, out, root, *fragments):
    """``drivelab compare`` of ``runs`` into ``out``: one error line holding ``fragments``, exit 2,
    nothing under ``root`` changed."""
    before = tree(root)
    result = runner.invoke(app, ["compare", "--runs", str(runs / "*"), "-o", str(out)])
    assert result.exit_code == 2, result.output
    error_line(result.output, *fragments)
    assert tree(root) == before


@pytest.mark.parametrize("listed", [["thesis.tex", "data"], ["report.md", "data"], ["../x"]])
def test_a_manifest_that_is_not_drivelabs_deletes_nothing(runs, tmp_path, listed):
    out = tmp_path / "out"
    (out / "data").mkdir(parents=True)
    (out / "data" / "results.csv").write_text("the user's")
    (out / "thesis.tex").write_text("the user's")
    (out / "report.md").write_text("the user's notes")
    (out / "report-manifest.json").write_text(json.dumps({"files": listed}))
    foreign = next(name for name in listed if name != "report.md")
    _refused(runs, out, tmp_path, f"lists {foreign!r}, which no drivelab report writes", "deletes nothing")


def test_a_report_file_name_that_is_a_folder_is_not_deleted(runs, tmp_path):
    out = compare([str(runs / "*")], tmp_path / "out")
    (out / "metrics.png").unlink()
    (out / "metrics.png").mkdir()
    (out / "metrics.png" / "mine.png").write_text("the user's")
    _refused(runs, out, tmp_path, "metrics.png' is a folder, not a file of a drivelab report")


def test_a_users_folder_named_like_a_temporary_report_stays(runs, tmp_path):
    out = compare([str(runs / "*")], tmp_path / "out")
    notes = out / ".report.tmp-notes"
    notes.mkdir()
    (notes / "notes.txt").write_text("the user's")
    (notes / "report.md").write_text("a draft of the user's")
    compare([str(runs / "*")], out)
    assert sorted(p.name for p in notes.iterdir()) == ["notes.txt", "report.md"]
    # in a folder without a report, it makes the folder the user's: refused, nothing deleted
    lone = tmp_path / "lone"
    (lone / ".report.tmp-notes").mkdir(parents=True)
    (lone / ".report.tmp-notes" / "notes.txt").write_text("the user's")
    _refused(runs, lone, tmp_path, "is not empty and holds no drivelab report")


def test_a_temporary_report_of_a_killed_compare_holding_only_report_files_is_removed(runs, tmp_path):
    out = compare([str(runs / "*")], tmp_path / "out")
    killed = out / ".report.tmp-x1y2z3w4"
    killed.mkdir()
    (killed / "report.md").write_text("half a report")
    (killed / "summary.csv").write_text("half")
    compare([str(runs / "*")], out)
    assert not killed.exists()
