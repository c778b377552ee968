"""Sweeps: a grid of runs (algorithms × scenarios × sensors × rewards × seeds …) with per-cell
overrides, executed in a local process pool or as Ray tasks. The sweep file (``name``, ``runs_dir``,
``eval_episodes``, ``base``, ``grid``, ``overrides``) is described in docs/compare.md.

Each cell's run directory is named from its grid values, so a re-run skips a finished run, resumes
an interrupted one and restarts one that never reached a checkpoint (``cell_action``); a directory
that is not that cell's run is refused before anything runs."""

from __future__ import annotations

import contextlib
import errno
import fcntl
import grp
import hashlib
import itertools
import json
import logging
import multiprocessing
import os
import pwd
import re
import shlex
import socket
import stat
import threading
import time
import traceback
import warnings
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from dataclasses import dataclass
from pathlib import Path

from tqdm import tqdm

from drivelab.config import FIELDS, RunConfig, build_config, check_eval_every, check_steps
from drivelab.errors import UsageError
from drivelab.hyperparams import with_shipped_hyperparams
from drivelab.yaml_io import load_yaml

SWEEP_KEYS = ("name", "runs_dir", "eval_episodes", "base", "grid", "overrides")
MERGED_FIELDS = ("hyperparams", "env_options")  # dict fields merged key by key, not replaced
EXECUTORS = ("pool", "ray")
LOG_FOLDER = ".sweep-logs"  # per-run stdout/stderr of the workers, beside the run directories
# how long a lock file or logs folder this user may not write is waited for: another user's command
# that has just made it shares it a moment later (``_share_like_folder``)
SHARE_WAIT_S = 0.5
LOCK_FILE = ".sweep.lock"  # the runs a command is running now (``claim_runs``), beside them
RAY_CONNECT_TIMEOUT_S = 10  # --address: how long the cluster's port may take to answer


@dataclass(frozen=True)
class Cell:
    """One run of a sweep.

    :param config: the run's validated config (its ``name`` is the run directory's name).
    :param grid_values: the grid value of each axis that made this cell.
    """

    config: RunConfig
    grid_values: dict


@dataclass(frozen=True)
class Sweep:
    """An expanded sweep: its cells and where and how to run them."""

    cells: tuple[Cell, ...]
    runs_dir: Path
    eval_episodes: int


# --- reading and expanding -------------------------------------------------------------------
def _slug(value) -> str:
    text = ",".join(map(str, value)) if isinstance(value, (list, tuple)) else str(value)
    return re.sub(r"[^A-Za-z0-9.+]+", "_", text).strip("_") or "x"


def _axis_values(axis: str, values) -> list:
    if axis == "seed" and isinstance(values, int) and not isinstance(values, bool):
        if values < 1:
            raise UsageError("sweep grid 'seed' as a count must be >= 1")
        return list(range(values))
    if not isinstance(values, list) or not values:
        raise UsageError(f"sweep grid axis {axis!r} must be a non-empty list")
    return values


def _merge(values: dict, update: dict, where: str) -> dict:
    merged = dict(values)
    for key, value in update.items():
        if key not in FIELDS or key == "name":
            raise UsageError(f"{where} has unknown run field {key!r}")
        if key in MERGED_FIELDS:
            if not isinstance(value, dict):
                raise UsageError(f"{where} field {key!r} must be a mapping")
            merged[key] = {**merged.get(key, {}), **value}
        else:
            merged[key] = value
    return merged


def _matches(match: dict, grid_values: dict) -> bool:
    return all(_slug(grid_values.get(axis)) == _slug(value) for axis, value in match.items())


