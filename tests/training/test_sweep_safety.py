"""Sweeps never delete what is not theirs: a damaged run (a checkpoint or model without a readable
manifest) or a folder holding files a run does not write is refused, one line and exit 2, before
any cell runs (``--dry-run`` too), and a restart removes only the files of a run stopped before
its first checkpoint. The run directories are made by hand: nothing is trained."""

from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path

import pytest
import yaml
from typer.testing import CliRunner

from drivelab.cli import app
from drivelab.config import build_config, save_yaml
from drivelab.errors import UsageError
from drivelab.training.sweep import expand_sweep, plan, run_cell

runner = CliRunner()
SPEC = {
    "base": {
        "algo": "ppo",
        "traffic": "empty",
        "steps": 64,
        "hyperparams": {"n_steps": 32, "batch_size": 32},
    },
    "grid": {"seed": 1},
    "eval_episodes": 1,
}
RUN = "ppo-highway-s0"
AS_ROOT = os.geteuid() == 0  # root writes through chmod 0o444


def snapshot(root: Path) -> dict[str, str]:
    """Every path under ``root`` → "dir" or its bytes' SHA-256."""
    return {
        str(path.relative_to(root)): "dir" if path.is_dir() else hashlib.sha256(path.read_bytes()).hexdigest()
        for path in sorted(root.rglob("*"))
    }


@pytest.fixture
def sweep_file(tmp_path) -> Path:
    path = tmp_path / "sweep.yaml"
    path.write_text(yaml.safe_dump(SPEC))
    return path


def make_run(runs: Path, files: dict[str, str]) -> Path:
    """The sweep's one run directory with its config.yaml and ``files`` (path → text)."""
    (cell,) = expand_sweep(SPEC, runs).cells
    run_dir = runs / RUN
    run_dir.mkdir(parents=True)
    save_yaml(cell.config, run_dir / "config.yaml")
    for name, text in files.items():
        (run_dir / name).parent.mkdir(parents=True, exist_ok=True)
        (run_dir / name).write_text(text)
    return run_dir


def assert_sweep_refused(tmp_path: Path, sweep_file: Path, message: str) -> None:
    """``sweep`` and ``sweep --dry-run``: exit 2, exactly ``error: MESSAGE``, nothing changed."""
    runs = tmp_path / "runs"
    before = snapshot(tmp_path)
    for extra in ([], ["--dry-run"]):
        result = runner.invoke(
            app, ["sweep", str(sweep_file), "--workers", "1", "--runs-dir", str(runs), *extra]
        )
        assert result.exit_code == 2, result.output
        assert result.output.splitlines() == [f"error: {message}"]
        assert snapshot(tmp_path) == before


MANIFEST = "checkpoints/latest.json"
CORRUPT = "checkpoint manifest checkpoints/latest.json is corrupted"
BESIDE_MODEL = CORRUPT + " beside a finished model.zip"


@pytest.mark.parametrize(
    ("files", "damage"),
    [
        ({MANIFEST: "{corrupt", "checkpoints/latest.zip": "z"}, CORRUPT),
        (
            {MANIFEST: "{corrupt", "checkpoints/latest.zip": "z", "model.zip": "m", "eval.json": "{}"},
            BESIDE_MODEL,
        ),
        ({MANIFEST: '{"sha256": "x"}', "model.zip": "m"}, BESIDE_MODEL),
        ({MANIFEST: '["steps", 64]'}, CORRUPT),
        ({"checkpoints/latest.zip": "z", "model.zip": "m"}, "model.zip but no checkpoint manifest"),
        ({"model.zip": "m"}, "model.zip but no checkpoint manifest"),
        ({"checkpoints/latest.zip": "z"}, "checkpoints/latest.zip but no checkpoint manifest"),
    ],
)  # fmt: skip
def test_a_damaged_run_is_refused_not_retrained(tmp_path, sweep_file, files, damage):
    run_dir = make_run(tmp_path / "runs", files)
    assert_sweep_refused(
        tmp_path,
        sweep_file,
        f"run directory {str(run_dir)!r} is damaged ({damage}); the sweep will not replace it: "
        "move it away or remove it, then re-run",
    )


