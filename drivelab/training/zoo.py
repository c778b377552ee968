"""Shipped agents: the zoo inside the package, ``drivelab zoo`` and ``drivelab enjoy``.

A shipped agent is a run directory cut down to what acting needs, in ``drivelab/zoo/<name>/``:
config.yaml, model.zip (float16 weights, no optimizer moments) and card.json (what it is and every
evaluation measured on it; see docs/zoo.md). Loading one is loading a run directory: nothing is
unpickled, and every command that takes a run directory takes a zoo name too.
``benchmarks/zoo_build.py`` trains, packs and measures them."""

from __future__ import annotations

import io
import json
import os
import shutil
import tempfile
import zipfile
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, NamedTuple

import numpy as np

from drivelab.errors import UsageError

if TYPE_CHECKING:
    from drivelab.config import RunConfig

ZOO_DIR = Path(__file__).resolve().parents[1] / "zoo"
CARD_FORMAT = "drivelab-zoo-1"
# the run fields a card repeats from config.yaml, in its order
CARD_RUN_FIELDS = ("algo", "env", "obs", "action", "reward", "traffic", "seed", "hyperparams")
VIDEO_SUFFIXES = (".mp4", ".gif")


@dataclass(frozen=True)
class ShippedAgent:
    """One agent of the zoo: its folder (a run directory: config.yaml, model.zip) and its card."""

    name: str
    path: Path
    card: dict


def shipped_agents(zoo_dir: Path | None = None) -> list[ShippedAgent]:
    """Every agent of ``zoo_dir`` (default: the package's zoo), sorted by name."""
    zoo_dir = ZOO_DIR if zoo_dir is None else zoo_dir
    cards = sorted(zoo_dir.glob("*/card.json")) if zoo_dir.is_dir() else []
    return [
        ShippedAgent(card.parent.name, card.parent, json.loads(card.read_text()))
        for card in cards
        if not card.parent.name.startswith(".")  # a pack in progress
    ]


def resolve(target: str | Path, zoo_dir: Path | None = None) -> tuple[Path, str | None]:
    """(run directory, zoo name or None) of a command's ``target``: a directory, else a shipped agent."""
    path = Path(target)
    if path.is_dir():
        return path, None
    agents = {agent.name: agent for agent in shipped_agents(zoo_dir)}
    if str(target) in agents:
        return agents[str(target)].path, str(target)
    if path.exists():
        raise UsageError(f"{str(target)!r} is a file, not a run directory")
    names = ", ".join(agents) or "none"
    raise UsageError(
        f"run directory or shipped agent {str(target)!r} does not exist (`drivelab zoo` lists: {names})"
    )


class Trained(NamedTuple):
    """A run's agent, loaded to act (``load_trained``)."""

    agent: Any
    config: RunConfig
    run_dir: Path
    name: str | None  # the shipped agent's name; None for a run directory
    env: Any  # the run's evaluation environment, whose spaces the agent's are


def load_trained(target: str | Path) -> Trained:
    """The agent of a run directory or of a shipped agent (its final model, else its latest verified
    checkpoint), built on the run's evaluation environment; a UsageError when its spaces or config
    are not those it was trained with, or the run is being trained now."""
    from drivelab.envs.core import DriveEnv
    from drivelab.training.checkpoints import check_trained_config, load_agent
    from drivelab.training.evaluate import check_spaces, load_run_config
    from drivelab.training.safe_files import locked_run

    run_dir, name = resolve(target)
    with locked_run(run_dir, writes=False):  # not a run that trains now
        config = load_run_config(run_dir)
        env = DriveEnv(**config.eval_env_kwargs())
        agent = load_agent(run_dir, config, env)
        check_spaces(agent, env, run_dir)
        check_trained_config(run_dir, config)
    return Trained(agent, config, run_dir, name, env)


def report_dir(target: str | Path, out: Path | None, runs_dir: Path = Path("runs")) -> Path | None:
    """Where an evaluation of ``target`` writes its reports: ``out`` when given, else None (the run
    directory itself) for a run directory and ``runs_dir/zoo-<name>`` for a shipped agent."""
    _, name = resolve(target)
    if out is not None or name is None:
        return out
    return runs_dir / f"zoo-{name}"