def expand_sweep(spec: dict, runs_dir: str | Path | None = None) -> Sweep:
    """Validate a sweep mapping and expand its grid into cells (configs checked, nothing run).

    :param spec: the parsed sweep file (see the module docstring).
    :param runs_dir: where the run directories go; overrides the file's ``runs_dir``.
    """
    if not isinstance(spec, dict):
        raise UsageError("a sweep file must be a mapping with a 'grid'")
    if unknown := sorted(set(spec) - set(SWEEP_KEYS), key=str):
        raise UsageError(f"unknown sweep key {unknown[0]!r} (known: {', '.join(SWEEP_KEYS)})")
    base, grid, overrides = spec.get("base") or {}, spec.get("grid"), spec.get("overrides") or []
    if not isinstance(base, dict):
        raise UsageError("sweep 'base' must be a mapping of run fields")
    if not isinstance(grid, dict) or not grid:
        raise UsageError("sweep needs a non-empty 'grid' mapping of run fields to lists")
    if not isinstance(overrides, list) or not all(isinstance(o, dict) for o in overrides):
        raise UsageError("sweep 'overrides' must be a list of {match: ..., set: ...}")
    for axis in grid:
        if axis not in FIELDS or axis == "name":
            raise UsageError(f"sweep grid has unknown run field {axis!r}")
    axes = {axis: _axis_values(axis, values) for axis, values in grid.items()}
    for i, override in enumerate(overrides):
        if set(override) - {"match", "set"} or not isinstance(override.get("set"), dict):
            raise UsageError(f"sweep override {i + 1} must have 'set' (a mapping) and optional 'match'")
        if stray := sorted(set(override.get("match") or {}) - set(axes), key=str):
            raise UsageError(f"sweep override {i + 1} matches {stray[0]!r}, which is not a grid axis")
    eval_episodes = spec.get("eval_episodes", 10)
    if not isinstance(eval_episodes, int) or isinstance(eval_episodes, bool) or eval_episodes < 0:
        raise UsageError(f"sweep 'eval_episodes' must be an integer >= 0, got {eval_episodes!r}")
    prefix = str(spec["name"]) + "-" if spec.get("name") else ""
    cells, names, runs = [], {}, {}
    for combination in itertools.product(*axes.values()):
        grid_values = dict(zip(axes, combination, strict=True))
        values = _merge(base, grid_values, "sweep base/grid")
        for i, override in enumerate(overrides):
            if _matches(override.get("match") or {}, grid_values):
                values = _merge(values, override["set"], f"sweep override {i + 1}")
        if "algo" not in values:
            raise UsageError("sweep cells need an 'algo' (in base or grid)")
        # algo and scenario always, then the other grid axes in order, then the seed
        parts = [values["algo"], values.get("env", "highway")]
        parts += [v for axis, v in grid_values.items() if axis not in ("algo", "env", "seed")]
        name = prefix + "-".join(_slug(p) for p in parts) + f"-s{values.get('seed', 0)}"
        if name in names:
            raise UsageError(f"sweep cells {names[name]} and {grid_values} both map to run {name!r}")
        names[name] = grid_values
        config = build_config(with_shipped_hyperparams({**values, "name": name}))
        same = runs.setdefault((config.identity(), config.steps), grid_values)
        if same is not grid_values:
            raise UsageError(f"sweep cells {same} and {grid_values} are the same run (one config)")
        cells.append(Cell(config, grid_values))
    where = runs_dir if runs_dir is not None else spec.get("runs_dir", "runs")
    if not isinstance(where, (str, Path)) or not str(where):
        raise UsageError(f"sweep 'runs_dir' must be a folder path, got {where!r}")
    sweep = Sweep(tuple(cells), Path(where), eval_episodes)
    _check_cells(sweep)
    return sweep


def load_sweep(path: str | Path, runs_dir: str | Path | None = None) -> Sweep:
    """Read and expand a sweep YAML file (one-line UsageError for anything malformed)."""
    return expand_sweep(load_yaml(path), runs_dir)


