"""Exact resume: the state a checkpoint needs beyond the model so that an interrupted and resumed
run continues exactly as the uninterrupted one would have, and the safe points where it is taken.

Besides the model's own files (weights, optimizer, replay) the rest of a run depends on:

- the random generators: python ``random``, numpy's global generator, torch's, the model's action
space and our own agents' ``rng`` and ``generator``; - the learning loop's counters (steps, updates,
episodes, ε, …) and its current observation; - the training environment, mid-episode. An episode is
a deterministic function of the generator state its reset draws from and of the actions since:
``RecordEpisodes`` / ``RecordVecEpisodes`` log both per world, and ``restore`` resets from that
state, replays the actions and checks that the replay ends in the saved observation; - the monitors'
partial episodes and the rows monitor.csv and evaluations.csv held, so that a resume cuts rows
written after the checkpoint.

Safe points: every learning loop calls ``callback.on_rollout_start()`` between its training phases
and ``callback.on_step()`` after the environment step, before the step changes anything learned. A
``Snapshot`` taken at a rollout start stays valid until the next one: on SIGINT/SIGTERM
(``StopRequest``) ``on_step`` returns False and the run is rolled back to the snapshot
(``apply_to_model``) before it is saved.

Files: ``checkpoints/resume-<steps>.json`` and ``resume-<steps>.npz`` (arrays, loaded with
``allow_pickle=False``), written before the checkpoint manifest that names their step."""

from __future__ import annotations

import csv
import hashlib
import json
import random
import re
import signal
import sys
import time
from collections import deque
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import torch
from gymnasium.utils import seeding
from stable_baselines3.common.vec_env import VecEnvWrapper, VecMonitor

from drivelab.agents.counters import check_counters
from drivelab.errors import UsageError, is_number
from drivelab.training.safe_files import remove_file, replacing, write_file

FORMAT = 1
# what the learning loops keep between steps: SB3's (BaseAlgorithm, OffPolicyAlgorithm, DQN) and ours
COUNTERS = (
    "num_timesteps", "_n_updates", "_episode_num", "_n_calls", "exploration_rate",
    "_current_progress_remaining",
    "epsilon", "_obs", "_episode_return", "_episode_length",  # Q-learning's
)  # fmt: skip
EPISODE_BUFFERS = ("ep_info_buffer", "ep_success_buffer", "episode_returns")  # logged means only
STATE_NAME = re.compile(r"resume-\d+\.(json|npz)")  # ``write_state``'s files
STALE_RESULTS = ("eval.json", "nocrash.json", "learning_curve.png", "model.zip")


# --- stopping at a safe point ------------------------------------------------------------------
class StopRequest:
    """SIGINT and SIGTERM set ``requested`` while training runs (a second one interrupts at once);
    the previous handlers come back on exit. Outside the main thread no handler is installed."""

    SIGNALS = (signal.SIGINT, signal.SIGTERM)

    def __init__(self) -> None:
        self.requested = False
        self.previous: dict[int, Any] = {}

    def _handle(self, signum, frame) -> None:
        if self.requested:
            raise KeyboardInterrupt
        self.requested = True

    def __enter__(self) -> StopRequest:
        try:
            for signum in self.SIGNALS:
                self.previous[signum] = signal.signal(signum, self._handle)
        except ValueError:  # not the main thread
            self.previous.clear()
        return self

    def __exit__(self, *exc) -> None:
        for signum, handler in self.previous.items():
            signal.signal(signum, handler)


# --- recording the training worlds ---------------------------------------------------------------
class EpisodeLog:
    """Per world: the ``np_random`` state its episode's reset drew from, and the actions since."""

    def __init__(self, worlds: int) -> None:
        self.starts: list[dict | None] = [None] * worlds
        self.actions: list[list[np.ndarray]] = [[] for _ in range(worlds)]

    def started(self, index: int, state: dict) -> None:
        self.starts[index], self.actions[index] = state, []

    def stepped(self, index: int, action: Any) -> None:
        self.actions[index].append(np.array(action, copy=True))

    def mark(self) -> list[tuple[dict | None, list, int]]:
        """The log as it is now, without copying (an episode only appends to its own list)."""
        return [
            (start, actions, len(actions)) for start, actions in zip(self.starts, self.actions, strict=True)
        ]