@pytest.mark.parametrize("stray", ["notes.txt", "data/points.csv", "checkpoints/mine.bin", "videos/trip.mp4"])
def test_a_folder_with_files_no_run_writes_is_not_restarted(tmp_path, sweep_file, stray):
    run_dir = make_run(tmp_path / "runs", {"monitor.csv": MONITOR, "progress.csv": "p", stray: "mine"})
    first = "data/" if stray.startswith("data/") else stray
    assert_sweep_refused(
        tmp_path,
        sweep_file,
        f"{str(run_dir)!r} has no checkpoint to resume from and holds files a drivelab run does not write "
        f"({first}); nothing was changed (train a new run elsewhere, or move them out)",
    )


def test_a_file_at_the_run_path_is_refused(tmp_path, sweep_file):
    (tmp_path / "runs").mkdir()
    (tmp_path / "runs" / RUN).write_text("my notes")
    path = str(tmp_path / "runs" / RUN)
    assert_sweep_refused(
        tmp_path, sweep_file, f"{path!r} is a file, not a run directory; move it away or rename the sweep"
    )


MONITOR = '#{"t_start": 1.0, "env_id": "highway"}\nr,l,t\n'  # as SB3's Monitor starts it
UNSTARTED = {
    "monitor.csv": MONITOR, "progress.csv": "p", "events.out.tfevents.1.host.1.0": "e",
    "evaluations.csv": "v", "videos/eval-32.mp4": "v", "checkpoints/latest.tmp.zip": "t",
    "checkpoints/resume-32.json": "{}", "checkpoints/resume-32.npz": "n",
}  # fmt: skip


def test_a_run_stopped_before_its_first_checkpoint_is_restarted_and_only_its_files_go(tmp_path, monkeypatch):
    from drivelab.training import run

    trained = []
    monkeypatch.setattr(run, "train", lambda config, root, **_: trained.append(sorted(root.iterdir())))
    runs = tmp_path / "runs"
    run_dir = make_run(runs, UNSTARTED)
    (cell,) = expand_sweep(SPEC, runs).cells
    assert [action for _, action in plan(expand_sweep(SPEC, runs))] == ["restart"]
    outcome = run_cell(cell.config.to_dict(), str(runs), "restart", 0)
    assert outcome["ok"], outcome
    assert trained == [[runs / ".sweep-logs"]] and not run_dir.exists()


def test_a_restart_keeps_a_file_that_appeared_after_the_plan(tmp_path):
    """The worker checks again: a file put there since the plan fails the cell and stays."""
    runs = tmp_path / "runs"
    run_dir = make_run(runs, UNSTARTED)
    (cell,) = expand_sweep(SPEC, runs).cells
    assert [action for _, action in plan(expand_sweep(SPEC, runs))] == ["restart"]
    (run_dir / "notes.txt").write_text("mine")
    before = snapshot(run_dir)
    outcome = run_cell(cell.config.to_dict(), str(runs), "restart", 0)
    assert not outcome["ok"] and "files a drivelab run does not write (notes.txt)" in outcome["error"]
    assert snapshot(run_dir) == before


def test_a_readable_manifest_still_resumes_and_skips(tmp_path):
    runs = tmp_path / "runs"
    run_dir = make_run(
        runs, {MANIFEST: json.dumps({"steps": 32, "sha256": "x"}), "checkpoints/latest.zip": "z"}
    )
    sweep = expand_sweep(SPEC, runs)
    assert [action for _, action in plan(sweep)] == ["resume"]
    (run_dir / MANIFEST).write_text(json.dumps({"steps": 64, "sha256": "x"}))
    (run_dir / "model.zip").write_text("m")
    assert [action for _, action in plan(sweep)] == ["finish"]  # killed before its learning curve
    (run_dir / "learning_curve.png").write_text("png")
    assert [action for _, action in plan(sweep)] == ["evaluate"]
    (run_dir / "eval.json").write_text("{}")
    assert [action for _, action in plan(sweep)] == ["skip"]