def _check_cells(sweep: Sweep) -> None:
    """Fail before anything is written, as ``drivelab train`` does: ``check_config`` once per
    distinct config (but for name, seed and steps), and for the cells whose run does not exist yet
    ``check_eval_every`` and ``check_steps``."""
    from drivelab.training.run import check_config

    begun = [os.path.lexists(sweep.runs_dir / cell.config.name) for cell in sweep.cells]
    # a run that exists keeps its own schedule; one made before the check with eval_every > steps
    # shows that the whole sweep was (eval_every is part of a run's identity)
    before_the_check = any(
        exists and cell.config.eval_every > cell.config.steps
        for cell, exists in zip(sweep.cells, begun, strict=True)
    )
    checked: set[str] = set()
    for cell, exists in zip(sweep.cells, begun, strict=True):
        if not exists and not before_the_check:
            check_eval_every(cell.config)  # depends on the step budget, which the key below leaves out
        fields = {k: v for k, v in cell.config.to_dict().items() if k not in ("name", "seed", "steps")}
        key = json.dumps(fields, sort_keys=True, default=str)
        if key not in checked:
            check_config(cell.config)
            checked.add(key)
        if not exists:
            check_steps(cell.config)  # the step budget against a rollout: after the agent's own checks


# --- what each cell needs --------------------------------------------------------------------
def cell_action(run_dir: Path, config: RunConfig, eval_episodes: int) -> str:
    """What a re-run must do for this cell: "train", "restart" (stopped before its first
    checkpoint), "resume", "finish" (killed between model.zip and its learning curve), "evaluate" or
    "skip". A UsageError when ``run_dir`` is not that cell's run or is damaged: nothing in it is
    replaced or deleted."""
    from drivelab.training.evaluate import load_run_config

    if not run_dir.exists() and not run_dir.is_symlink():
        return "train"
    if not run_dir.is_dir():
        raise UsageError(f"{str(run_dir)!r} is a file, not a run directory; move it away or rename the sweep")
    existing = load_run_config(run_dir)
    if existing.identity() != config.identity():
        raise UsageError(
            f"run directory {str(run_dir)!r} holds a run with a different config; "
            "remove it or rename the sweep"
        )
    folder = run_dir / "checkpoints"
    manifest_path = folder / "latest.json"
    if not manifest_path.exists():
        if (folder / "latest.tmp.json").is_file() and (folder / "latest.zip").is_file():
            return "resume"  # killed between a checkpoint's renames: resuming finishes them
        saved = [path for path in (run_dir / "model.zip", folder / "latest.zip") if path.exists()]
        if saved:
            _damaged(run_dir, f"{saved[0].relative_to(run_dir).as_posix()} but no checkpoint manifest")
        from drivelab.training.run import unstarted_run_files

        unstarted_run_files(run_dir)  # refused if it holds anything else
        return "restart"  # stopped before its first checkpoint
    steps = _manifest_steps(run_dir, manifest_path)
    if steps < config.steps or not (run_dir / "model.zip").is_file():
        return "resume"
    if not (run_dir / "learning_curve.png").is_file():
        return "finish"  # killed between model.zip and its learning curve (run._save_model)
    if eval_episodes and not (run_dir / "eval.json").is_file():
        return "evaluate"
    return "skip"


def _damaged(run_dir: Path, what: str) -> None:
    raise UsageError(
        f"run directory {str(run_dir)!r} is damaged ({what}); the sweep will not replace it: "
        "move it away or remove it, then re-run"
    )


def _manifest_steps(run_dir: Path, manifest_path: Path) -> int:
    """The step count of a run's checkpoint manifest; a damaged run when it cannot be read."""
    finished = " beside a finished model.zip" if (run_dir / "model.zip").is_file() else ""
    try:
        manifest = json.loads(manifest_path.read_text())
    except OSError as exc:
        _damaged(run_dir, f"checkpoint manifest checkpoints/latest.json cannot be read: {exc.strerror}")
    except (json.JSONDecodeError, UnicodeDecodeError):
        manifest = None
    steps = manifest.get("steps") if isinstance(manifest, dict) else None
    if not isinstance(steps, int) or isinstance(steps, bool) or steps < 0:
        _damaged(run_dir, f"checkpoint manifest checkpoints/latest.json is corrupted{finished}")
    return steps


def plan(sweep: Sweep) -> list[tuple[Cell, str]]:
    """Each cell with what it needs (see ``cell_action``), checked before anything runs."""
    return [
        (cell, cell_action(sweep.runs_dir / cell.config.name, cell.config, sweep.eval_episodes))
        for cell in sweep.cells
    ]