class RecordEpisodes(gym.Wrapper):
    """Logs one DriveEnv's episodes into ``log`` (world 0); sits right around the DriveEnv."""

    def __init__(self, env: gym.Env) -> None:
        super().__init__(env)
        self.log = EpisodeLog(1)

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        drive = self.env.unwrapped
        generator = drive.np_random
        state = generator.bit_generator.state
        result = self.env.reset(seed=seed, options=options)
        if drive.np_random is not generator:  # reseeded: the new seed's first state
            state = seeding.np_random(drive.np_random_seed)[0].bit_generator.state
        self.log.started(0, state)
        return result

    def step(self, action):
        self.log.stepped(0, action)
        return self.env.step(action)


class RecordVecEpisodes(VecEnvWrapper):
    """Logs the episodes of every world of an ``SB3VecEnv`` (whose worlds reset inside ``step``)."""

    def __init__(self, venv) -> None:
        super().__init__(venv)
        self.vector = venv.vector_env
        self.log = EpisodeLog(self.vector.num_envs)

    def reset(self):
        before = [(rng, rng.bit_generator.state) for rng in self.vector.world_rngs]
        seeds = self.venv._seed
        obs = self.venv.reset()
        for index, (generator, state) in enumerate(before):
            if self.vector.world_rngs[index] is not generator:  # reseeded: the new seed's first state
                state = seeding.np_random(seeds + index)[0].bit_generator.state
            self.log.started(index, state)
        return obs

    def step_async(self, actions: np.ndarray) -> None:
        self._actions = actions
        self.venv.step_async(actions)

    def step_wait(self):
        obs, rewards, dones, infos = self.venv.step_wait()
        self._log_step(self._actions, dones)
        return obs, rewards, dones, infos

    def step_arrays(self, actions: np.ndarray):
        """``SB3VecEnv.step_arrays`` with the episodes logged, as ``step_wait`` logs them."""
        obs, rewards, terminated, truncated, infos = self.venv.step_arrays(actions)
        self._log_step(actions, terminated | truncated)
        return obs, rewards, terminated, truncated, infos

    def _log_step(self, actions: np.ndarray, dones: np.ndarray) -> None:
        """A finished world started its next episode inside the step, from the generator state its
        seed draw recorded (``VectorDriveEnv.draw_states``); every other world took its action."""
        actions = np.array(actions, copy=True)
        for index, done in enumerate(dones):
            if done:
                self.log.started(index, self.vector.draw_states[index])
            else:
                self.log.actions[index].append(actions[index])


class ArrayVecMonitor(VecMonitor):
    """SB3's ``VecMonitor`` that also passes ``step_arrays`` through, recording the finished
    episodes in the infos (``episode`` and the mask ``_episode``) and in monitor.csv as
    ``step_wait`` does."""

    def step_arrays(self, actions: np.ndarray):
        obs, rewards, terminated, truncated, infos = self.venv.step_arrays(actions)
        done = terminated | truncated
        self.episode_returns += rewards.astype(np.float32)
        self.episode_lengths += 1
        if np.count_nonzero(done):
            episodes = np.empty(len(done), dtype=object)
            for index in np.flatnonzero(done):
                episode = {
                    "r": self.episode_returns[index],
                    "l": self.episode_lengths[index],
                    "t": round(time.time() - self.t_start, 6),
                }
                episodes[index] = episode
                self.episode_count += 1
                self.episode_returns[index] = 0
                self.episode_lengths[index] = 0
                if self.results_writer:
                    self.results_writer.write_row(episode)
            infos["episode"], infos["_episode"] = episodes, done.copy()
        return obs, rewards, terminated, truncated, infos