def test_a_checkpoint_cut_between_its_renames_resumes(tmp_path):
    """Killed after latest.zip was renamed, before latest.tmp.json was: resume finishes it."""
    runs = tmp_path / "runs"
    make_run(runs, {"checkpoints/latest.tmp.json": "{}", "checkpoints/latest.zip": "z"})
    assert [action for _, action in plan(expand_sweep(SPEC, runs))] == ["resume"]


def test_a_damaged_run_fails_the_plan(tmp_path):
    runs = tmp_path / "runs"
    make_run(runs, {MANIFEST: "{corrupt", "model.zip": "m"})
    with pytest.raises(UsageError, match="is damaged"):
        plan(expand_sweep(SPEC, runs))


def _children(pid: int) -> set[int]:
    """The live processes whose parent is ``pid`` (from /proc)."""
    found = set()
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if int(fields[1]) == pid and fields[0] != "Z":
            found.add(int(stat.parent.name))
    return found


@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="reads processes from /proc")
def test_a_killed_sweep_leaves_no_workers_behind(tmp_path):
    """SIGKILL of the sweep (no cleanup): its pool workers end too, instead of training on and
    idling for ever beside the workers of a re-run."""
    import os
    import signal
    import subprocess
    import sys
    import time

    (tmp_path / "sweep.yaml").write_text(
        "base: {algo: ppo, traffic: empty, steps: 200000, checkpoint_every: 100000, eval_every: 200000,\n"
        "       hyperparams: {n_steps: 64, batch_size: 64, n_epochs: 1}}\ngrid: {seed: [1, 2]}\n"
    )
    sweep = subprocess.Popen(
        [sys.executable, "-m", "drivelab.cli", "sweep", "sweep.yaml", "--workers", "2", "--runs-dir", "runs"],
        cwd=tmp_path, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
    )  # fmt: skip
    deadline = time.monotonic() + 120
    while len(workers := _children(sweep.pid)) < 2 and time.monotonic() < deadline:
        time.sleep(0.2)
    assert len(workers) >= 2, "the sweep started no pool"
    while not list((tmp_path / "runs").glob("*/config.yaml")) and time.monotonic() < deadline:
        time.sleep(0.2)  # the workers train
    sweep.send_signal(signal.SIGKILL)
    sweep.wait()
    deadline = time.monotonic() + 20
    while (
        alive := {pid for pid in workers if Path(f"/proc/{pid}").exists()}
    ) and time.monotonic() < deadline:
        time.sleep(0.2)
    for pid in alive:  # leave nothing running if the test fails
        os.kill(pid, signal.SIGKILL)
    assert not alive, "the sweep's workers outlived it"


HOLD = """
import sys
from pathlib import Path
from drivelab.training.sweep import claim_runs
with claim_runs(Path(sys.argv[1]), sys.argv[2:]):
    print("held", flush=True)
    sys.stdin.read()
"""


def hold_runs(runs: Path, *names: str):
    """Another process that holds ``names`` of ``runs`` as a running sweep does, until its stdin
    closes (a context manager)."""
    import contextlib
    import subprocess
    import sys

    @contextlib.contextmanager
    def holding():
        holder = subprocess.Popen(
            [sys.executable, "-c", HOLD, str(runs), *names],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            text=True,
        )
        try:
            assert holder.stdout.readline() == "held\n"
            yield
        finally:
            holder.stdin.close()
            holder.wait(timeout=30)

    return holding()


