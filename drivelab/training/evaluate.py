"""Evaluation: run a policy for N episodes and report driving metrics."""

from __future__ import annotations

import contextlib
import json
import math
import tempfile
from collections.abc import Callable
from pathlib import Path

import numpy as np
from gymnasium import spaces
from tqdm import tqdm

from drivelab.config import RunConfig, build_config, parse_maps
from drivelab.errors import UsageError
from drivelab.training.metrics import labels
from drivelab.training.safe_files import (
    check_folder,
    check_replaceable,
    check_run_dir,
    locked_run,
    make_folder,
    remove_empty_folders,
    remove_file,
    replacing,
    write_failure,
    write_file,
)
from drivelab.yaml_io import load_yaml


def run_episodes(
    policy: Callable,
    env,
    episodes: int,
    seed: int | None = None,
    record_first: bool = False,
    on_episode: Callable[[dict], None] | None = None,
    on_frame: Callable[[np.ndarray], None] | None = None,
    side_by_side: bool | None = None,
    first: int = 0,
) -> tuple[list[dict], list[np.ndarray]]:
    """Play ``episodes`` episodes; return each one's ``episode_metrics`` and, with ``record_first``,
    the video frames of the first episode (``envs/video.py``'s, one per simulation frame).
    ``on_episode`` is called with each episode's metrics, ``on_frame`` with every frame of every
    episode (not kept).

    :param seed: None: the scenario's evaluation episodes (``evaluation_seeds``, none of them a
        training episode); an int: episode e is the first episode of the env seeded ``seed + e``.
    :param side_by_side: show the agent's image observation left of the scene; None: when it has
        one.
    :param first: with ``seed`` None, play evaluation episodes ``first`` … (``VALIDATION_START``:
        tuning's validation episodes)."""
    from drivelab.training.seeds import evaluation_seeds

    recorder = None
    if record_first or on_frame is not None:
        from drivelab.envs.video import EpisodeRecorder

        recorder = EpisodeRecorder(env, side_by_side)
    results, frames = [], []
    fixed = evaluation_seeds(episodes, first) if seed is None else None
    for episode in range(episodes):
        if fixed is None:
            obs, _ = env.reset(seed=seed + episode)
        else:
            obs, _ = env.reset(options={"episode_seed": int(fixed[episode])})
        keep = record_first and episode == 0
        record = recorder is not None and (keep or on_frame is not None)

        def show(new: list[np.ndarray], keep: bool = keep) -> None:
            if keep:
                frames.extend(new)
            if on_frame is not None:
                for frame in new:
                    on_frame(frame)

        if record:
            show([recorder.first_frame(episode)])
        while True:
            if record:
                (obs, _, terminated, truncated, info), new = recorder.step(policy(obs))
                show(new)
            else:
                obs, _, terminated, truncated, info = env.step(policy(obs))
            if terminated or truncated:
                results.append(info["episode_metrics"])
                if on_episode is not None:
                    on_episode(info["episode_metrics"])
                break
    return results, frames


def aggregate(results: list[dict]) -> dict[str, float]:
    """Mean return ± std, success / crash rates, distance, speed, events per km."""
    returns = np.array([r["return"] for r in results], dtype=float)
    km = sum(r["distance_km"] for r in results)
    per_km = lambda key: sum(r.get(key, 0) for r in results) / km if km > 0 else None  # noqa: E731
    completion = [r["route_completion"] for r in results if r["route_completion"] is not None]
    return {
        "episodes": len(results),
        "mean_return": float(returns.mean()),
        "std_return": float(returns.std()),
        "success_rate": float(np.mean([r["success"] for r in results])),
        "crash_rate": float(np.mean([r["crashed"] for r in results])),
        "mean_distance_km": km / len(results),
        "mean_speed_mps": float(np.mean([r["mean_speed_mps"] for r in results])),
        "mean_length": float(np.mean([r["length"] for r in results])),
        "collisions_per_km": per_km("collisions"),
        "pedestrian_collisions_per_km": per_km("pedestrian_collisions"),
        "vehicle_collisions_per_km": per_km("collisions") - per_km("pedestrian_collisions") if km else None,
        "off_road_per_km": per_km("off_road_events"),
        "red_lights_per_km": per_km("red_lights"),
        "blocked_per_km": per_km("blocked"),
        "route_completion": float(np.mean(completion)) if completion else None,
    }


def has_mp4_encoder() -> bool:
    """Whether imageio-ffmpeg and its ffmpeg are installed (mp4 videos; else gif, with Pillow)."""
    try:
        import imageio_ffmpeg

        imageio_ffmpeg.get_ffmpeg_exe()
    except (ImportError, RuntimeError):
        return False
    return True