@dataclass
class TrainingWorlds:
    """The training env's monitor, its episode log and its DriveEnvs."""

    monitor: Any
    log: EpisodeLog
    worlds: list

    @classmethod
    def of(cls, monitor, recorder) -> TrainingWorlds:
        worlds = recorder.vector if isinstance(recorder, RecordVecEpisodes) else [recorder.unwrapped]
        return cls(monitor, recorder.log, worlds)

    @property
    def vector(self) -> bool:
        return hasattr(self.monitor, "episode_count")

    def episodes(self) -> int:
        """Episodes the monitor finished (rows it wrote) in this process."""
        return int(self.monitor.episode_count) if self.vector else len(self.monitor.episode_returns)


# --- snapshots -------------------------------------------------------------------------------------
@dataclass
class Snapshot:
    """A safe point's state: ``meta`` for JSON, ``arrays`` for .npz, ``worlds`` the episode log mark."""

    steps: int
    meta: dict
    arrays: dict[str, np.ndarray] = field(default_factory=dict)
    worlds: list = field(default_factory=list)

    def world_actions(self) -> list[np.ndarray]:
        return [
            np.stack(actions[:count]) if count else np.zeros((0,), dtype=np.float32)
            for _, actions, count in self.worlds
        ]


def _rng_state(model) -> tuple[dict, dict[str, np.ndarray]]:
    """Every generator training draws from: JSON part and array part."""
    numpy_state = np.random.get_state(legacy=False)
    arrays = {"numpy_key": numpy_state["state"]["key"].copy(), "torch_cpu": torch.get_rng_state().numpy()}
    meta = {
        "python": random.getstate(),
        "numpy": {"pos": numpy_state["state"]["pos"], "has_gauss": numpy_state["has_gauss"],
                  "gauss": numpy_state["gauss"]},
        "action_space": None,
        "agent_rng": None,
        "torch_cuda": 0,
    }  # fmt: skip
    if torch.cuda.is_available() and torch.cuda.is_initialized():
        states = torch.cuda.get_rng_state_all()
        meta["torch_cuda"] = len(states)
        arrays.update({f"torch_cuda_{i}": state.numpy() for i, state in enumerate(states)})
    if getattr(model, "action_space", None) is not None:
        meta["action_space"] = model.action_space.np_random.bit_generator.state
    if isinstance(getattr(model, "rng", None), np.random.Generator):
        meta["agent_rng"] = model.rng.bit_generator.state
    if isinstance(getattr(model, "generator", None), torch.Generator):
        arrays["agent_generator"] = model.generator.get_state().numpy()
    return meta, arrays


def _observation_arrays(obs: Any, prefix: str) -> tuple[Any, dict[str, np.ndarray]]:
    """(how ``obs`` is stored, its arrays): "array", a list of dict keys, or None."""
    if obs is None:
        return None, {}
    if isinstance(obs, dict):
        return list(obs), {f"{prefix}.{key}": np.array(value, copy=True) for key, value in obs.items()}
    return "array", {prefix: np.array(obs, copy=True)}