def preview(sweep: Sweep) -> list[tuple[Cell, str]]:
    """What ``run_sweep`` would do with each cell (``--dry-run``), with nothing written."""
    steps = plan_unclaimed(sweep)
    if not all(action == "skip" for _, action in steps):
        check_unclaimed(sweep)
    return steps


def plan_unclaimed(sweep: Sweep) -> list[tuple[Cell, str]]:
    """``plan`` by a command that holds none of the sweep's runs: when a check fails and a run is
    held by another command, the UsageError says that (a run being started looks half-made)."""
    try:
        return plan(sweep)
    except UsageError:
        check_unclaimed(sweep)
        raise


def check_unclaimed(sweep: Sweep) -> None:
    """A UsageError when another command is running one of the sweep's runs now; nothing is written.
    Never call it while this process holds the claim (closing another handle of the lock file drops
    this process's ``fcntl.lockf`` locks)."""
    with claim_runs(sweep.runs_dir.resolve(), [cell.config.name for cell in sweep.cells], create=False):
        pass


def run_cell(
    config_values: dict,
    runs_dir: str,
    action: str,
    eval_episodes: int,
    on_evaluation=None,
    eval_first: int = 0,
) -> dict:
    """Do one cell's work in a worker (process-pool worker or Ray task); never raises. Its output
    goes to ``runs_dir/.sweep-logs/<name>.log``.

    :param on_evaluation: ``run.train``'s (it must pickle); returning False stops the run there (a
        pruned tuning trial).
    :param eval_first: the first evaluation episode played (tuning's validation episodes).
    :returns: ``{"name", "action", "ok", "seconds", "error", "stopped"}`` (and ``"interrupted":
        True`` after Ctrl-C or SIGTERM); ``stopped``: the step at which ``on_evaluation`` stopped
        the run, else None."""
    import torch

    torch.set_num_threads(1)  # one run per core: no oversubscription
    from drivelab.training import run
    from drivelab.training.evaluate import evaluate_run

    config = build_config(config_values)
    root = Path(runs_dir)
    run_dir = root / config.name
    start = time.perf_counter()
    outcome = {"name": config.name, "action": action, "ok": True, "error": None, "stopped": None}
    try:
        log_file = (logs_folder(root) / f"{config.name}.log").open("a")
    except OSError as exc:  # another user's log of this run, say: reported, as any failure of a run
        where = str(root / LOG_FOLDER / f"{config.name}.log")
        outcome.update(ok=False, error=f"cannot write its log {where!r}: {exc.strerror or exc}", seconds=0.0)
        return outcome
    with log_file as log, contextlib.redirect_stderr(log), contextlib.redirect_stdout(log):
        try:
            if action == "restart":
                run.remove_unstarted_run(run_dir)
            if action in ("train", "restart"):
                run.train(config, root, on_evaluation=on_evaluation, eval_first=eval_first)
            elif action == "resume":
                run.resume(run_dir, config.steps, on_evaluation=on_evaluation, eval_first=eval_first)
            elif action == "finish":
                from drivelab.training.plots import plot_learning_curve
                from drivelab.training.safe_files import locked_run

                with locked_run(run_dir):
                    plot_learning_curve(run_dir)
            evaluated = action == "finish" and (run_dir / "eval.json").is_file()
            if eval_episodes and action != "skip" and not evaluated:
                evaluate_run(run_dir, episodes=eval_episodes, first=eval_first)
        except run.StoppedByEvaluation as stop:
            outcome["stopped"] = stop.steps
        except (KeyboardInterrupt, run.TrainingInterrupted) as exc:  # the driver stops (execute)
            outcome.update(ok=False, error=f"{type(exc).__name__}: {exc}", interrupted=True)
        except BaseException as exc:  # noqa: BLE001 - reported to the driver, which goes on
            traceback.print_exc(file=log)
            outcome.update(ok=False, error=f"{type(exc).__name__}: {exc}")
    outcome["seconds"] = round(time.perf_counter() - start, 1)
    return outcome


