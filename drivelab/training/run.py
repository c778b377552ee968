"""Training runs: a run directory, checkpoints that resume, periodic evaluation, plots.

Run directory layout::

    config.yaml            resolved RunConfig
    progress.csv, events.* SB3 logger (CSV + TensorBoard), continued by a resume
    monitor.csv            one row per training episode (return, length, time)
    evaluations.csv        one row per periodic evaluation
    checkpoints/latest.zip + latest.json (manifest: steps, sha256, config identity)
    checkpoints/replay.npz replay buffer of off-policy agents (arrays)
    checkpoints/resume-<steps>.json + .npz  what an exact resume needs beyond the model (resume_state.py)
    model.zip              final model: tensors (``torch.load(weights_only=True)``) and JSON
    learning_curve.png     training returns and evaluation returns against steps
    videos/                periodic-evaluation videos (when asked)
    .in-use.pid            the pid of the command using the run, while it runs

Nothing in a run directory is unpickled (``agents/storage.py``), and nothing is written through a
link in it (``safe_files.py``). The manifest's sha256 only detects a truncated or corrupted
checkpoint, not tampering."""

from __future__ import annotations

import contextlib
import csv
import gc
import os
import shutil
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path

from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.monitor import Monitor, ResultsWriter
from tqdm import tqdm

from drivelab.agents.registry import check_combination, get_algo
from drivelab.config import RunConfig, build_config, check_steps
from drivelab.errors import UsageError
from drivelab.training.allocator import keep_freed_memory
from drivelab.training.checkpoints import load_agent, load_replay, save_checkpoint, verify_checkpoint
from drivelab.training.divergence import (
    CHECK_EVERY_STEPS,
    TrainingDiverged,
    non_finite_weights,
    raised_by_divergence,
    remedy,
)
from drivelab.training.evaluate import aggregate, load_run_config, make_out_dir, run_episodes, write_video
from drivelab.training.progress_log import run_logger
from drivelab.training.resume_state import (
    ArrayVecMonitor,
    RecordEpisodes,
    RecordVecEpisodes,
    Snapshot,
    StopRequest,
    TrainingWorlds,
    apply_to_model,
    apply_truncation,
    check_restore,
    count_rows,
    plan_truncation,
    prune_states,
    read_state,
    restore,
    state_path,
    take_snapshot,
    warn_inexact,
    write_state,
)
from drivelab.training.safe_files import (
    AGAIN,
    DISK_FULL,
    IN_USE,
    WriteError,
    locked_run,
    make_folder,
    remove_empty_folders,
    remove_file,
    replacing,
    write_failure,
    write_file,
)
from drivelab.training.warm_start import initial_policy, load_initial_policy
from drivelab.yaml_io import dump_yaml


class TrainingInterrupted(KeyboardInterrupt):
    """SIGINT or SIGTERM during training; ``steps``: the checkpoint to resume from."""

    def __init__(self, run_dir: Path, steps: int) -> None:
        super().__init__(f"interrupted at step {steps}")
        self.run_dir, self.steps = run_dir, steps


class StoppedByEvaluation(Exception):
    """``on_evaluation`` returned False (a pruned tuning trial): the run stopped and was
    checkpointed at ``steps``, as after SIGINT."""

    def __init__(self, run_dir: Path, steps: int) -> None:
        super().__init__(f"stopped after an evaluation, checkpointed at step {steps}")
        self.run_dir, self.steps = run_dir, steps