def take_snapshot(model, worlds: TrainingWorlds, rows: dict[str, int]) -> Snapshot:
    """The state at a safe point. ``rows``: monitor.csv and evaluations.csv data rows written."""
    rng, arrays = _rng_state(model)
    layout, obs_arrays = _observation_arrays(getattr(model, "_last_obs", None), "last_obs")
    arrays.update(obs_arrays)
    starts = getattr(model, "_last_episode_starts", None)
    if starts is not None:
        arrays["last_episode_starts"] = np.array(starts, copy=True)
    monitor = worlds.monitor
    if worlds.vector:
        arrays["monitor_returns"] = monitor.episode_returns.copy()
        arrays["monitor_lengths"] = monitor.episode_lengths.copy()
        partial: dict = {"episode_count": int(monitor.episode_count)}
    else:
        partial = {"rewards": [float(r) for r in monitor.rewards]}
    partial["elapsed_s"] = time.time() - monitor.t_start
    meta = {
        "format": FORMAT,
        "steps": int(model.num_timesteps),
        "rng": rng,
        "counters": {name: getattr(model, name) for name in COUNTERS if hasattr(model, name)},
        "buffers": {name: list(getattr(model, name)) for name in EPISODE_BUFFERS
                    if isinstance(getattr(model, name, None), deque)},
        "last_obs": layout,
        "monitor": partial,
        "rows": dict(rows),
    }  # fmt: skip
    return Snapshot(int(model.num_timesteps), meta, arrays, worlds.log.mark())


def _restore_rngs(model, meta: dict, arrays: dict[str, np.ndarray]) -> None:
    version, internal, gauss = meta["python"]
    random.setstate((version, tuple(internal), gauss))
    numpy_meta = meta["numpy"]
    np.random.set_state({
        "bit_generator": "MT19937", "state": {"key": arrays["numpy_key"], "pos": numpy_meta["pos"]},
        "has_gauss": numpy_meta["has_gauss"], "gauss": numpy_meta["gauss"],
    })  # fmt: skip
    torch.set_rng_state(torch.from_numpy(np.array(arrays["torch_cpu"])))
    if meta["torch_cuda"] and torch.cuda.is_available():
        torch.cuda.set_rng_state_all(
            [torch.from_numpy(np.array(arrays[f"torch_cuda_{i}"])) for i in range(meta["torch_cuda"])]
        )
    if meta["action_space"] is not None:
        model.action_space.np_random.bit_generator.state = meta["action_space"]
    if meta["agent_rng"] is not None:
        model.rng.bit_generator.state = meta["agent_rng"]
    if "agent_generator" in arrays:
        model.generator.set_state(torch.from_numpy(np.array(arrays["agent_generator"])))


def _saved_observation(layout: Any, arrays: dict[str, np.ndarray], prefix: str) -> Any:
    if layout is None:
        return None
    if layout == "array":
        return np.array(arrays[prefix])
    return {key: np.array(arrays[f"{prefix}.{key}"]) for key in layout}


def apply_to_model(model, snapshot: Snapshot) -> None:
    """Put the model's counters, current observation, episode buffers and every generator back to
    ``snapshot`` (weights and optimizer do not change between safe points)."""
    meta, arrays = snapshot.meta, snapshot.arrays
    for name, value in meta["counters"].items():
        setattr(model, name, value)
    for name, values in meta["buffers"].items():
        current = getattr(model, name, None)
        maxlen = current.maxlen if isinstance(current, deque) else getattr(model, "_stats_window_size", 100)
        setattr(model, name, deque(values, maxlen=maxlen))
    if meta["last_obs"] is not None:
        model._last_obs = _saved_observation(meta["last_obs"], arrays, "last_obs")
    if "last_episode_starts" in arrays:
        model._last_episode_starts = np.array(arrays["last_episode_starts"])
    _restore_rngs(model, meta["rng"], arrays)


# --- restoring the environment -------------------------------------------------------------------
def _replay_world(world, start: dict, actions: np.ndarray) -> Any:
    """Reset ``world`` from generator state ``start`` and take ``actions``; the last observation."""
    world.np_random.bit_generator.state = start
    obs, _ = world.reset()
    for action in actions:
        obs, _, terminated, truncated, _ = world.step(action)
        if terminated or truncated:
            raise UsageError("the checkpoint's episode ends early when replayed (the environment changed?)")
    return obs


def _observation_row(observations: Any, index: int) -> Any:
    if isinstance(observations, dict):
        return {key: value[index] for key, value in observations.items()}
    return observations[index]