def write_video(frames: list[np.ndarray], path: Path, fps: float) -> Path:
    """Write frames as mp4, or as a gif where no mp4 encoder is installed, whole or not at all
    (``safe_files.replacing``); a failed write is one line."""
    import imageio.v2 as imageio

    made = not path.parent.exists()
    make_folder(path.parent)
    mp4 = has_mp4_encoder()
    final = path.with_suffix(".mp4" if mp4 else ".gif")
    try:
        with replacing(final, final.with_name(f"{final.stem}.tmp{final.suffix}")) as temporary:
            if mp4:
                # ffmpeg says nothing: a failure (a full disk) is this function's one line
                quiet = {"macro_block_size": 1, "ffmpeg_log_level": "quiet"}
                imageio.mimwrite(temporary, frames, fps=max(fps, 1), **quiet)
            else:
                imageio.mimwrite(temporary, frames, duration=1000 / max(fps, 1))
    except Exception as exc:  # ffmpeg's failures (a full disk too) come as its own errors
        if made:
            with contextlib.suppress(OSError):
                path.parent.rmdir()
        raise exc if isinstance(exc, UsageError) else write_failure(exc, final) from None
    return final


def report_name(maps: str | None = None) -> str:
    """``eval.json``, or ``eval-maps-START-COUNT.json`` on block maps ``maps`` ("START:COUNT")."""
    return "eval.json" if maps is None else "eval-maps-{}-{}.json".format(*parse_maps(maps))


def load_run_config(run_dir: Path) -> RunConfig:
    """The resolved config of an existing run directory."""
    check_run_dir(run_dir)
    config_path = run_dir / "config.yaml"
    if not config_path.is_file():
        raise UsageError(f"{str(run_dir)!r} is not a drivelab run directory (no config.yaml)")
    return build_config(load_yaml(config_path))


def evaluate_run(
    run_dir: str | Path,
    episodes: int = 10,
    video: bool = False,
    deterministic: bool = True,
    out_dir: str | Path | None = None,
    maps: str | None = None,
    side_by_side: bool | None = None,
    first: int = 0,
    progress: bool = False,
) -> dict:
    """Evaluate the final model of ``run_dir`` (or its latest checkpoint); write eval.json (and the
    video) into ``out_dir`` (default: the run directory; created if missing).

    :param maps: procedural maps only: ``"START:COUNT"``, play the maps of seeds START … START +
        COUNT − 1 instead of the run's evaluation maps, and write ``eval-maps-START-COUNT.json``.
    :param side_by_side: the video shows the agent's image observation beside the scene; None: when
        it has one.
    :param first: the first evaluation episode played (``run_episodes``).
    :param progress: show a progress bar of the episodes (on stderr)."""
    from drivelab.envs.core import DriveEnv
    from drivelab.envs.video import video_fps
    from drivelab.training.checkpoints import check_trained_config, file_sha256, load_agent, model_path

    if episodes < 1:
        raise UsageError("--episodes must be >= 1")
    run_dir = Path(run_dir)
    with locked_run(run_dir, writes=out_dir is None):  # no evaluation of a run that trains now
        config = load_run_config(run_dir)
        trained = config
        if maps is not None:
            config = build_config({**config.to_dict(), "eval_maps": maps})  # checks START:COUNT, scenario
        name = report_name(maps)
        if out_dir is None:
            out_dir = run_dir
            check_writable(out_dir, name, video)
        env = DriveEnv(**config.eval_env_kwargs())
        agent = load_agent(run_dir, trained)  # a checkpoint matches the run's config, not the maps'
        check_spaces(agent, env, run_dir)
        check_trained_config(run_dir, trained)  # edits that leave the spaces as they were: traffic, n_envs
        if out_dir is not run_dir:  # created only once the model has loaded
            out_dir = make_out_dir(Path(out_dir))
            check_writable(out_dir, name, video)
        policy = lambda obs: agent.predict(obs, deterministic=deterministic)[0]  # noqa: E731
        with tqdm(
            total=episodes, desc=f"evaluate {config.algo}", unit="episode", disable=not progress
        ) as bar:
            results, frames = run_episodes(
                policy, env, episodes, record_first=video, side_by_side=side_by_side, first=first,
                on_episode=lambda _: bar.update(),
            )  # fmt: skip
        report = {"run": str(run_dir), "algo": config.algo, "env": config.env, **aggregate(results)}
        report["model_steps"] = int(agent.num_timesteps)  # compare: an eval.json of this model only
        report["model_sha256"] = file_sha256(model_path(run_dir, trained))  # the model it evaluated
        if first:
            report["first_episode"] = first
        if maps is not None:
            report["maps"] = config.eval_maps
        made = not (out_dir / "videos").exists()
        if video:
            report["video"] = str(write_video(frames, out_dir / "videos" / "evaluate", video_fps(env)))
        try:
            write_file(out_dir / name, json.dumps({**report, "per_episode": results}, indent=2))
        except UsageError:  # a full disk: the report and its video are written together or not at all
            if video:
                remove_file(Path(report["video"]))
                remove_empty_folders([out_dir / "videos"] if made else [])
            raise
        return report


def make_out_dir(path: Path, what: str = "report folder") -> Path:
    """``path`` as a folder, created if missing; a one-line UsageError naming ``what`` if it cannot
    be (then no folder above it is left)."""
    missing = [folder for folder in (path, *path.parents) if not _exists(folder)]
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        remove_empty_folders(missing)
        raise UsageError(f"cannot create {what} {str(path)!r}: {exc.strerror or exc}") from None
    return path