def _assert_refused_while_held(tmp_path, runs, sweep_file):
    """While another process holds the run, the sweep and its ``--dry-run`` are one line, exit 2,
    and nothing changes; the dry run lets the locks go at once (the holder's run is not held up)."""
    with hold_runs(runs, RUN):
        before = snapshot(tmp_path)
        for extra in ([], ["--dry-run"]):
            result = runner.invoke(
                app, ["sweep", str(sweep_file), "--workers", "1", "--runs-dir", str(runs), *extra]
            )
            assert result.exit_code == 2, (extra, result.output)
            assert result.output.splitlines() == [
                f"error: run {str(runs / RUN)!r} is being run by another drivelab command (the same sweep "
                "or ablation started twice?); wait for it to end, or stop it, then re-run"
            ], extra
            assert snapshot(tmp_path) == before


def test_a_sweep_whose_runs_another_command_is_running_is_refused(tmp_path, sweep_file):
    """The same sweep started twice at once (a double click) trained the same runs in both and
    mixed their logs (monitor.csv rows, evaluations.csv) without an error: the second is refused,
    one line, exit 2, nothing changed."""
    runs = tmp_path / "runs"
    runs.mkdir()
    _assert_refused_while_held(tmp_path, runs, sweep_file)


def test_commands_running_other_runs_of_one_folder_go_on_side_by_side(tmp_path):
    from drivelab.training.sweep import claim_runs

    with hold_runs(tmp_path, "ppo-highway-s0", "ppo-highway-s1"):
        with claim_runs(tmp_path, ["ppo-highway-s2", "dqn-highway-s0"]):
            pass
        with pytest.raises(UsageError, match="ppo-highway-s1' is being run by another drivelab command"):
            with claim_runs(tmp_path, ["ppo-highway-s2", "ppo-highway-s1"]):
                pass
    with claim_runs(tmp_path, ["ppo-highway-s0", "ppo-highway-s1"]):  # its locks went with it
        pass


def test_a_run_that_another_command_has_just_started_is_refused_as_such(tmp_path, sweep_file):
    """The same sweep started twice: the second one's plan, made before it claims the runs, found the
    first one's run as ``run.train`` has it while its envs start (config.yaml, no monitor.csv yet)
    and refused it as a folder that is not a run ("train a new run with --runs-dir and --name
    instead"). It says that another command is running it, and so does ``--dry-run``."""
    runs = tmp_path / "runs"
    make_run(runs, {})
    _assert_refused_while_held(tmp_path, runs, sweep_file)
    result = runner.invoke(app, ["sweep", str(sweep_file), "--workers", "1", "--runs-dir", str(runs)])
    assert result.exit_code == 2 and "no monitor.csv of a run that started training" in result.output
    result = runner.invoke(app, ["sweep", str(sweep_file), "--runs-dir", str(runs), "--dry-run"])
    assert result.exit_code == 2 and "no monitor.csv of a run that started training" in result.output
    (runs / ".sweep.lock").unlink()  # nor when no command ever claimed a run there
    for extra in ([], ["--dry-run"]):
        result = runner.invoke(
            app, ["sweep", str(sweep_file), "--workers", "1", "--runs-dir", str(runs), *extra]
        )
        assert result.exit_code == 2 and "no monitor.csv of a run that started training" in result.output
        assert not (runs / ".sweep.lock").exists()


def test_a_dry_run_lists_the_runs_again_once_their_command_has_ended(tmp_path, sweep_file):
    """The dry run's check takes no lock it keeps, and creates no lock file."""
    runs = tmp_path / "runs"
    runs.mkdir()
    result = runner.invoke(app, ["sweep", str(sweep_file), "--runs-dir", str(runs), "--dry-run"])
    assert result.exit_code == 0 and result.output.splitlines() == [f"train    {runs / RUN}"]
    assert not (runs / ".sweep.lock").exists()
    with hold_runs(runs, "ppo-highway-s1"):  # another run of the folder: not this sweep's
        result = runner.invoke(app, ["sweep", str(sweep_file), "--runs-dir", str(runs), "--dry-run"])
        assert result.exit_code == 0 and result.output.splitlines() == [f"train    {runs / RUN}"]
    with hold_runs(runs, RUN):
        result = runner.invoke(app, ["sweep", str(sweep_file), "--runs-dir", str(runs), "--dry-run"])
        assert result.exit_code == 2
    result = runner.invoke(app, ["sweep", str(sweep_file), "--runs-dir", str(runs), "--dry-run"])
    assert result.exit_code == 0 and result.output.splitlines() == [f"train    {runs / RUN}"]


