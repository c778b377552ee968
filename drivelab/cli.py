"""The ``drivelab`` command: parses arguments and calls library functions, nothing more."""

from __future__ import annotations

import sys
from pathlib import Path

import typer
import yaml

from drivelab.errors import UsageError

app = typer.Typer(
    add_completion=False, no_args_is_help=True, help="Train, evaluate and compare RL driving agents."
)


def _fail(message: str) -> None:
    typer.echo(f"error: {message}", err=True)
    raise typer.Exit(2)


def _parse_pairs(pairs: list[str], what: str) -> dict:
    values = {}
    for pair in pairs:
        key, sep, value = pair.partition("=")
        if not sep or not key:
            raise UsageError(f"{what} {pair!r} must look like key=value")
        try:
            values[key.strip()] = yaml.safe_load(value)
        except yaml.YAMLError:
            raise UsageError(f"{what} {pair!r} has a value that is not valid YAML") from None
    return values


@app.command()
def envs() -> None:
    """List scenarios, sensors, action kinds, reward presets and algorithms, one per line."""
    from drivelab.agents.registry import ALGO_NAMES, get_algo
    from drivelab.envs.actions import ACTIONS, make_action
    from drivelab.envs.scenarios import SCENARIOS
    from drivelab.perception.sensors import SENSOR_HELP
    from drivelab.rewards.shapers import PRESETS

    for name, scenario in SCENARIOS.items():
        typer.echo(f"scenario  {name:<18} {scenario.description}")
    for name, text in SENSOR_HELP.items():
        typer.echo(f"sensor    {name:<18} {text}")
    for name in ACTIONS:
        typer.echo(f"action    {name:<18} {make_action(name).describe()}")
    for name, preset in PRESETS.items():
        typer.echo(f"reward    {name:<18} {preset.description}")
    for name in ALGO_NAMES:
        spec = get_algo(name)
        typer.echo(f"algo      {name:<18} {spec.description} (actions: {', '.join(spec.action_kinds)})")


@app.command()
def train(
    algo: str | None = typer.Option(None, help="dqn, ppo, a2c or sac"),
    env: str | None = typer.Option(
        None, help="scenario: highway, merge, roundabout, intersection, racetrack"
    ),
    obs: str | None = typer.Option(None, help="sensor or comma list, e.g. lidar,topdown or lidar:beams=120"),
    action: str | None = typer.Option(None, help="meta, grid or continuous"),
    reward: str | None = typer.Option(None, help="preset, term=weight list, or preset,term=weight"),
    steps: int | None = typer.Option(None, help="total environment steps"),
    seed: int | None = typer.Option(None),
    traffic: str | None = typer.Option(None, help="empty, regular or dense"),
    backend: str | None = typer.Option(
        None, help="highway (highway-env) or fast (compiled; highway scenario)"
    ),
    config: Path | None = typer.Option(None, help="YAML file of run fields (CLI options win)"),
    name: str | None = typer.Option(None, help="run directory name"),
    runs_dir: Path = typer.Option(Path("runs"), help="where run directories are created"),
    eval_every: int | None = typer.Option(None, help="steps between evaluations (0: 5 per run)"),
    eval_episodes: int | None = typer.Option(None),
    video: bool = typer.Option(False, "--video", help="record a video at each periodic evaluation"),
    checkpoint_every: int | None = typer.Option(None, help="steps between checkpoints (0: 10 per run)"),
    hyperparams: list[str] = typer.Option([], "--hyperparams", "-H", help="algorithm override key=value"),
    resume: Path | None = typer.Option(None, help="continue this run directory from its checkpoint"),
) -> None:
    """Train an agent and write a run directory."""
    from drivelab.config import build_config, load_yaml
    from drivelab.training.run import TrainingInterrupted
    from drivelab.training.run import resume as resume_run
    from drivelab.training.run import train as train_run

    try:
        if resume is not None:
            given = [
                o
                for o in (algo, env, obs, action, reward, seed, traffic, backend, config, name)
                if o is not None
            ]
            if given or hyperparams:
                raise UsageError("--resume takes the run's own config; only --steps may be given with it")
            run_dir = resume_run(resume, steps)
        else:
            values = load_yaml(config) if config is not None else {}
            cli = {
                "algo": algo, "env": env, "obs": obs, "action": action, "reward": reward,
                "steps": steps, "seed": seed, "traffic": traffic, "backend": backend, "name": name,
                "eval_every": eval_every, "eval_episodes": eval_episodes,
                "checkpoint_every": checkpoint_every,
            }  # fmt: skip
            values.update({k: v for k, v in cli.items() if v is not None})
            if video:
                values["eval_video"] = True
            if hyperparams:
                values["hyperparams"] = {
                    **values.get("hyperparams", {}),
                    **_parse_pairs(hyperparams, "--hyperparams"),
                }
            run_dir = train_run(build_config(values), runs_dir)
    except UsageError as exc:
        _fail(str(exc))
    except TrainingInterrupted as stop:
        typer.echo(
            f"\ninterrupted at step {stop.steps}: checkpoint saved; "
            f"continue with `drivelab train --resume {stop.run_dir}`",
            err=True,
        )
        raise typer.Exit(130) from None
    typer.echo(f"run directory: {run_dir}")