# --- callbacks -------------------------------------------------------------------------------
class RunCallback(BaseCallback):
    """Progress bar, periodic evaluation (CSV + logger + optional video), checkpoints, stopping, and
    divergence checks (``divergence.py``) at safe points and before every evaluation and checkpoint.

    ``on_evaluation(step, summary)``, when given, is called after each evaluation; returning False
    stops the run as a stop request does. Each rollout start takes a ``Snapshot`` (the safe points
    of ``resume_state``) and writes the periodic checkpoints; on a stop request ``on_step`` returns
    False and ``_learn`` saves the run as it was at that snapshot."""

    def __init__(
        self,
        run_dir: Path,
        config: RunConfig,
        eval_env,
        worlds: TrainingWorlds,
        stop: StopRequest,
        on_evaluation: Callable[[int, dict], bool | None] | None = None,
        eval_first: int = 0,
    ) -> None:
        super().__init__()
        self.on_evaluation, self.halted, self.eval_first = on_evaluation, False, eval_first
        self.run_dir, self.config, self.eval_env = run_dir, config, eval_env
        self.worlds, self.stop = worlds, stop
        self.save_replay = get_algo(config.algo).sb3_replay
        self.bar: tqdm | None = None
        self.snapshot: Snapshot | None = None
        self.stopped = self.rollout_starts = False
        # rows already in the logs (after a resume cut them back to the checkpoint)
        self.monitor_rows = count_rows(run_dir / "monitor.csv", 2) - worlds.episodes()
        self.evaluation_rows = count_rows(run_dir / "evaluations.csv", 1)

    def _on_training_start(self) -> None:
        self.next_eval = _next_multiple(self.num_timesteps, self.config.resolved_eval_every)
        self.next_checkpoint = _next_multiple(self.num_timesteps, self.config.resolved_checkpoint_every)
        self.checkpoint_steps = self.num_timesteps  # a resumed run starts at its checkpoint
        self.next_divergence_check = _next_multiple(self.num_timesteps, CHECK_EVERY_STEPS)
        self.bar = tqdm(
            total=self.config.steps,
            initial=self.num_timesteps,
            desc=f"{self.config.algo} on {self.config.env}",
            unit="step",
            mininterval=2.0,
            dynamic_ncols=True,
        )

    def rows(self) -> dict[str, int]:
        """Data rows written so far to monitor.csv and evaluations.csv."""
        return {"monitor": self.monitor_rows + self.worlds.episodes(), "evaluations": self.evaluation_rows}

    def _on_rollout_start(self) -> None:
        self.rollout_starts = True
        self.safe_point()

    def safe_point(self) -> None:
        """Check for divergence when due, take the snapshot, write the checkpoint when due."""
        if self.num_timesteps >= self.next_divergence_check:
            self.check_weights(self.num_timesteps)
            self.next_divergence_check = _next_multiple(self.num_timesteps, CHECK_EVERY_STEPS)
        self.snapshot = take_snapshot(self.model, self.worlds, self.rows())
        if self.num_timesteps >= self.next_checkpoint:
            self.checkpoint(self.snapshot)
            self.next_checkpoint = _next_multiple(self.num_timesteps, self.config.resolved_checkpoint_every)

    def _on_step(self) -> bool:
        self.bar.update(self.model.num_timesteps - self.bar.n)
        if self.num_timesteps >= self.next_eval:
            self.check_weights(self.num_timesteps)  # no evaluation row from a diverged model
            summary = self.evaluate()
            self.next_eval += self.config.resolved_eval_every
            if self.on_evaluation is not None and self.on_evaluation(self.num_timesteps, summary) is False:
                self.halted = True
        if not self.rollout_starts:  # a loop without rollout starts (Q-learning, the expert) calls
            self.safe_point()  # on_step at the end of a whole step: that is its safe point
        self.stopped = self.stop.requested or self.halted
        return not self.stopped

    def _on_training_end(self) -> None:
        if self.bar is not None:
            self.bar.close()

    def checkpoint(self, snapshot: Snapshot) -> None:
        """The model's checkpoint and the resume state of ``snapshot``, the resume state first: the
        manifest, written last, commits both."""
        self.check_weights(snapshot.steps)  # keep the last finite checkpoint as the latest
        folder = make_folder(self.run_dir / "checkpoints")
        write_state(folder, snapshot)
        save_checkpoint(self.model, self.run_dir, self.config, self.save_replay)
        prune_states(folder, snapshot.steps)
        self.checkpoint_steps = snapshot.steps

    def check_weights(self, steps: int) -> None:
        """``TrainingDiverged`` (found at ``steps``) when a weight of the model is NaN or infinite."""
        found = non_finite_weights(self.model)
        if found:
            raise TrainingDiverged(
                self.config, steps, self.run_dir, self.checkpoint_steps, found, remedy(self.model)
            )

    def evaluate(self) -> dict:
        policy = lambda obs: self.model.predict(obs, deterministic=True)[0]  # noqa: E731
        results, frames = run_episodes(
            policy,
            self.eval_env,
            self.config.eval_episodes,
            record_first=self.config.eval_video,
            first=self.eval_first,
        )
        summary = aggregate(results)
        row = {"step": self.num_timesteps, **summary}
        path = self.run_dir / "evaluations.csv"
        new = not path.exists()
        with path.open("a", newline="") as handle:
            writer = csv.DictWriter(handle, fieldnames=list(row))
            if new:
                writer.writeheader()
            writer.writerow(row)
        self.evaluation_rows += 1
        for key in ("mean_return", "success_rate", "crash_rate"):
            self.logger.record(f"eval/{key}", summary[key])
        if frames:
            from drivelab.envs.video import video_fps

            write_video(
                frames,
                self.run_dir / "videos" / f"eval-{self.num_timesteps}",
                video_fps(self.eval_env),  # run_episodes' frames: one per simulation frame
            )
        return summary