@pytest.mark.parametrize(
    ("folder_mode", "umask", "lock_mode"),
    [
        (0o2775, 0o022, 0o664),  # a folder shared by its group (setgid): the group writes the lock too
        (0o775, 0o022, 0o664),
        (0o777, 0o022, 0o666),
        (0o755, 0o022, 0o644),  # a folder of one user: the umask decides
        (0o775, 0o002, 0o664),
        (0o700, 0o077, 0o600),
    ],
    ids=["setgid-group", "group", "everyone", "own", "own-umask-002", "private"],
)
def test_the_lock_file_is_as_writable_as_its_folder(tmp_path, folder_mode, umask, lock_mode):
    """A second user's sweep in a runs folder shared by a group was refused ("Permission denied")
    when the first user's umask (022) had left .sweep.lock writable by its maker alone."""
    import stat

    from drivelab.training.sweep import claim_runs

    runs = tmp_path / "runs"
    runs.mkdir()
    runs.chmod(folder_mode)
    before = os.umask(umask)
    try:
        with claim_runs(runs, [RUN]):
            pass
    finally:
        os.umask(before)
    assert stat.S_IMODE((runs / ".sweep.lock").stat().st_mode) == lock_mode
    assert (runs / ".sweep.lock").read_bytes() == b""


def test_a_lock_file_that_cannot_be_written_is_one_error_line(tmp_path, sweep_file, monkeypatch):
    """A lock file this user may not open for writing (another user's, or made read-only): the
    sweep and its dry run are one line that names the file and the fix, exit 2, nothing changed.
    chmod 0o444 where it binds; as root (which writes through it) the refusal is simulated."""
    runs = tmp_path / "runs"
    runs.mkdir()
    lock = runs / ".sweep.lock"
    lock.write_bytes(b"")
    lock.chmod(0o444)
    if AS_ROOT:
        real_open = os.open

        def refuse(path, flags, *args, **kwargs):
            if Path(path) == lock and flags & (os.O_WRONLY | os.O_RDWR):
                raise PermissionError(13, "Permission denied", str(path))
            return real_open(path, flags, *args, **kwargs)

        monkeypatch.setattr(os, "open", refuse)
    assert_sweep_refused(
        tmp_path,
        sweep_file,
        f"cannot open the runs folder's lock file {str(lock)!r} for writing (Permission denied), which "
        f"every sweep or ablation there needs; `chmod u+w {lock}`",
    )


def _user_name(uid: int) -> str:
    """How the error lines name user ``uid``."""
    import pwd

    try:
        return pwd.getpwuid(uid).pw_name
    except KeyError:
        return f"uid {uid}"


def test_the_error_for_another_users_lock_file_says_who_can_share_it(tmp_path):
    from drivelab.training.sweep import _lock_file_denied

    lock = tmp_path / ".sweep.lock"
    for owner in (os.geteuid() + 1, 2**31 - 7):
        message = _lock_file_denied(lock, owner, PermissionError(13, "Permission denied"))
        assert message.endswith(
            f"; its owner ({_user_name(owner)}) can let the folder's group write it: `chmod g+w {lock}`"
        )