# --- executing -------------------------------------------------------------------------------
def execute(
    function: Callable[..., dict],
    jobs: Iterable[dict],
    executor: str = "pool",
    workers: int = 1,
    in_flight: int | None = None,
) -> Iterator[dict]:
    """``function(**job)`` for each job, yielded as each finishes: in this process (one ``pool``
    worker), in a spawned process pool, or as Ray tasks (inside ``executor_ready``).

    :param function: a module-level function that pickles and does not raise, e.g. ``run_cell``.
    :param jobs: keyword arguments of each call, drawn lazily when a slot is free (``tune`` asks
        Optuna for a trial only then).
    :param in_flight: at most this many calls at once; None: every job at once."""
    if executor == "ray":
        import ray

        remote = ray.remote(num_cpus=1, max_retries=0)(function)
        return _until_interrupted(_as_done(lambda job: remote.remote(**job).future(), iter(jobs), in_flight))
    if workers == 1:  # one worker: run here, one after another (no process start-up)
        return _until_interrupted(function(**job) for job in jobs)
    return _until_interrupted(_pool(function, iter(jobs), workers, in_flight))


def _as_done(submit: Callable[[dict], Future], jobs: Iterator[dict], in_flight: int | None) -> Iterator[dict]:
    """The results of ``submit(job)``'s futures as they finish, at most ``in_flight`` pending."""
    pending = {submit(job) for job in itertools.islice(jobs, in_flight)}
    while pending:
        done, pending = wait(pending, return_when=FIRST_COMPLETED)
        for future in done:
            yield future.result()
            pending.update(submit(job) for job in itertools.islice(jobs, 1))


def _until_interrupted(outcomes: Iterator[dict]) -> Iterator[dict]:
    """``outcomes`` until one says its run was interrupted; then KeyboardInterrupt, so that the
    command stops and a re-run resumes that run instead of counting it as failed."""
    for outcome in outcomes:
        if outcome.get("interrupted"):
            raise KeyboardInterrupt
        yield outcome


def _exit_with_parent(parent: int) -> None:
    """A pool worker's start: the worker exits once its parent is gone (no orphan trains on)."""

    def watch() -> None:
        while os.getppid() == parent:
            time.sleep(0.5)
        os._exit(1)

    threading.Thread(target=watch, name="exit-with-parent", daemon=True).start()


def _pool(function: Callable, jobs: Iterator[dict], workers: int, in_flight: int | None) -> Iterator[dict]:
    context = multiprocessing.get_context("spawn")  # fresh interpreters: no forked torch/numba state
    with ProcessPoolExecutor(
        max_workers=workers, mp_context=context, initializer=_exit_with_parent, initargs=(os.getpid(),)
    ) as pool:
        try:
            yield from _as_done(lambda job: pool.submit(function, **job), jobs, in_flight)
        except KeyboardInterrupt:
            pool.shutdown(wait=True, cancel_futures=True)
            raise


def _ray_init(workers: int, address: str | None) -> bool:
    """Start a local Ray cluster of ``workers`` CPUs, or join the one at ``address``, unless Ray
    runs in this process already; True when this call started it. Failing that is one UsageError
    line, within ``RAY_CONNECT_TIMEOUT_S`` when nothing answers."""
    try:
        import ray
    except ImportError:
        raise UsageError("--executor ray needs Ray: pip install 'drivelab[ray]'") from None
    if ray.is_initialized():
        return False
    if address:
        _check_answers(address)
    # "local": always a fresh cluster of our own, never someone else's running one
    where = f"join the Ray cluster at {address!r}" if address else "start a local Ray cluster"
    keywords = {"address": address} if address else {"address": "local", "num_cpus": workers}
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # the Ray client's "connection timed out" warning
            ray.init(**keywords, include_dashboard=False, log_to_driver=False, logging_level=logging.ERROR)
    except (ConnectionError, ValueError, RuntimeError, ray.exceptions.RayError) as exc:
        # e.g. a head that requires a token (RAY_AUTH_MODE=token) and none given: Ray's
        # AuthenticationError, several lines long; the first says what is wrong
        ray.shutdown()  # whatever the failed call started
        reason = next((line.strip() for line in str(exc).splitlines() if line.strip()), type(exc).__name__)
        raise UsageError(f"cannot {where}: {reason}") from None
    return True