def _next_multiple(value: int, every: int) -> int:
    return (value // every + 1) * every


# --- the run ---------------------------------------------------------------------------------
def new_run_dir(config: RunConfig, runs_root: Path) -> Path:
    """The path of a new run directory inside ``runs_root`` (not created yet). A UsageError when it
    exists, or when no folder can be created in ``runs_root``."""
    name = config.name or f"{config.algo}-{config.env}-s{config.seed}-{time.strftime('%Y%m%d-%H%M%S')}"
    run_dir = runs_root / name
    try:
        exists = run_dir.exists()
        existing = next(p for p in (runs_root, *runs_root.absolute().parents) if p.exists())
    except OSError as exc:  # a name too long (ENAMETOOLONG) for this file system
        raise UsageError(f"cannot create run directory {str(run_dir)!r}: {exc.strerror or exc}") from None
    if exists:
        raise _exists(run_dir)
    if not existing.is_dir():
        raise UsageError(f"--runs-dir {str(runs_root)!r}: {str(existing)!r} is not a directory")
    if not os.access(existing, os.W_OK | os.X_OK):
        raise UsageError(f"--runs-dir {str(runs_root)!r}: no permission to write in {str(existing)!r}")
    return run_dir


def _check_model(spec, config: RunConfig, probe) -> None:
    """Build the agent once on the probe environment and throw it away, so that hyper-parameters the
    algorithm rejects, or an ``init_from`` policy that does not fit, fail before any folder exists.
    The real build re-seeds everything."""
    weights = None if config.init_from is None else initial_policy(config)
    try:
        agent = spec.build(config.algo, probe, config.seed, dict(config.hyperparams), None)
        if weights is not None:
            load_initial_policy(agent, weights, config.init_from)
    except UsageError:
        raise
    except (TypeError, ValueError, AssertionError, RuntimeError) as exc:  # torch: RuntimeError
        raise UsageError(f"bad hyperparameters for {config.algo!r}: {exc}") from None
    except MemoryError:  # a replay buffer too large to allocate
        raise UsageError(_out_of_memory(config)) from None
    finally:
        gc.collect()  # the throwaway agent's networks (on a GPU too) go before the real ones come


def _make_envs(config: RunConfig, run_dir: Path | None, resume: bool):
    """(training env, evaluation env, the training env's ``TrainingWorlds``). The training env logs
    its episodes to monitor.csv (appending on a resume; ``run_dir`` None: to no file), records them
    for the resume state and is seeded with the run's seed."""
    from drivelab.envs.core import DriveEnv

    monitor = None if run_dir is None else str(run_dir / "monitor.csv")
    if config.n_envs == 1:
        recorder = RecordEpisodes(_training_worlds(config))
        train_env = Monitor(recorder)
        train_env.reset(seed=config.seed)
    else:
        recorder = RecordVecEpisodes(_training_worlds(config))
        train_env = ArrayVecMonitor(recorder)
        train_env.seed(config.seed)
    if monitor is not None:  # the scenario's name in the header (SB3's would read the env's spec: None)
        train_env.results_writer = ResultsWriter(
            monitor, header={"t_start": train_env.t_start, "env_id": config.env}, override_existing=not resume
        )
    return train_env, DriveEnv(**config.eval_env_kwargs()), TrainingWorlds.of(train_env, recorder)


def _training_worlds(config: RunConfig):
    """The run's ``n_envs`` training worlds, unmonitored: a DriveEnv, or an SB3 VecEnv of several."""
    from drivelab.envs.core import DriveEnv

    if config.n_envs == 1:
        return DriveEnv(**config.env_kwargs())
    from drivelab.agents.sb3_env import SB3VecEnv
    from drivelab.envs.vector import VectorDriveEnv

    return SB3VecEnv(VectorDriveEnv(config.n_envs, autoreset_mode="same_step", **config.env_kwargs()))


def _check_snapshot(model, config: RunConfig, snapshot: Snapshot, path: Path) -> None:
    """``check_restore`` into ``model`` and a training env that writes no file."""
    check_env, check_eval_env, check_worlds = _make_envs(config, None, resume=True)
    try:
        model.set_env(check_env)
        check_restore(model, check_worlds, snapshot, path)
    finally:
        check_env.close()
        check_eval_env.close()


def check_config(config: RunConfig):
    """Everything a run's config must pass before anything is written: the algorithm with its action
    kind and number of worlds, the environment, and the agent built once on a probe environment.
    Returns the algorithm's spec. Not ``check_eval_every``, which the commands check for new runs
    only."""
    from drivelab.envs.core import DriveEnv

    check_combination(config.algo, config.action)
    if config.n_envs > 1 and not get_algo(config.algo).multi_env:
        raise UsageError(
            f"algorithm {config.algo!r} trains in one world: n_envs must be 1 (got {config.n_envs})"
        )
    probe = DriveEnv(**config.env_kwargs())  # validates scenario, sensors, reward, action
    try:
        spec = check_combination(config.algo, config.action, probe.observation_space)
        _check_model(spec, config, probe)
    finally:
        probe.close()
    return spec


def train(
    config: RunConfig,
    runs_root: str | Path = "runs",
    on_evaluation: Callable[[int, dict], bool | None] | None = None,
    eval_first: int = 0,
) -> Path:
    """Train a new run; every input is validated (the agent built once) before anything is written.

    :param on_evaluation: called after each periodic evaluation with (step, its summary); False
        stops the run there, checkpointed, with ``StoppedByEvaluation``.
    :param eval_first: the first evaluation episode the periodic evaluations play (tuning's
        validation episodes).

    A run that fails before its first checkpoint cannot be resumed: its directory, and the folders
    above it that this call created, are removed."""
    run_dir = new_run_dir(config, Path(runs_root))
    spec = check_config(config)
    check_steps(config)
    created = _make_run_dir(run_dir)
    with locked_run(run_dir):
        try:
            write_file(run_dir / "config.yaml", dump_yaml(config.to_dict()))
            train_env, eval_env, worlds = _make_envs(config, run_dir, resume=False)
            model = spec.build(config.algo, train_env, config.seed, dict(config.hyperparams), run_dir)
            if config.init_from is not None:
                load_initial_policy(model, initial_policy(config), config.init_from)
        except BaseException as exc:  # Ctrl-C too: a folder of a config alone could not be resumed
            _remove_created(created)  # bad hyperparameters, too little memory: leave nothing behind
            if isinstance(exc, MemoryError):
                raise UsageError(_out_of_memory(config)) from None
            if isinstance(exc, OSError):  # a full disk
                raise _write_failed(exc, run_dir, AGAIN) from None
            if isinstance(exc, (TypeError, ValueError)) and not isinstance(exc, UsageError):
                raise UsageError(f"bad hyperparameters for {config.algo!r}: {exc}") from None
            raise
        try:
            _learn(model, run_dir, config, eval_env, worlds, on_evaluation, eval_first)
        except Exception as exc:
            # a run that failed before its first checkpoint cannot be resumed: it leaves nothing behind
            if not (run_dir / "checkpoints" / "latest.json").is_file():
                _remove_created(created)
            if isinstance(exc, MemoryError):
                raise UsageError(_out_of_memory(config)) from None
            raise
    return run_dir


def _make_run_dir(run_dir: Path) -> list[Path]:
    """Make ``run_dir`` exclusively and the folders above it; the folders made, innermost first."""
    created = [folder for folder in (run_dir, *run_dir.parents) if not folder.exists()]
    make_out_dir(run_dir.parent, "runs folder")  # one error line, no folder left, if it cannot be
    try:
        run_dir.mkdir()
    except FileExistsError:
        raise _exists(run_dir) from None
    except OSError as exc:
        remove_empty_folders(created[1:])
        raise UsageError(f"cannot create run directory {str(run_dir)!r}: {exc.strerror or exc}") from None
    return created


def _exists(run_dir: Path) -> UsageError:
    return UsageError(
        f"run directory {str(run_dir)!r} already exists (choose another --name, or --resume it)"
    )


def _write_failed(exc: OSError | WriteError, run_dir: Path, then: str) -> WriteError:
    """``write_failure`` of a write in ``run_dir`` (the file the error names, if any)."""
    if isinstance(exc, OSError) and isinstance(exc.filename, str):
        return write_failure(exc, Path(exc.filename), then)
    return write_failure(exc, run_dir, then, what=f"in {str(run_dir)!r}")


def _resume_hint(run_dir: Path) -> str:
    """What to do after a failure that left ``run_dir`` with a checkpoint, or without one."""
    if (run_dir / "checkpoints" / "latest.json").is_file():
        return f"continue with `drivelab train --resume {run_dir}`"
    return AGAIN


def _remove_created(created: list[Path]) -> None:
    """Remove the run directory ``created[0]``, then the folders above it that are left empty."""
    shutil.rmtree(created[0], ignore_errors=True)
    remove_empty_folders(created[1:])


def _out_of_memory(config: RunConfig) -> str:
    return (
        f"not enough memory for this run of {config.algo!r} (n_envs={config.n_envs}): use fewer worlds "
        "(--n-envs) or smaller buffers (-H buffer_size, n_steps)"
    )


def resume(
    run_dir: str | Path,
    steps: int | None = None,
    on_evaluation: Callable[[int, dict], bool | None] | None = None,
    eval_first: int = 0,
) -> Path:
    """Continue a run from its latest checkpoint up to ``steps`` (default: its configured total),
    exactly as the uninterrupted run with the checkpoint's resume state (``resume_state``).

    Everything is read and checked (a damaged resume state too, by restoring it) before anything is
    written; then the logs are cut back to the checkpoint and the older model's results removed. A
    run killed before its first checkpoint is trained again from step 0 in the same directory
    (``unstarted_run_files``); one stopped between its final checkpoint and its model gets the
    checkpoint's model. ``on_evaluation``, ``eval_first``: as for ``train``."""
    run_dir = Path(run_dir)
    with locked_run(run_dir):  # one command at a time; no link in it (``safe_files``)
        config = load_run_config(run_dir)
        if steps is not None:
            config = build_config({**config.to_dict(), "steps": steps})
        if not _stopped_before_first_checkpoint(run_dir):
            _continue(run_dir, config, on_evaluation, eval_first)
            return run_dir
        config = build_config({**config.to_dict(), "name": run_dir.name})
        written = unstarted_run_files(run_dir)  # a folder holding anything else is refused
        check_config(config)
        sys.stderr.write(f"{run_dir}: stopped before its first checkpoint; training again from step 0\n")
        _remove_run_files(run_dir, written)
    return train(config, run_dir.parent, on_evaluation, eval_first)


def _continue(run_dir: Path, config: RunConfig, on_evaluation, eval_first: int) -> None:
    """``resume`` of a run with a checkpoint, while it holds ``run_dir``."""
    manifest = verify_checkpoint(run_dir, config)
    if manifest["steps"] == config.steps and not (run_dir / "model.zip").is_file():
        # stopped between its final checkpoint and the model: the model is the checkpoint's
        _save_model(_load_checkpoint(config, run_dir, manifest, replay=False), run_dir)
        return
    if manifest["steps"] >= config.steps:
        raise UsageError(
            f"run already has {manifest['steps']} steps (>= {config.steps}); pass a larger --steps"
        )
    folder = run_dir / "checkpoints"
    snapshot = read_state(folder, manifest["steps"])
    changes = plan_truncation(run_dir, manifest["steps"], snapshot)
    model = _load_checkpoint(config, run_dir, manifest)
    if snapshot is not None:
        _check_snapshot(model, config, snapshot, state_path(folder, manifest["steps"]))
    # everything checked: from here on the run directory changes
    try:
        write_file(run_dir / "config.yaml", dump_yaml(config.to_dict()))
        apply_truncation(changes)
        train_env, eval_env, worlds = _make_envs(config, run_dir, resume=True)
    except (OSError, WriteError) as exc:  # a full disk: the checkpoint stands, resuming again works
        raise _write_failed(exc, run_dir, _resume_hint(run_dir)) from None
    model.set_env(train_env)
    if snapshot is None:
        warn_inexact()
    else:
        restore(model, worlds, snapshot)
    _learn(model, run_dir, config, eval_env, worlds, on_evaluation, eval_first)


def _stopped_before_first_checkpoint(run_dir: Path) -> bool:
    folder = run_dir / "checkpoints"
    return not any(
        path.exists() for path in (folder / "latest.json", folder / "latest.zip", run_dir / "model.zip")
    )


# what a run writes before its first checkpoint: the files a resume that finds no checkpoint may remove
UNSTARTED_FILES = (
    "config.yaml", "config.yaml.tmp", "monitor.csv", "progress.csv", "progress-*.csv", "evaluations.csv",
    "events.out.tfevents.*", "learning_curve.png", "learning_curve.tmp.png", IN_USE, IN_USE + ".tmp",
)  # fmt: skip
UNSTARTED_FOLDERS = {
    "checkpoints": ("resume-*.json", "resume-*.npz", "resume.tmp.json", "resume.tmp.npz",
                    "latest.tmp.zip", "latest.tmp.json", "replay.tmp.npz"),
    "videos": ("eval-*.mp4", "eval-*.gif"),  # the temporaries too: eval-<step>.tmp.mp4
}  # fmt: skip


def unstarted_run_files(run_dir: Path) -> list[Path]:
    """The files in ``run_dir``, a run stopped before its first checkpoint, that its run wrote
    (``UNSTARTED_FILES``, ``UNSTARTED_FOLDERS``). A UsageError, naming them, when it holds anything
    else or has no monitor.csv of SB3's: then nothing in it may be removed."""
    if run_dir.is_symlink():
        raise UsageError(f"run directory {str(run_dir)!r} is a link; nothing is removed through it")
    written: list[Path] = []
    foreign: list[str] = []
    for path in sorted(run_dir.iterdir()):
        if path.is_dir() and not path.is_symlink() and path.name in UNSTARTED_FOLDERS:
            for inner in sorted(path.iterdir()):
                if _plain_file(inner) and any(inner.match(p) for p in UNSTARTED_FOLDERS[path.name]):
                    written.append(inner)
                else:
                    foreign.append(f"{path.name}/{inner.name}")
        elif _plain_file(path) and any(path.match(pattern) for pattern in UNSTARTED_FILES):
            written.append(path)
        else:
            foreign.append(path.name + ("/" if path.is_dir() else ""))
    if foreign:
        shown = ", ".join(foreign[:5]) + (f" and {len(foreign) - 5} more" if len(foreign) > 5 else "")
        raise UsageError(
            f"{str(run_dir)!r} has no checkpoint to resume from and holds files a drivelab run does not "
            f"write ({shown}); nothing was changed (train a new run elsewhere, or move them out)"
        )
    if not _is_monitor_log(run_dir / "monitor.csv"):
        raise UsageError(
            f"{str(run_dir)!r} has no checkpoint to resume from and no monitor.csv of a run that started "
            "training; nothing was changed (train a new run with --runs-dir and --name instead)"
        )
    return written


def _plain_file(path: Path) -> bool:
    return path.is_file() and not path.is_symlink()


def _is_monitor_log(path: Path) -> bool:
    """Whether ``path`` starts as SB3's Monitor writes it: ``#{"t_start": ...}``."""
    try:
        with path.open("rb") as handle:
            return handle.read(11) == b'#{"t_start"'
    except OSError:
        return False


def remove_unstarted_run(run_dir: Path) -> None:
    """Remove ``run_dir``, a run stopped before its first checkpoint, if it holds only its own files."""
    with locked_run(run_dir):
        _remove_run_files(run_dir, unstarted_run_files(run_dir))


def _remove_run_files(run_dir: Path, files: list[Path]) -> None:
    """Remove ``files`` (``unstarted_run_files``), then the folders they leave empty and ``run_dir``."""
    for path in files:
        remove_file(path)
    for name in UNSTARTED_FOLDERS:
        if (run_dir / name).is_dir():
            (run_dir / name).rmdir()
    run_dir.rmdir()


def _load_checkpoint(config: RunConfig, run_dir: Path, manifest: dict, replay: bool = True):
    """The checkpoint's model with its replay buffer (unless not ``replay``), rebuilt on an
    unmonitored copy of the training env, so that nothing is written."""
    path = run_dir / "checkpoints" / "latest.zip"
    model = load_agent(run_dir, config, _training_worlds(config), path)
    if replay and manifest.get("replay_buffer"):
        load_replay(model, run_dir, manifest)
    if model.num_timesteps != manifest["steps"]:  # the logs are cut back to the manifest's step
        raise UsageError(
            f"checkpoint {str(path)!r} holds a model of {model.num_timesteps} steps, but its manifest "
            f"says {manifest['steps']}: one of them was edited; nothing was changed"
        )
    return model


def _learn(model, run_dir: Path, config: RunConfig, eval_env, worlds: TrainingWorlds,
           on_evaluation: Callable[[int, dict], bool | None] | None = None,
           eval_first: int = 0) -> None:  # fmt: skip
    """Train to ``config.steps``, then save the final checkpoint, model and learning curve.

    SIGINT/SIGTERM stop at the next step: the run is put back to the last safe point's snapshot and
    checkpointed there (``TrainingInterrupted``). A second signal stops at once, without a
    checkpoint."""
    keep_freed_memory()  # a third of a CNN's update went to mapping and unmapping its blocks
    model.set_logger(run_logger(run_dir, model.num_timesteps or None))  # a resume continues the logs
    if hasattr(model, "log_over"):  # rows by the step, about ten in a short run (SB3's on-policy, DDQN)
        model.log_over(config.steps)
    with _full_disk_reported_once():
        try:
            _learn_logged(model, run_dir, config, eval_env, worlds, on_evaluation, eval_first)
        except (OSError, WriteError) as exc:  # a full disk, most often: one line, the logs closed
            _close_logs(model)
            raise _write_failed(exc, run_dir, _resume_hint(run_dir)) from None


@contextlib.contextmanager
def _full_disk_reported_once():
    """Silence the traceback TensorBoard's writer thread prints on a full disk (the training loop
    reports the same error as one line); other thread errors go to the previous hook."""
    previous = threading.excepthook

    def report(args) -> None:
        if not (isinstance(args.exc_value, OSError) and args.exc_value.errno in DISK_FULL):
            previous(args)

    threading.excepthook = report
    try:
        yield
    finally:
        threading.excepthook = previous


def _learn_logged(model, run_dir: Path, config: RunConfig, eval_env, worlds: TrainingWorlds,
                  on_evaluation: Callable[[int, dict], bool | None] | None,
                  eval_first: int) -> None:  # fmt: skip
    """``_learn`` once the logger is set."""
    with StopRequest() as stop:
        callback = RunCallback(run_dir, config, eval_env, worlds, stop, on_evaluation, eval_first)
        try:
            model.learn(
                total_timesteps=config.steps - model.num_timesteps,
                callback=callback,
                reset_num_timesteps=False,
            )
        except KeyboardInterrupt:
            callback._on_training_end()
            raise TrainingInterrupted(run_dir, callback.checkpoint_steps) from None
        except (TrainingDiverged, OSError, WriteError):
            callback._on_training_end()
            raise
        except (ValueError, RuntimeError, FloatingPointError) as exc:
            callback._on_training_end()
            if isinstance(exc, UsageError) or not raised_by_divergence(model, exc):
                raise
            raise TrainingDiverged(
                config, model.num_timesteps, run_dir, callback.checkpoint_steps,
                non_finite_weights(model), remedy(model),
            ) from None  # fmt: skip
        if callback.stopped:
            apply_to_model(model, callback.snapshot)
            callback.checkpoint(callback.snapshot)
            if callback.halted and not stop.requested:
                raise StoppedByEvaluation(run_dir, callback.snapshot.steps)
            raise TrainingInterrupted(run_dir, callback.snapshot.steps)
        callback.checkpoint(take_snapshot(model, worlds, callback.rows()))
    _save_model(model, run_dir)


def _close_logs(model) -> None:
    """Close the run's logs after a failed write, so that they are not written again at exit."""
    with contextlib.suppress(Exception):
        model.logger.close()
    with contextlib.suppress(Exception):
        model.get_env().close()


def _save_model(model, run_dir: Path) -> None:
    """The final ``model.zip`` (written whole) and the learning curve; when the curve fails, the
    model is removed too, so that a resume writes both from the final checkpoint."""
    from drivelab.training.plots import plot_learning_curve

    with replacing(run_dir / "model.zip", run_dir / "model.tmp.zip") as temporary:
        model.save(temporary)
    try:
        plot_learning_curve(run_dir)
    except BaseException:
        remove_file(run_dir / "model.zip")
        raise