# --- the card's numbers ------------------------------------------------------------------------
def headline(card: dict) -> str:
    """One line of the card's main measured numbers, with their episode counts."""
    parts = []
    for evaluation in card.get("evaluations", []):
        metrics = evaluation["metrics"]
        if evaluation["protocol"] == "nocrash":
            levels = metrics["levels"]
            success = " / ".join(f"{100 * levels[level]['success_rate']:.0f}" for level in levels)
            parts.append(
                f"NoCrash {metrics['town']} town {'/'.join(levels)} {success} % "
                f"({metrics['episodes_per_level']} episodes per level)"
            )
        else:
            parts.append(
                f"{evaluation['protocol']}: crash {100 * metrics['crash_rate']:.0f} %, success "
                f"{100 * metrics['success_rate']:.0f} %, {metrics['mean_speed_mps']:.1f} m/s "
                f"({metrics['episodes']} episodes)"
            )
    return "; ".join(parts) or "not measured"


# --- packing -----------------------------------------------------------------------------------
def _drop_optimizer_moments(agent) -> None:
    """Empty the state of every optimizer the agent (or its SB3 policy) holds: a fresh optimizer's."""
    import torch

    holders = [agent, getattr(agent, "policy", None)]
    for holder in (h for h in holders if h is not None):
        for value in vars(holder).values():
            if isinstance(value, torch.optim.Optimizer):
                value.state.clear()


def _halve(state, converted: dict):
    """``state`` (nested dicts/lists of tensors) with every float32 tensor as float16; a tensor
    shared by two entries stays one tensor (``converted``: by storage view)."""
    import torch

    if isinstance(state, dict):
        return {key: _halve(value, converted) for key, value in state.items()}
    if isinstance(state, (list, tuple)):
        return type(state)(_halve(value, converted) for value in state)
    if isinstance(state, torch.Tensor) and state.dtype == torch.float32:
        view = (state.untyped_storage().data_ptr(), state.storage_offset(), state.shape, state.stride())
        if view not in converted:
            largest = float(state.abs().max()) if state.numel() else 0.0
            if largest > torch.finfo(torch.float16).max:
                raise UsageError(
                    f"a weight of magnitude {largest:.3g} does not fit float16 (at most 65504): the model "
                    "cannot be shipped in half precision"
                )
            converted[view] = state.half()
        return converted[view]
    return state


def _store_half_precision(path: Path) -> None:
    """Rewrite the tensor files (``*.pt``) of the model zip ``path`` with float16 weights."""
    from drivelab.agents.storage import tensors_from_bytes, tensors_to_bytes

    with zipfile.ZipFile(path) as archive:
        members = {name: archive.read(name) for name in archive.namelist()}
    for name in members:
        if name.endswith(".pt"):
            members[name] = tensors_to_bytes(_halve(tensors_from_bytes(members[name]), {}))
    with zipfile.ZipFile(path, "w", compression=zipfile.ZIP_DEFLATED) as archive:
        for name, data in members.items():
            archive.writestr(name, data)