def _matches(saved: Any, obs: Any, index: int | None) -> bool:
    """Whether world ``index``'s part of the saved current observation equals the replayed ``obs``
    (None: a single world's). Shapes that differ (an image transposed by SB3) are not compared."""
    if isinstance(saved, dict):
        return all(_matches(saved[key], obs[key], index) for key in saved)
    part = saved if index is None else saved[index]
    obs = np.asarray(obs)
    return part.shape != obs.shape or np.array_equal(part, obs.astype(part.dtype))


def restore(model, worlds: TrainingWorlds, snapshot: Snapshot) -> None:
    """Bring a freshly built training env and a loaded model to ``snapshot``: replay every world's
    episode, restore the monitor's partial episodes, then the model's counters and generators."""
    meta, arrays = snapshot.meta, snapshot.arrays
    saved = _saved_observation(meta["last_obs"], arrays, "last_obs")
    batched = not isinstance(model.get_env(), gym.Env)
    starts = [start for start, _, _ in snapshot.worlds]
    if not isinstance(worlds.worlds, list):  # one VectorDriveEnv: every world replayed together
        replayed = worlds.worlds.replay(starts, snapshot.world_actions())
        observations = [_observation_row(replayed, index) for index in range(len(snapshot.worlds))]
    else:
        (world,), (actions,) = worlds.worlds, snapshot.world_actions()
        observations = [_replay_world(world, starts[0], actions)]
    for index, (start, actions, count) in enumerate(snapshot.worlds):
        worlds.log.started(index, start)
        worlds.log.actions[index] = list(actions[:count])
    for index, replayed_obs in enumerate(observations):
        if saved is not None and not _matches(saved, replayed_obs, index if batched else None):
            raise UsageError(
                "the checkpoint's episode does not replay to its observation (the environment changed?)"
            )
    monitor, partial = worlds.monitor, meta["monitor"]
    if worlds.vector:
        monitor.episode_returns[:] = arrays["monitor_returns"]
        monitor.episode_lengths[:] = arrays["monitor_lengths"]
    else:
        monitor.rewards, monitor.needs_reset = list(partial["rewards"]), False
    monitor.t_start = time.time() - partial["elapsed_s"]  # monitor.csv's t goes on from the checkpoint
    apply_to_model(model, snapshot)


# --- files -----------------------------------------------------------------------------------------
def state_path(folder: Path, steps: int) -> Path:
    """The JSON file of the resume state of the checkpoint at ``steps``."""
    return _paths(folder, steps)[0]


def _paths(folder: Path, steps: int) -> tuple[Path, Path]:
    return folder / f"resume-{steps}.json", folder / f"resume-{steps}.npz"


def _json_default(value: Any) -> Any:
    if isinstance(value, np.generic):
        return value.item()
    raise TypeError(f"cannot store {type(value).__name__} in a resume state")


def write_state(folder: Path, snapshot: Snapshot) -> None:
    """``resume-<steps>.json`` + ``.npz``, each written whole (``safe_files.replacing``)."""
    json_path, npz_path = _paths(folder, snapshot.steps)
    actions = {f"world_{index}_actions": taken for index, taken in enumerate(snapshot.world_actions())}
    with replacing(npz_path, folder / "resume.tmp.npz") as tmp_npz:
        with tmp_npz.open("wb") as handle:
            np.savez(handle, **{**snapshot.arrays, **actions})
        npz_sha256 = hashlib.sha256(tmp_npz.read_bytes()).hexdigest()
    meta = {**snapshot.meta, "worlds": [{"start": start} for start, _, _ in snapshot.worlds],
            "npz_sha256": npz_sha256}  # fmt: skip
    write_file(json_path, json.dumps(meta, default=_json_default), folder / "resume.tmp.json")