@pytest.mark.skipif(not AS_ROOT, reason="giving a file another group needs root")
def test_the_error_for_a_lock_file_of_another_group_says_to_give_it_the_folders(tmp_path):
    """In a folder without setgid the lock file gets its maker's group: `chmod g+w` alone would let
    that group write it, not the folder's."""
    import grp

    from drivelab.training.sweep import _lock_file_denied

    lock = tmp_path / ".sweep.lock"
    lock.touch()
    folder_gid = tmp_path.stat().st_gid
    os.chown(lock, -1, folder_gid + 1)
    try:
        group = grp.getgrgid(folder_gid).gr_name
    except KeyError:
        group = str(folder_gid)
    owner = os.geteuid() + 1
    message = _lock_file_denied(lock, owner, PermissionError(13, "Permission denied"))
    assert message.endswith(
        f"; its owner ({_user_name(owner)}) can let the folder's group write it: "
        f"`chgrp {group} {lock} && chmod g+w {lock}`"
    )


@pytest.mark.parametrize(
    ("folder_mode", "logs_mode"),
    [(0o2775, 0o775), (0o777, 0o777), (0o755, 0o755)],
    ids=["group", "everyone", "own"],
)
def test_the_logs_folder_is_as_writable_as_its_runs_folder(tmp_path, folder_mode, logs_mode):
    """After the lock file, a second user's sweep in a group-shared runs folder failed on
    .sweep-logs, made by the first user with a umask of 022 (a traceback from the worker)."""
    import stat

    from drivelab.training.sweep import logs_folder

    runs = tmp_path / "runs"
    runs.mkdir()
    runs.chmod(folder_mode)
    before = os.umask(0o022)
    try:
        folder = logs_folder(runs)
    finally:
        os.umask(before)
    assert folder == runs / ".sweep-logs" and stat.S_IMODE(folder.stat().st_mode) & 0o777 == logs_mode
    assert logs_folder(runs) == folder  # made once, then left as it is


def test_a_logs_folder_that_cannot_be_written_is_one_error_line(tmp_path, sweep_file, monkeypatch):
    """Checked before any run starts (os.access answering no: root writes through chmod)."""
    runs = tmp_path / "runs"
    (runs / ".sweep-logs").mkdir(parents=True)
    (runs / ".sweep.lock").write_bytes(b"")
    real_access = os.access
    monkeypatch.setattr(
        os, "access", lambda path, mode, **kw: Path(path).name != ".sweep-logs" and real_access(path, mode)
    )
    before = snapshot(tmp_path)
    result = runner.invoke(app, ["sweep", str(sweep_file), "--workers", "1", "--runs-dir", str(runs)])
    assert result.exit_code == 2, result.output
    logs = runs / ".sweep-logs"
    assert result.output.splitlines() == [
        f"error: cannot write the sweep logs in {str(logs)!r} (permission denied), which every sweep or "
        f"ablation there needs; `chmod u+w {logs}`"
    ]
    assert snapshot(tmp_path) == before


def test_a_newline_in_a_folder_name_keeps_the_error_one_line_and_its_command_right(
    tmp_path, sweep_file, monkeypatch
):
    """shlex.quote keeps a newline: the chmod in the error line is bash's $'…' word instead, so
    the line stays one line, and run as it is printed, it changes that folder."""
    import stat
    import subprocess

    runs = tmp_path / "runs\nof B"
    logs = runs / ".sweep-logs"
    logs.mkdir(parents=True)
    (runs / ".sweep.lock").write_bytes(b"")
    logs.chmod(0o555)
    real_access = os.access
    monkeypatch.setattr(
        os, "access", lambda path, mode, **kw: Path(path).name != ".sweep-logs" and real_access(path, mode)
    )
    result = runner.invoke(app, ["sweep", str(sweep_file), "--workers", "1", "--runs-dir", str(runs)])
    assert result.exit_code == 2, result.output
    [line] = result.output.splitlines()
    assert line.startswith("error: cannot write the sweep logs in ") and "\\n" in line
    command = line.rsplit("`", 2)[1]
    assert command.startswith("chmod u+w $'") and command.endswith("of B/.sweep-logs'")
    subprocess.run(["bash", "-c", command], check=True)
    assert stat.S_IMODE(logs.stat().st_mode) & stat.S_IWUSR