def pack(
    run_dir: str | Path,
    name: str,
    description: str,
    command: str,
    timing: dict | None = None,
    zoo_dir: Path | None = None,
) -> Path:
    """Copy ``run_dir``'s config and final model into ``zoo_dir/name`` (replacing an older copy)
    with a card: ``description``, the training ``command``, its ``timing`` (default: the run's
    train_timing.json if any) and what the run directory records. The model is saved without the
    optimizer's moments, in float16. Evaluations are added by ``add_evaluation``."""
    from drivelab.config import check_run_name, save_yaml
    from drivelab.training.checkpoints import file_sha256, load_agent
    from drivelab.training.evaluate import load_run_config

    run_dir, zoo_dir = Path(run_dir), ZOO_DIR if zoo_dir is None else zoo_dir
    check_run_name(name)
    config = load_run_config(run_dir)
    if not (run_dir / "model.zip").is_file():
        raise UsageError(f"{str(run_dir)!r} has no final model.zip (train it to the end first)")
    agent = load_agent(run_dir, config)
    _drop_optimizer_moments(agent)
    timing_path = run_dir / "train_timing.json"
    if timing is None:
        timing = json.loads(timing_path.read_text()) if timing_path.is_file() else {}
    zoo_dir.mkdir(parents=True, exist_ok=True)
    staging = Path(tempfile.mkdtemp(prefix=f".{name}.", dir=zoo_dir))
    staging.chmod(0o755)  # mkdtemp's 0700 would make the installed agent unreadable to others
    try:
        save_yaml(config, staging / "config.yaml")
        agent.save(staging / "model.zip")
        _store_half_precision(staging / "model.zip")
        full = {
            "format": CARD_FORMAT,
            "name": name,
            "description": description,
            **{key: value for key, value in config.to_dict().items() if key in CARD_RUN_FIELDS},
            "training": {
                "steps": int(agent.num_timesteps),
                "n_envs": config.n_envs,
                **timing,
                "command": command,
            },
            "model": {
                "file": "model.zip",
                "bytes": (staging / "model.zip").stat().st_size,
                "sha256": file_sha256(staging / "model.zip"),
                "weights": "float16 (loaded into the float32 networks)",
                "optimizer_moments": "dropped (acting does not use them; fine-tuning restarts Adam)",
            },
            "evaluations": [],
        }
        (staging / "card.json").write_text(json.dumps(full, indent=2) + "\n")
        target = zoo_dir / name
        if target.exists():
            shutil.rmtree(target)
        os.replace(staging, target)
    finally:
        shutil.rmtree(staging, ignore_errors=True)
    return target


def model_differences(first: str | Path, second: str | Path) -> dict[str, str]:
    """How the model zips ``first`` and ``second`` differ, member by member, in the values they hold
    (``_without_clock``): {} when they hold the same; otherwise, per member, how (missing from one,
    other keys, other shapes, the largest absolute difference). Nothing is unpickled."""
    with zipfile.ZipFile(first) as one, zipfile.ZipFile(second) as two:
        left = {name: one.read(name) for name in one.namelist()}
        right = {name: two.read(name) for name in two.namelist()}
    differences = {}
    for name in sorted(set(left) | set(right)):
        if name not in right or name not in left:
            differences[name] = f"only in {str(first if name in left else second)!r}"
        elif left[name] != right[name]:
            difference = _member_difference(name, left[name], right[name])
            if difference is not None:
                differences[name] = difference
    return differences


def _member_difference(name: str, left: bytes, right: bytes) -> str | None:
    """How two versions of one model-zip member differ in their values (None: they do not)."""
    from drivelab.agents.storage import read_arrays, tensors_from_bytes

    if name.endswith(".json"):
        a, b = _without_clock(json.loads(left)), _without_clock(json.loads(right))
        if a == b:
            return None
        if isinstance(a, dict) and isinstance(b, dict):
            keys = sorted(k for k in set(a) | set(b) if a.get(k, b) != b.get(k, a))
            return "other values of " + ", ".join(map(str, keys))
        return "other values"
    if name.endswith(".pt"):
        a, b = _leaves(tensors_from_bytes(left)), _leaves(tensors_from_bytes(right))
    elif name.endswith(".npz"):
        a, b = read_arrays(left), read_arrays(right)
    elif name.endswith(".npy"):
        a, b = ({"": np.load(io.BytesIO(data), allow_pickle=False)} for data in (left, right))
    else:
        return "other bytes"
    if set(a) != set(b):
        return "other entries: " + ", ".join(sorted(set(a) ^ set(b)))
    largest, nan_against_number, shapes = 0.0, False, []
    for key in sorted(a):
        x, y = np.asarray(a[key]), np.asarray(b[key])
        if x.shape != y.shape:
            shapes.append(key)
            continue
        floating = x.dtype.kind in "fc" or y.dtype.kind in "fc"
        differ = (x != y) & ~(np.isnan(x) & np.isnan(y)) if floating else x != y
        if differ.any() and not floating:  # whole numbers: exactly (a float64 rounds 2**53 + 1)
            largest = max(
                largest, float(max(abs(int(p) - int(q)) for p, q in zip(x[differ], y[differ], strict=True)))
            )
        elif differ.any():  # gaps: nan where one side is nan; > 0 elsewhere
            gaps = np.abs(x[differ].astype(np.float64) - y[differ].astype(np.float64))
            nan_against_number |= bool(np.isnan(gaps).any())
            largest = max(largest, float(np.max(gaps, initial=0.0, where=~np.isnan(gaps))))
    if shapes:
        return "other shapes: " + ", ".join(shapes)
    if nan_against_number:
        return "nan against a number" + (f"; max |difference| elsewhere {largest:.3g}" if largest else "")
    return None if largest == 0.0 else f"max |difference| {largest:.3g}"