def _check_answers(address: str) -> None:
    """A UsageError when nothing answers at the host and port of ``address`` (``ray://host:port`` or
    ``host:port``; others are left to Ray)."""
    match = re.fullmatch(r"(?:ray://)?\[?([^\[\]/]+?)\]?:(\d+)", address)
    if match is None:
        return
    host, port = match.group(1), int(match.group(2))
    try:
        socket.create_connection((host, port), timeout=RAY_CONNECT_TIMEOUT_S).close()
    except (OSError, ValueError, OverflowError) as exc:
        reason = exc.strerror if isinstance(exc, OSError) and exc.strerror else str(exc) or type(exc).__name__
        raise UsageError(
            f"cannot join the Ray cluster at {address!r}: nothing answers at {host}:{port} ({reason})"
        ) from None


@contextlib.contextmanager
def executor_ready(executor: str, workers: int, address: str | None) -> Iterator[None]:
    """With ``executor`` "ray": Ray started (or its cluster joined) for the block, so that a cluster
    that cannot be joined stops a command before it writes anything; shut down after if started
    here."""
    started = executor == "ray" and _ray_init(workers, address)
    try:
        yield
    finally:
        if started:
            import ray

            ray.shutdown()


@contextlib.contextmanager
def claim_runs(runs_dir: Path, names: Iterable[str], create: bool = True) -> Iterator[None]:
    """Hold the run directories ``names`` of ``runs_dir`` for this process: a second command that
    would run one of them is refused with one UsageError line. Commands running other runs of the
    folder go on side by side.

    One byte-range lock (``fcntl.lockf``) per run in ``runs_dir/.sweep.lock``, at an offset drawn
    from its name; the locks go with the process. On a file system without locks runs are not
    claimed. With ``create`` False nothing is written: without a lock file no run is claimed. The
    lock file is shared as the folder is (``_share_like_folder``); one this user cannot write is a
    UsageError."""
    path = runs_dir / LOCK_FILE
    try:
        handle = _open_lock_file(path, create)
    except OSError as exc:
        owner = _owner(path)
        if isinstance(exc, PermissionError) and owner is not None:  # the file refused, not the folder
            raise UsageError(_lock_file_denied(path, owner, exc)) from None
        if create:
            raise UsageError(
                f"cannot write in the runs folder {str(runs_dir)!r}: {exc.strerror or exc}"
            ) from None
        handle = None  # no lock file (or none that can be locked): no command claims a run here
    if handle is None:
        yield
        return
    with handle:
        for name in names:
            offset = int.from_bytes(hashlib.sha256(name.encode()).digest()[:7], "big")
            try:
                fcntl.lockf(handle, fcntl.LOCK_EX | fcntl.LOCK_NB, 1, offset)
            except OSError as exc:
                if exc.errno not in (errno.EACCES, errno.EAGAIN):
                    break  # no locks on this file system
                raise UsageError(
                    f"run {str(runs_dir / name)!r} is being run by another drivelab command (the same "
                    "sweep or ablation started twice?); wait for it to end, or stop it, then re-run"
                ) from None
        yield


def _open_lock_file(path: Path, create: bool):
    """``path``, the lock file, opened for appending (a lock needs a handle open for writing); a new
    one (``create``) is made with mode 0o666 and shared as its folder is."""
    flags = os.O_WRONLY | os.O_APPEND
    if create:
        try:
            descriptor = os.open(path, flags | os.O_CREAT | os.O_EXCL, 0o666)
        except FileExistsError:
            pass  # made before, by this user or another: opened as it is
        else:
            _share_like_folder(descriptor, path.parent)
            return os.fdopen(descriptor, "a")
    deadline = time.monotonic() + SHARE_WAIT_S
    while True:
        try:
            return os.fdopen(os.open(path, flags), "a")
        except PermissionError:
            if time.monotonic() >= deadline:  # not one being shared by its maker now
                raise
            time.sleep(0.02)


