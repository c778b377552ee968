"""The writing primitives of ``training/safe_files.py``: temporaries created exclusively, renames
that replace links instead of writing through them, deletions of files only, the run lock, and
the one line of a failed write."""

import errno
import os
import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace

import pytest

import drivelab
from drivelab.errors import UsageError
from drivelab.training import safe_files
from drivelab.training.safe_files import (
    IN_USE,
    check_run_members,
    locked_run,
    remove_file,
    replacing,
    write_failure,
    write_file,
)

SOURCE = str(Path(drivelab.__file__).parents[1])  # the drivelab that these tests import


@pytest.fixture
def outside(tmp_path):
    """A user's file outside the folder drivelab writes in."""
    path = tmp_path / "thesis.tex"
    path.write_text("the user's")
    return path


def test_a_file_is_written_whole_and_its_temporary_goes(tmp_path):
    write_file(tmp_path / "eval.json", "{}")
    write_file(tmp_path / "eval.json", '{"a": 1}')
    assert [p.name for p in tmp_path.iterdir()] == ["eval.json"]
    assert (tmp_path / "eval.json").read_text() == '{"a": 1}'


def test_a_link_at_the_name_is_replaced_not_written_through(tmp_path, outside):
    (tmp_path / "eval.json").symlink_to(outside)
    write_file(tmp_path / "eval.json", "{}")
    assert outside.read_text() == "the user's"
    assert not (tmp_path / "eval.json").is_symlink() and (tmp_path / "eval.json").read_text() == "{}"


@pytest.mark.parametrize("kind", ["link to a file", "dangling link", "folder"])
def test_a_temporary_name_holding_anything_but_a_file_is_refused(tmp_path, outside, kind):
    temporary = tmp_path / "eval.json.tmp"
    if kind == "folder":
        temporary.mkdir()
    else:
        temporary.symlink_to(outside if kind == "link to a file" else tmp_path / "nowhere")
    link, folder = (
        "eval.json.tmp' is a symbolic link: drivelab neither",
        "cannot write eval.json.tmp in .*: it is a folder",
    )
    refused = f"({link}|{folder})"
    with pytest.raises(UsageError, match=refused):
        write_file(tmp_path / "eval.json", "{}")
    assert outside.read_text() == "the user's" and not (tmp_path / "eval.json").exists()
    assert not (tmp_path / "nowhere").exists()


def test_a_temporary_left_by_a_killed_command_is_replaced(tmp_path):
    (tmp_path / "eval.json.tmp").write_text("half of a report")
    write_file(tmp_path / "eval.json", "{}")
    assert [p.name for p in tmp_path.iterdir()] == ["eval.json"]


def test_a_failed_write_leaves_no_temporary_and_is_one_line(tmp_path):
    with pytest.raises(
        UsageError, match=r"^cannot write '.*model.zip': no space left on device \(the disk is full\)"
    ):
        with replacing(tmp_path / "model.zip", tmp_path / "model.tmp.zip") as temporary:
            temporary.write_bytes(b"half a model")
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
    with pytest.raises(KeyError):
        with replacing(tmp_path / "model.zip") as temporary:
            raise KeyError("not a write")
    assert list(tmp_path.iterdir()) == []


def test_a_temporary_replaced_while_it_was_written_is_not_renamed(tmp_path, outside):
    with pytest.raises(UsageError, match="was replaced while drivelab wrote it"):
        with replacing(tmp_path / "eval.json") as temporary:
            temporary.unlink()
            temporary.symlink_to(outside)
    assert not (tmp_path / "eval.json").exists() and outside.read_text() == "the user's"


def test_write_failures_name_a_full_disk(tmp_path, monkeypatch):
    full = write_failure(OSError(errno.EDQUOT, "Disk quota exceeded"), tmp_path / "x", then="resume")
    disk_full = "no space left on device (the disk is full); free some space, then resume"
    assert str(full) == f"cannot write {str(tmp_path / 'x')!r}: {disk_full}"
    assert str(write_failure(OSError(errno.EROFS, "Read-only file system"), tmp_path)).endswith(
        ": Read-only file system"
    )
    # ffmpeg reports a failed write through its pipe, without an errno: the free space tells
    ffmpeg = OSError("[Errno 32] Broken pipe\n\nFFMPEG COMMAND:\nffmpeg -y ...")
    monkeypatch.setattr(safe_files.shutil, "disk_usage", lambda path: SimpleNamespace(free=4096))
    assert write_failure(ffmpeg, tmp_path / "v.mp4").disk_full
    monkeypatch.setattr(safe_files.shutil, "disk_usage", lambda path: SimpleNamespace(free=10 << 30))
    assert str(write_failure(ffmpeg, tmp_path / "v.mp4")).endswith(": [Errno 32] Broken pipe")