def _exists(path: Path) -> bool:
    """``path.exists()``, False where the name cannot be looked up (too long: ENAMETOOLONG)."""
    try:
        return path.exists()
    except OSError:
        return False


def check_writable(run_dir: Path, name: str, video: bool = False) -> None:
    """A UsageError unless ``name`` (and with ``video``, ``videos/``) can be written in ``run_dir``,
    probed with a real file: checked before an evaluation, not after its episodes."""
    if (run_dir / name).is_dir():
        raise UsageError(f"cannot write {name} in {str(run_dir)!r}: it is a directory")
    check_replaceable(run_dir / name)
    if video:
        check_folder(run_dir / "videos")
    problem = _cannot_create_in(run_dir)
    if problem is not None:
        raise UsageError(f"cannot write {name} in {str(run_dir)!r}: {problem}")


def check_output_file(path: Path, option: str) -> None:
    """A UsageError unless the file ``path`` (given as ``option``) can be written."""
    folder = path.parent
    if not folder.is_dir():
        raise UsageError(f"cannot write {option} {str(path)!r}: folder {str(folder)!r} does not exist")
    problem = _cannot_create_in(folder)
    if problem is not None:
        raise UsageError(f"cannot write {option} {str(path)!r}: {problem}")


def _cannot_create_in(folder: Path) -> str | None:
    """Why no file can be created in ``folder`` (None: one can), from a real probe file: permission
    bits say nothing on a read-only mount or for root."""
    try:
        with tempfile.TemporaryFile(dir=folder):
            return None
    except OSError as exc:
        return exc.strerror or str(exc)


def _shape(space: spaces.Space) -> str:
    """A one-line description of a space: its shape, or the shape of each part of a Dict."""
    if isinstance(space, spaces.Dict):
        return "{" + ", ".join(f"{key}: {_shape(sub)}" for key, sub in space.spaces.items()) + "}"
    if isinstance(space, spaces.Discrete):
        return f"Discrete({space.n})"
    return f"{type(space).__name__}{space.shape}"


def _saved_spaces(agent) -> tuple[spaces.Space | None, spaces.Space | None]:
    """(observation space, action space) the agent was trained on; a Q-table's are its size."""
    if hasattr(agent, "observation_space"):
        return agent.observation_space, agent.action_space
    table = getattr(agent, "q_table", None)
    if table is None:
        return None, None
    return spaces.Discrete(table.shape[0]), spaces.Discrete(table.shape[1])


def check_spaces(agent, env, run_dir: Path) -> None:
    """A UsageError when ``env`` does not match the saved model's spaces (config.yaml edited)."""
    from stable_baselines3.common.base_class import BaseAlgorithm

    saved_obs, saved_action = _saved_spaces(agent)
    if saved_obs is None:
        return
    observation_space = env.observation_space
    if saved_obs != observation_space and isinstance(agent, BaseAlgorithm):
        observation_space = BaseAlgorithm._wrap_env(env, verbose=0, monitor_wrapper=False).observation_space
    if saved_obs != observation_space:
        raise UsageError(
            f"the model of {str(run_dir)!r} reads observations {_shape(saved_obs)}, but the obs of its "
            f"config.yaml give {_shape(env.observation_space)} (was config.yaml edited after training?)"
        )
    if saved_action != env.action_space:
        raise UsageError(
            f"the model of {str(run_dir)!r} takes actions {_shape(saved_action)}, but the action of its "
            f"config.yaml gives {_shape(env.action_space)} (was config.yaml edited after training?)"
        )


METRIC_LABELS = labels(
    ("mean_return", "success_rate", "crash_rate", "mean_distance_km", "mean_speed_mps", "collisions_per_km",
     "off_road_per_km", "red_lights_per_km", "blocked_per_km", "route_completion")
)  # fmt: skip
METRIC_LABELS["mean_return"] += " (mean ± std)"  # printed as mean ± std (metrics_rows)


# what success means where a scenario has no goal to reach (a slow, safe policy scores 100 %)
NO_GOAL_SUCCESS = "success rate (no goal here: the time limit reached, no crash, no off-road)"


def metrics_rows(report: dict, scenario: str | None = None) -> list[tuple[str, str]]:
    """(label, formatted value) rows for printing; ``scenario``: the report's, whose success rate is
    labelled for what it measures when the scenario has no goal."""
    from drivelab.scenarios import get_scenario

    goal = scenario is None or get_scenario(scenario).arrival != "none"
    rows = []
    for key, label in METRIC_LABELS.items():
        if key == "success_rate" and not goal:
            label = NO_GOAL_SUCCESS
        value = report[key]
        if value is None or (isinstance(value, float) and math.isnan(value)):
            text = "n/a"
        elif key == "mean_return":
            text = f"{value:.3f} ± {report['std_return']:.3f}"
        else:
            text = f"{value:.3f}"
        rows.append((label, text))
    return rows