def test_error_lines_write_a_line_break_in_a_message_as_an_escape():
    from drivelab.cli import error_line

    assert error_line("no run in 'a\nb'\r") == "error: no run in 'a\\nb'\\r"


def test_a_run_whose_log_cannot_be_written_fails_as_a_run_not_the_sweep(tmp_path):
    """run_cell never raises: a log it cannot open (another user's log of that run) is the run's
    failure, reported to the driver, not a traceback that ends the sweep."""
    (cell,) = expand_sweep(SPEC, tmp_path).cells
    (tmp_path / ".sweep-logs" / f"{RUN}.log").mkdir(parents=True)
    outcome = run_cell(cell.config.to_dict(), str(tmp_path), "train", 1)
    assert not outcome["ok"] and outcome["error"].startswith(
        f"cannot write its log {str(tmp_path / '.sweep-logs' / (RUN + '.log'))!r}: "
    )
    assert not (tmp_path / RUN).exists()


def test_a_sweep_begun_before_the_eval_every_check_goes_on(tmp_path):
    """A sweep with eval_every > steps whose runs were made before sweeps refused that: its finished
    run is skipped and its other cell trained, as before; changing eval_every in the file is no way
    out (it is part of a run's identity). A new sweep with that schedule is refused."""
    spec = {**SPEC, "base": {**SPEC["base"], "eval_every": 100}, "grid": {"seed": [0, 1]}}
    runs = tmp_path / "runs"
    with pytest.raises(UsageError, match=r"'eval_every' \(100\) is larger than 'steps' \(64\)"):
        expand_sweep(spec, runs)
    run_dir = runs / RUN
    run_dir.mkdir(parents=True)
    made = expand_sweep({**spec, "base": {**spec["base"], "eval_every": 64}}, runs).cells[0].config
    save_yaml(build_config({**made.to_dict(), "eval_every": 100}), run_dir / "config.yaml")
    for name, text in {MANIFEST: '{"steps": 64}', "model.zip": "m", "learning_curve.png": "p",
                       "eval.json": "{}"}.items():  # fmt: skip
        (run_dir / name).parent.mkdir(parents=True, exist_ok=True)
        (run_dir / name).write_text(text)
    actions = [action for _, action in plan(expand_sweep(spec, runs))]
    assert actions == ["skip", "train"]


def test_a_lock_file_or_logs_folder_being_shared_by_its_maker_is_waited_for(tmp_path, monkeypatch):
    """Two users' sweeps starting at once in a new group-shared runs folder: the second opened the
    lock file (and looked at the logs folder) between the first one's creating it, with its umask's
    mode, and its sharing it: refused, telling the owner to run a chmod that was already done.
    Simulated for any user: the lock file and logs folder refuse this user for 0.1 s."""
    import threading

    from drivelab.training import sweep as sweep_module

    runs = tmp_path / "runs"
    (runs / ".sweep-logs").mkdir(parents=True)
    lock = runs / ".sweep.lock"
    lock.write_bytes(b"")
    shared = threading.Event()
    threading.Timer(0.1, shared.set).start()
    real_open, real_access = os.open, os.access

    def not_yet_open(path, flags, *args, **kwargs):
        if Path(path) == lock and not shared.is_set() and not flags & os.O_CREAT:
            raise PermissionError(13, "Permission denied", str(path))
        return real_open(path, flags, *args, **kwargs)

    def not_yet_access(path, mode, **kwargs):
        return (shared.is_set() or Path(path).name != ".sweep-logs") and real_access(path, mode, **kwargs)

    monkeypatch.setattr(os, "open", not_yet_open)
    monkeypatch.setattr(os, "access", not_yet_access)
    with sweep_module.claim_runs(runs, ["a"]):
        assert shared.is_set()
        sweep_module._check_logs_folder(runs)
    shared.clear()
    threading.Timer(0.1, shared.set).start()
    sweep_module._check_logs_folder(runs)
    assert shared.is_set()