def test_only_files_are_removed(tmp_path, outside):
    (tmp_path / "link").symlink_to(outside)
    (tmp_path / "folder").mkdir()
    (tmp_path / "file").write_text("x")
    with pytest.raises(
        UsageError, match="link' is a symbolic link: drivelab neither writes nor deletes through"
    ):
        remove_file(tmp_path / "link")
    with pytest.raises(UsageError, match="folder' is a folder, where drivelab deletes a file of its own"):
        remove_file(tmp_path / "folder")
    remove_file(tmp_path / "file")
    remove_file(tmp_path / "missing")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["folder", "link", "thesis.tex"]
    assert outside.read_text() == "the user's"


@pytest.mark.parametrize(
    ("member", "kind", "message"),
    [
        ("config.yaml", "link", "config.yaml' is a symbolic link: drivelab neither writes nor deletes"),
        ("notes", "link", "notes' is a symbolic link"),  # any link at the top: drivelab reads its files
        ("checkpoints", "link", "checkpoints' is a symbolic link"),
        ("videos", "file", "videos' is a file, where drivelab keeps a folder of its own files"),
        ("checkpoints/resume-64.json", "link", "resume-64.json' is a symbolic link"),
        ("checkpoints/old", "folder", "old' is a folder, where drivelab keeps its own files"),
        ("eval.json.tmp", "folder", "cannot write eval.json.tmp in '.*run': it is a folder"),
    ],
)
def test_members_drivelab_could_write_through_are_refused(tmp_path, outside, member, kind, message):
    run_dir = tmp_path / "run"
    (run_dir / "checkpoints").mkdir(parents=True)
    (run_dir / "config.yaml").write_text("algo: ppo\n")
    (run_dir / "notes.txt").write_text("a user's file is no link: it stays allowed")
    check_run_members(run_dir)
    path = run_dir / member
    if path.is_file():
        path.unlink()
    if kind == "link":
        if path.is_dir():
            path.rmdir()
        path.symlink_to(outside)
    elif kind == "folder":
        path.mkdir()
    else:
        path.write_text("x")
    with pytest.raises(UsageError, match=message):
        check_run_members(run_dir)


def test_a_run_in_use_is_refused_naming_the_process(tmp_path):
    run_dir = tmp_path / "run"
    run_dir.mkdir()
    with locked_run(run_dir):
        assert (run_dir / IN_USE).read_text() == f"{os.getpid()}\n"
        for writes in (True, False):
            with pytest.raises(
                UsageError, match=rf"is in use by another drivelab process \(pid {os.getpid()}\)"
            ):
                with locked_run(run_dir, writes=writes):
                    pass
    assert list(run_dir.iterdir()) == []  # the pid goes with the lock
    with locked_run(run_dir, writes=False), locked_run(run_dir, writes=False):
        assert list(run_dir.iterdir()) == []  # readers share it and write nothing


def test_the_lock_of_a_killed_process_is_gone(tmp_path):
    """The kernel lets go of a flock when its process dies: a run killed while training resumes."""
    run_dir = tmp_path / "run"
    run_dir.mkdir()
    hold = (
        "import sys\nfrom pathlib import Path\nfrom drivelab.training.safe_files import locked_run\n"
        f"with locked_run(Path({str(run_dir)!r})):\n    print('held', flush=True)\n    sys.stdin.read()"
    )
    env = {**os.environ, "PYTHONPATH": SOURCE}
    holder = subprocess.Popen(
        [sys.executable, "-c", hold],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
        env=env,
    )
    try:
        assert holder.stdout.readline() == "held\n"
        with pytest.raises(UsageError, match=rf"\(pid {holder.pid}\)"):
            with locked_run(run_dir):
                pass
    finally:
        holder.kill()
        holder.wait(timeout=30)
    assert (run_dir / IN_USE).read_text() == f"{holder.pid}\n"  # SIGKILL: no cleanup, a stale pid
    with locked_run(run_dir):
        assert (run_dir / IN_USE).read_text() == f"{os.getpid()}\n"
    assert list(run_dir.iterdir()) == []