def read_state(folder: Path, steps: int) -> Snapshot | None:
    """The resume state of the checkpoint at ``steps`` (None: it has none); a damaged one is a UsageError."""
    json_path, npz_path = _paths(folder, steps)
    if not json_path.is_file():
        return None
    try:
        meta = json.loads(json_path.read_text())
        if not isinstance(meta, dict) or meta.get("format") != FORMAT or meta["steps"] != steps:
            raise ValueError("format or steps")
        _check_meta(meta)
        if hashlib.sha256(npz_path.read_bytes()).hexdigest() != meta["npz_sha256"]:
            raise ValueError("checksum")
        with np.load(npz_path, allow_pickle=False) as data:
            arrays = {key: data[key] for key in data.files}
        worlds = []
        for index, world in enumerate(meta.pop("worlds")):
            actions = list(arrays.pop(f"world_{index}_actions"))
            worlds.append((world["start"], actions, len(actions)))
    except (OSError, ValueError, KeyError, TypeError, AttributeError, IndexError) as exc:
        raise UsageError(f"resume state {str(json_path)!r} is damaged ({exc})") from None
    return Snapshot(steps, meta, arrays, worlds)


def _check_meta(meta: dict) -> None:
    """A ValueError naming the first part of a resume state's JSON that is not as ``take_snapshot``
    writes it; the rest is checked by restoring (``check_restore``)."""

    def need(ok: bool, what: str) -> None:
        if not ok:
            raise ValueError(f"{what} is malformed")

    def counts(value: Any) -> bool:
        return isinstance(value, int) and not isinstance(value, bool) and value >= 0

    rows, monitor, rng = meta.get("rows"), meta.get("monitor"), meta.get("rng")
    need(isinstance(rows, dict) and all(counts(rows.get(key)) for key in ("monitor", "evaluations")), "rows")
    need(isinstance(monitor, dict) and is_number(monitor.get("elapsed_s")), "monitor")
    rewards = monitor.get("rewards", [])
    need(isinstance(rewards, list) and all(is_number(reward) for reward in rewards), "monitor rewards")
    need(isinstance(rng, dict) and {"python", "numpy", "action_space", "agent_rng"} <= set(rng), "rng")
    python = rng["python"]
    need(isinstance(python, list) and len(python) == 3 and isinstance(python[1], list), "rng python")
    need(counts(rng.get("torch_cuda")), "rng torch_cuda")
    need(isinstance(meta.get("counters"), dict) and isinstance(meta.get("buffers"), dict), "counters")
    check_counters(meta["counters"])  # set on the model as attributes: only counters, each of its kind
    need(meta["counters"].get("num_timesteps", meta["steps"]) == meta["steps"], "counter num_timesteps")
    need(all(isinstance(values, list) for values in meta["buffers"].values()), "buffers")
    need(meta.get("last_obs") in (None, "array") or isinstance(meta["last_obs"], list), "last_obs")
    worlds = meta.get("worlds")
    need(isinstance(worlds, list) and len(worlds) > 0, "worlds")
    need(all(isinstance(world, dict) and isinstance(world.get("start"), dict) for world in worlds), "worlds")


def check_restore(model, worlds: TrainingWorlds, snapshot: Snapshot, path: Path) -> None:
    """``restore`` into ``model`` and a training env built for this check, before anything of the
    run changes: a state that does not restore is a UsageError naming ``path``."""
    try:
        restore(model, worlds, snapshot)
    except UsageError as exc:
        raise UsageError(f"resume state {str(path)!r}: {exc}") from None
    except (ValueError, TypeError, KeyError, IndexError, AttributeError, RuntimeError, OverflowError) as exc:
        raise UsageError(f"resume state {str(path)!r} is damaged ({type(exc).__name__}: {exc})") from None


def prune_states(folder: Path, keep_steps: int) -> None:
    """Remove the resume states of checkpoints other than the one at ``keep_steps``."""
    keep = set(_paths(folder, keep_steps))
    for path in folder.iterdir():
        if STATE_NAME.fullmatch(path.name) and path not in keep:
            remove_file(path)