@app.command()
def evaluate(
    run_dir: Path = typer.Argument(..., help="a run directory written by drivelab train"),
    episodes: int = typer.Option(10, help="evaluation episodes"),
    video: bool = typer.Option(False, "--video", help="write an mp4 (or gif) of the first episode"),
    stochastic: bool = typer.Option(
        False, "--stochastic", help="sample actions instead of the greedy policy"
    ),
) -> None:
    """Evaluate a run's model: print the driving metrics and write eval.json."""
    from rich.console import Console
    from rich.table import Table

    from drivelab.training.evaluate import evaluate_run, metrics_rows

    try:
        report = evaluate_run(run_dir, episodes=episodes, video=video, deterministic=not stochastic)
    except UsageError as exc:
        _fail(str(exc))
    table = Table(title=f"{report['algo']} on {report['env']}: {report['episodes']} episodes")
    table.add_column("metric")
    table.add_column("value", justify="right")
    for label, value in metrics_rows(report):
        table.add_row(label, value)
    Console().print(table)
    if "video" in report:
        typer.echo(f"video: {report['video']}")
    typer.echo(f"run directory: {run_dir}  (eval.json written)")


perception_app = typer.Typer(no_args_is_help=True, help="Perception models: train the lane CNN.")
app.add_typer(perception_app, name="perception")


@perception_app.command("train-lane")
def train_lane(
    frames: int = typer.Option(1500, help="generated training frames (follow-lane circuit, random poses)"),
    epochs: int = typer.Option(15),
    seed: int = typer.Option(0),
    out: Path | None = typer.Option(None, help="weights file (default: the package's shipped weights)"),
) -> None:
    """Train the seed-004 lane segmentation CNN on frames and masks drivelab renders itself."""
    import torch

    from drivelab.perception.lane_cnn import WEIGHTS_PATH, train_lane_cnn

    if frames < 1 or epochs < 1:
        _fail("--frames and --epochs must be >= 1")
    torch.set_num_threads(min(2, torch.get_num_threads()))
    summary = train_lane_cnn(frames=frames, epochs=epochs, seed=seed, out=out or WEIGHTS_PATH, log=typer.echo)
    size_kib, seconds = summary["bytes"] / 1024, summary["seconds"]
    typer.echo(f"weights: {summary['weights']} ({size_kib:.0f} KiB, trained in {seconds:.0f} s)")


def main() -> None:
    """Entry point of the ``drivelab`` console script."""
    try:
        app()
    except UsageError as exc:  # raised outside a command's own handler
        typer.echo(f"error: {exc}", err=True)
        sys.exit(2)


if __name__ == "__main__":
    main()