def _share_like_folder(descriptor: int, folder: Path) -> None:
    """Let the group and others read and write the new file or folder ``descriptor`` where
    ``folder`` lets them write (the group only where it has the folder's group), whatever the umask,
    so that every user of a group-shared runs folder can use it. A refused change is ignored."""
    with contextlib.suppress(OSError):
        folder_stat, file_stat = os.stat(folder), os.fstat(descriptor)
        every = 0o007 if stat.S_ISDIR(file_stat.st_mode) else 0o006  # read, write (and enter a folder)
        shared = every if folder_stat.st_mode & stat.S_IWOTH else 0
        if folder_stat.st_mode & stat.S_IWGRP and file_stat.st_gid == folder_stat.st_gid:
            shared |= every << 3
        if shared & ~file_stat.st_mode:
            os.fchmod(descriptor, stat.S_IMODE(file_stat.st_mode) | shared)


def logs_folder(runs_dir: Path) -> Path:
    """``runs_dir/.sweep-logs``, made when missing and shared as ``runs_dir`` is."""
    folder = runs_dir / LOG_FOLDER
    runs_dir.mkdir(parents=True, exist_ok=True)
    try:
        folder.mkdir()
    except FileExistsError:
        return folder
    descriptor = os.open(folder, os.O_RDONLY)
    try:
        _share_like_folder(descriptor, runs_dir)
    finally:
        os.close(descriptor)
    return folder


def _check_logs_folder(runs_dir: Path) -> None:
    """``logs_folder``, and a UsageError when this user cannot write in it, before any run starts."""
    try:
        folder = logs_folder(runs_dir)
    except OSError as exc:
        raise UsageError(
            f"cannot write the sweep logs in {str(runs_dir / LOG_FOLDER)!r}: {exc.strerror or exc}"
        ) from None
    deadline = time.monotonic() + SHARE_WAIT_S  # one that another user has just made and shares
    while not os.access(folder, os.W_OK | os.X_OK) and time.monotonic() < deadline:
        time.sleep(0.02)
    if not os.access(folder, os.W_OK | os.X_OK):
        raise UsageError(
            f"cannot write the sweep logs in {str(folder)!r} (permission denied), which every sweep or "
            f"ablation there needs; {_chmod_fix(folder, folder.stat().st_uid)}"
        )


def _owner(path: Path) -> int | None:
    """The user id of the file ``path``; None when it is no file or cannot be looked at."""
    try:
        info = path.stat()
    except OSError:
        return None
    return info.st_uid if stat.S_ISREG(info.st_mode) else None


def shell_word(text: str) -> str:
    """``text`` as one shell word on one line (bash's ``$'…'`` for control characters)."""
    if text.isprintable():
        return shlex.quote(text)
    return "$'" + "".join(_ansi_c(character) for character in text) + "'"


_ANSI_C = {"\\": "\\\\", "'": "\\'", "\n": "\\n", "\t": "\\t", "\r": "\\r"}


def _ansi_c(character: str) -> str:
    """One character inside bash's ``$'…'``: itself when printable, else its escape (an undecodable
    byte, kept by Python as a surrogate, as that byte)."""
    code = ord(character)
    if character in _ANSI_C:
        return _ANSI_C[character]
    if character.isprintable():
        return character
    if code < 0x80:
        return f"\\x{code:02x}"
    if 0xDC80 <= code <= 0xDCFF:  # os.fsdecode's surrogateescape of an undecodable byte
        return f"\\x{code - 0xDC00:02x}"
    return f"\\u{code:04x}" if code < 0x10000 else f"\\U{code:08x}"


def _chmod_fix(path: Path, owner: int) -> str:
    """How the file or folder ``path`` of user ``owner`` becomes writable for this user."""
    quoted = shell_word(str(path))
    if owner == os.geteuid():
        return f"`chmod u+w {quoted}`"
    try:
        name = pwd.getpwuid(owner).pw_name
    except KeyError:
        name = f"uid {owner}"
    return f"its owner ({name}) can let the folder's group write it: `{_regroup(path)}chmod g+w {quoted}`"