def _without_clock(state):
    """A model's JSON without SB3's wall-clock records (``t``, ``_num_timesteps_at_start``)."""
    if not isinstance(state, dict):
        return state
    state = dict(state)
    if isinstance(state.get("ep_info_buffer"), list):
        state["ep_info_buffer"] = [
            {k: v for k, v in e.items() if k != "t"} if isinstance(e, dict) else e
            for e in state["ep_info_buffer"]
        ]
    if isinstance(state.get("counters"), dict):
        state["counters"] = {k: v for k, v in state["counters"].items() if k != "_num_timesteps_at_start"}
    return state


def _leaves(state, prefix: str = "") -> dict[str, np.ndarray]:
    """Every tensor and number of nested dicts/lists of them, as arrays keyed by their paths."""
    import torch

    if isinstance(state, dict):
        items = state.items()
    elif isinstance(state, (list, tuple)):
        items = enumerate(state)
    else:
        if not isinstance(state, torch.Tensor):
            return {prefix: np.asarray(state)}
        tensor = state.detach()  # numpy has no bfloat16; float32 holds its every value
        return {prefix: (tensor.float() if tensor.dtype == torch.bfloat16 else tensor).numpy()}
    return {path: leaf for key, value in items for path, leaf in _leaves(value, f"{prefix}/{key}").items()}


def add_evaluation(name: str, evaluation: dict, zoo_dir: Path | None = None) -> dict:
    """Record ``evaluation`` in ``name``'s card, replacing one of the same protocol; the card."""
    path = (ZOO_DIR if zoo_dir is None else zoo_dir) / name / "card.json"
    card = json.loads(path.read_text())
    kept = [e for e in card["evaluations"] if e["protocol"] != evaluation["protocol"]]
    card["evaluations"] = [*kept, evaluation]
    path.write_text(json.dumps(card, indent=2) + "\n")
    return card


# --- enjoy -------------------------------------------------------------------------------------
def check_video_path(path: Path) -> None:
    """A UsageError unless a video can be written at ``path`` (checked before any episode)."""
    if path.suffix.lower() not in VIDEO_SUFFIXES:
        raise UsageError(f"--video {str(path)!r} must end in .mp4 or .gif")
    from drivelab.training.evaluate import check_output_file, has_mp4_encoder

    if path.suffix.lower() == ".mp4" and not has_mp4_encoder():
        raise UsageError("no mp4 encoder (imageio-ffmpeg's ffmpeg) is installed: use a .gif path")
    if path.is_dir():
        raise UsageError(f"--video {str(path)!r} is a directory")
    check_output_file(path, "--video")


class VideoFile:
    """Frames streamed to a temporary video, renamed to ``path`` by ``close``, removed by ``discard``."""

    def __init__(self, path: Path, fps: float) -> None:
        import imageio.v2 as imageio

        self.path = path
        self.temporary = path.with_name(f".{path.stem}.partial{path.suffix}")
        if path.suffix.lower() == ".mp4":
            self.writer = imageio.get_writer(self.temporary, fps=fps, macro_block_size=1)
        else:
            self.writer = imageio.get_writer(self.temporary, mode="I", duration=1000 / fps, loop=0)
        self.frames = 0

    def append(self, frame: np.ndarray) -> None:
        self.writer.append_data(frame)
        self.frames += 1

    def close(self) -> Path:
        self.writer.close()
        os.replace(self.temporary, self.path)
        return self.path

    def discard(self) -> None:
        try:
            self.writer.close()
        finally:
            self.temporary.unlink(missing_ok=True)


