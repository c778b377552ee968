"""Nothing drivelab writes follows a link out of a run directory (``safe_files``).

A run directory (downloaded, shared) whose files or folders are symbolic links made ``evaluate``
and ``train --resume`` overwrite what the links point to, and a resume delete files in a folder
``checkpoints/`` linked to. Now such a run is refused with one ``error:`` line (exit 2) before
anything is written, and every file outside it, and in it, is as it was. Runs are tiny (PPO, 128
steps on an empty road).
"""

import shutil
from pathlib import Path

import pytest
from typer.testing import CliRunner

from drivelab.cli import app
from drivelab.training import run as run_module
from tests.training.tiny_runs import error_line, tiny_config, tree

# what the run writes, or writes a temporary of, on evaluate or resume; each planted as a link
LINKED = (
    "eval.json.tmp", "config.yaml", "monitor.csv", "evaluations.csv", "checkpoints/latest.tmp.zip",
    "model.tmp.zip", "learning_curve.tmp.png", "checkpoints/resume.tmp.json", "videos", "checkpoints",
)  # fmt: skip
COMMANDS = {
    "evaluate": lambda run_dir: ["evaluate", str(run_dir), "--episodes", "1", "--video"],
    "resume": lambda run_dir: ["train", "--resume", str(run_dir), "--steps", "192"],
}
runner = CliRunner()


@pytest.fixture(scope="module")
def finished_run(tmp_path_factory) -> Path:
    """A finished tiny run with checkpoints (and a resume state) at step 128."""
    return run_module.train(tiny_config(), tmp_path_factory.mktemp("runs"))


def _plant(run_dir: Path, member: str, outside: Path) -> None:
    """Make ``member`` of ``run_dir`` a link to ``outside``: the member itself moved there when it
    exists (so that the run still reads as it was), else a user's file (or folder) of that name."""
    path, target = run_dir / member, outside / member.replace("/", "-")
    if path.exists():
        shutil.move(path, target)
    elif member == "videos":
        target.mkdir()
        (target / "evaluate.mp4").write_bytes(b"the user's video")
    else:
        target.write_text("the user's thesis")
    if member == "checkpoints":
        (target / "resume-notes.txt").write_text("the user's notes")
    path.symlink_to(target)


@pytest.mark.parametrize("command", list(COMMANDS))
@pytest.mark.parametrize("member", LINKED)
def test_a_run_holding_a_link_is_refused_and_nothing_changes(finished_run, tmp_path, member, command):
    run_dir, outside = tmp_path / "run", tmp_path / "outside"
    shutil.copytree(finished_run, run_dir)
    outside.mkdir()
    _plant(run_dir, member, outside)
    before = tree(tmp_path)
    result = runner.invoke(app, COMMANDS[command](run_dir))
    assert result.exit_code == 2, result.output
    error_line(result.output, f"{str(run_dir / member)!r} is a symbolic link", "nothing was changed")
    assert tree(tmp_path) == before


def test_a_folder_where_the_report_is_written_first_is_one_line(finished_run, tmp_path):
    """``eval.json.tmp`` a folder: IsADirectoryError after the episodes, before."""
    run_dir = tmp_path / "run"
    shutil.copytree(finished_run, run_dir)
    (run_dir / "eval.json.tmp").mkdir()
    (run_dir / "eval.json.tmp" / "draft.md").write_text("the user's")
    before = tree(tmp_path)
    result = runner.invoke(app, COMMANDS["evaluate"](run_dir))
    assert result.exit_code == 2, result.output
    error_line(result.output, f"cannot write eval.json.tmp in {str(run_dir)!r}: it is a folder")
    assert tree(tmp_path) == before


def test_a_resume_deletes_only_the_resume_states_it_wrote(finished_run, tmp_path):
    """The earlier checkpoints' resume states go; a user's ``resume-notes.txt`` beside them stays
    (it matched the ``resume-*.*`` that was deleted)."""
    run_dir = tmp_path / "run"
    shutil.copytree(finished_run, run_dir)
    (run_dir / "checkpoints" / "resume-notes.txt").write_text("the user's notes")
    result = runner.invoke(app, COMMANDS["resume"](run_dir))
    assert result.exit_code == 0, result.output
    assert sorted(p.name for p in (run_dir / "checkpoints").iterdir()) == [
        "latest.json", "latest.zip", "resume-192.json", "resume-192.npz", "resume-notes.txt",
    ]  # fmt: skip
    assert (run_dir / "checkpoints" / "resume-notes.txt").read_text() == "the user's notes"


def test_an_evaluation_written_elsewhere_replaces_links_there_instead_of_writing_through(
    finished_run, tmp_path
):
    """``--out`` is a folder of the user's, where links may be theirs: eval.json, a link to a file
    outside, is replaced by the report; the file it pointed to is unchanged."""
    out, thesis = tmp_path / "report", tmp_path / "thesis.tex"
    out.mkdir()
    thesis.write_text("the user's thesis")
    (out / "eval.json").symlink_to(thesis)
    result = runner.invoke(app, ["evaluate", str(finished_run), "--episodes", "1", "--out", str(out)])
    assert result.exit_code == 0, result.output
    assert thesis.read_text() == "the user's thesis"
    assert not (out / "eval.json").is_symlink() and '"episodes": 1' in (out / "eval.json").read_text()