# --- logs back to the checkpoint -------------------------------------------------------------------
def count_rows(path: Path, header_lines: int) -> int:
    """Data rows of a CSV log (0 when it does not exist)."""
    if not path.is_file():
        return 0
    with path.open() as handle:
        return max(sum(1 for _ in handle) - header_lines, 0)


def _head(path: Path, header_lines: int, rows: int) -> str | None:
    """The text of ``path`` cut after ``rows`` data rows (None: nothing to cut)."""
    if not path.is_file():
        return None
    lines = path.read_text().splitlines(keepends=True)
    return None if len(lines) <= header_lines + rows else "".join(lines[: header_lines + rows])


def _progress_upto(path: Path, steps: int) -> str | None:
    """progress.csv's rows logged at ``steps`` or before ("" when none is; None: unchanged)."""
    lines = path.read_text().splitlines(keepends=True)
    if not lines:
        return None
    header = next(csv.reader(lines[:1]))
    if "time/total_timesteps" not in header:
        return None
    column = header.index("time/total_timesteps")
    kept = [line for line, row in zip(lines[1:], csv.reader(lines[1:]), strict=True)
            if len(row) > column and row[column] and float(row[column]) <= steps]  # fmt: skip
    if len(kept) == len(lines) - 1:
        return None
    return "".join(lines[:1] + kept) if kept else ""


def _evaluations_upto(path: Path, steps: int) -> str | None:
    """evaluations.csv's rows of ``steps`` or before (for checkpoints without a resume state)."""
    if not path.is_file():
        return None
    lines = path.read_text().splitlines(keepends=True)
    kept = [line for line, row in zip(lines[1:], csv.reader(lines[1:]), strict=True) if int(row[0]) <= steps]
    return None if len(kept) == len(lines) - 1 else "".join(lines[:1] + kept)


def plan_truncation(run_dir: Path, steps: int, snapshot: Snapshot | None) -> dict[Path, str | None]:
    """What a resume from the checkpoint at ``steps`` must rewrite (path → new text) or delete (path
    → None): logs written after the checkpoint, and results of the older model. Reads only."""
    try:
        if snapshot is not None:
            rows = snapshot.meta["rows"]
            cuts = {
                run_dir / "monitor.csv": _head(run_dir / "monitor.csv", 2, rows["monitor"]),
                run_dir / "evaluations.csv": _head(run_dir / "evaluations.csv", 1, rows["evaluations"]),
            }
        else:  # no row counts: evaluations by their step; monitor.csv cannot be cut exactly
            cuts = {run_dir / "evaluations.csv": _evaluations_upto(run_dir / "evaluations.csv", steps)}
        for path in sorted(run_dir.glob("progress*.csv")):
            cuts[path] = _progress_upto(path, steps)
    except (OSError, ValueError, IndexError, csv.Error, UnicodeDecodeError) as exc:
        raise UsageError(f"cannot read the logs of {str(run_dir)!r} to resume ({exc})") from None
    changes = {path: text or None for path, text in cuts.items() if text is not None}  # "": no row left
    for name in STALE_RESULTS:
        if (run_dir / name).exists():
            changes[run_dir / name] = None
    for path in run_dir.glob("eval-maps-*.json"):  # ``drivelab evaluate --maps``: also the old model's
        changes[path] = None
    return changes


def apply_truncation(changes: dict[Path, str | None]) -> None:
    """Write ``plan_truncation``'s changes, the rewrites first (a full disk fails one of them before
    anything is deleted)."""
    for path, text in changes.items():
        if text is not None:
            write_file(path, text)
    for path, text in changes.items():
        if text is None:
            remove_file(path)


def warn_inexact() -> None:
    print(
        "warning: the checkpoint has no resume state (an older drivelab wrote it); training goes on "
        "from a new episode and will not match an uninterrupted run",
        file=sys.stderr,
    )