def enjoy(
    target: str | Path,
    episodes: int = 3,
    video: Path | None = None,
    seed: int | None = None,
    on_episode: Callable[[int, dict], None] | None = None,
    zoo_dir: Path | None = None,
    side_by_side: bool | None = None,
) -> dict:
    """Drive a shipped agent (or a run directory's model) greedily for ``episodes`` episodes and
    return its metrics (``evaluate.aggregate``) with the per-episode ones; writes only ``video``.

    :param seed: None: the scenario's fixed evaluation episodes; an int S: episode e is the first
        episode of the env seeded S + e.
    :param on_episode: called with (episode index, episode metrics) after each episode.
    :param side_by_side: the video shows the agent's image observation beside the scene; None: when
        it has one."""
    from drivelab.envs.core import DriveEnv
    from drivelab.envs.video import video_fps
    from drivelab.training.checkpoints import file_sha256, load_agent, model_path
    from drivelab.training.evaluate import aggregate, check_spaces, load_run_config, run_episodes

    if episodes < 1:
        raise UsageError("--episodes must be >= 1")
    if seed is not None and not 0 <= seed < 2**31 - 1:
        raise UsageError("--seed must be in [0, 2**31 - 1)")
    run_dir, name = resolve(target, zoo_dir)
    config = load_run_config(run_dir)
    if video is not None:
        check_video_path(video)
    env = DriveEnv(**config.eval_env_kwargs())
    agent = load_agent(run_dir, config)
    check_spaces(agent, env, run_dir)
    policy = lambda obs: agent.predict(obs, deterministic=True)[0]  # noqa: E731
    writer = VideoFile(video, video_fps(env)) if video is not None else None
    done: list[dict] = []

    def episode_done(metrics: dict) -> None:
        done.append(metrics)
        if on_episode is not None:
            on_episode(len(done) - 1, metrics)

    try:
        on_frame = writer.append if writer is not None else None
        results, _ = run_episodes(
            policy, env, episodes, seed, on_episode=episode_done, on_frame=on_frame, side_by_side=side_by_side
        )
    except BaseException:
        if writer is not None:
            writer.discard()
        raise
    report = {"agent": name or str(run_dir), "algo": config.algo, "env": config.env, **aggregate(results)}
    report["model_steps"] = int(agent.num_timesteps)  # as evaluate's report
    report["model_sha256"] = file_sha256(model_path(run_dir, config))
    report["seed"] = seed
    if writer is not None:
        report["video"] = str(writer.close())
        report["video_frames"] = writer.frames
    report["per_episode"] = results
    return report


def check_metrics(name: str, zoo_dir: str | None = None) -> dict:
    """The metrics of agent ``name``'s card check, played in this process: its first ``episodes``
    evaluation episodes, greedy, each cut at the check's ``duration_s`` where it has one. Recorded
    and compared under ``drivelab.isa.PINNED_ISA`` (``pinned_check_metrics``)."""
    from drivelab.envs.core import DriveEnv
    from drivelab.training.checkpoints import load_agent
    from drivelab.training.evaluate import aggregate, load_run_config, run_episodes

    agents = {agent.name: agent for agent in shipped_agents(None if zoo_dir is None else Path(zoo_dir))}
    if name not in agents:
        raise UsageError(f"shipped agent {name!r} does not exist (`drivelab zoo` lists: {', '.join(agents)})")
    run_dir, check = agents[name].path, agents[name].card["check"]
    config = load_run_config(run_dir)
    limit = {"duration_s": check["duration_s"]} if "duration_s" in check else {}
    env = DriveEnv(**{**config.eval_env_kwargs(), **limit})
    agent = load_agent(run_dir, config)
    policy = lambda obs: agent.predict(obs, deterministic=True)[0]  # noqa: E731
    return aggregate(run_episodes(policy, env, check["episodes"])[0])


def pinned_check_metrics(name: str, zoo_dir: Path | None = None) -> dict:
    """``check_metrics`` in a fresh process under ``drivelab.isa.PINNED_ISA``."""
    from drivelab.isa import call_pinned

    return call_pinned(f"{__name__}:check_metrics", name, *([] if zoo_dir is None else [str(zoo_dir)]))