def _regroup(path: Path) -> str:
    """``chgrp GROUP PATH && `` when ``path`` is not of its folder's group GROUP; empty when it is,
    or when either cannot be looked at."""
    try:
        gid, folder_gid = path.stat().st_gid, path.parent.stat().st_gid
    except OSError:
        return ""
    if gid == folder_gid:
        return ""
    try:
        group = grp.getgrgid(folder_gid).gr_name
    except KeyError:
        group = str(folder_gid)
    return f"chgrp {shell_word(group)} {shell_word(str(path))} && "


def _lock_file_denied(path: Path, owner: int, exc: OSError) -> str:
    """The one-line error for a lock file, of user ``owner``, that this user may not write."""
    return (
        f"cannot open the runs folder's lock file {str(path)!r} for writing ({exc.strerror}), which every "
        f"sweep or ablation there needs; {_chmod_fix(path, owner)}"
    )


def check_workers(executor: str, workers: int | None, address: str | None) -> int:
    """The number of parallel runs (default: one per core), checked with the executor choice."""
    if executor not in EXECUTORS:
        raise UsageError(f"unknown executor {executor!r} (choose from {', '.join(EXECUTORS)})")
    if address and executor != "ray":
        raise UsageError("--address is for --executor ray")
    if workers is None:
        workers = os.cpu_count() or 1
    if workers < 1:
        raise UsageError(f"--workers must be >= 1, got {workers}")
    return workers


def run_sweep(
    sweep: Sweep, executor: str = "pool", workers: int | None = None, address: str | None = None
) -> list[dict]:
    """Run every cell that is not finished; return one outcome per cell (skipped ones included).

    :param sweep: from ``load_sweep`` / ``expand_sweep``.
    :param executor: "pool" (local processes) or "ray" (Ray tasks).
    :param workers: parallel runs; default one per core (with Ray and no ``address``: the local
        cluster's CPUs). One worker runs the cells in this process.
    :param address: an existing Ray cluster (``ray://host:10001`` or ``auto``), with drivelab
        installed on its nodes and ``runs_dir`` on storage they share."""
    workers = check_workers(executor, workers, address)
    steps = plan_unclaimed(sweep)  # every cell checked before anything is written
    if all(action == "skip" for _, action in steps):  # nothing to run: no Ray started, no lock taken
        return [skipped(cell.config.name) for cell in sweep.cells]
    from drivelab.training.evaluate import make_out_dir

    with executor_ready(executor, workers, address):
        runs_dir = make_out_dir(sweep.runs_dir.resolve(), "runs folder")
        with claim_runs(runs_dir, [cell.config.name for cell in sweep.cells]):
            steps = plan(sweep)  # again, now that no other command can change them
            _check_logs_folder(runs_dir)
            outcomes = [skipped(cell.config.name) for cell, action in steps if action == "skip"]
            jobs = [
                {"config_values": c.config.to_dict(), "runs_dir": str(runs_dir), "action": action,
                 "eval_episodes": sweep.eval_episodes}
                for c, action in steps
                if action != "skip"
            ]  # fmt: skip
            results = execute(run_cell, jobs, executor, workers)
            with tqdm(total=len(jobs), desc=f"sweep ({executor}, {workers} workers)", unit="run") as bar:
                for outcome in results:
                    outcomes.append(outcome)
                    bar.set_postfix_str(f"{outcome['name']}: {'ok' if outcome['ok'] else 'FAILED'}")
                    bar.update(1)
    order = {c.config.name: i for i, c in enumerate(sweep.cells)}
    return sorted(outcomes, key=lambda o: order[o["name"]])


def skipped(name: str) -> dict:
    """The outcome (``run_cell``'s) of the run ``name`` that had nothing left to do."""
    return {"name": name, "action": "skip", "ok": True, "error": None, "seconds": 0.0, "stopped": None}


def run_dirs(sweep: Sweep) -> list[Path]:
    """The run directories of a sweep's cells, in grid order."""
    return [sweep.runs_dir / cell.config.name for cell in sweep.cells]
