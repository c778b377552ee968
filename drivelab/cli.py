"""The ``drivelab`` command: parses arguments and calls library functions, nothing more."""

from __future__ import annotations

import shlex
import sys
from pathlib import Path

import typer
import yaml
from typer.core import TyperGroup

from drivelab.agents.registry import ALGO_NAMES
from drivelab.config import FIELDS, RunConfig
from drivelab.envs.actions import ACTIONS
from drivelab.errors import UsageError
from drivelab.scenarios import SCENARIOS

# click's exception classes, from wherever this typer takes click (newer typers carry their own copy)
CLICK_ERRORS = {cls.__name__: cls for cls in typer.BadParameter.__mro__}


class NeedsCommand(TyperGroup):
    """A command group given no command: one ``error:`` line naming the commands it has (exit 2),
    not the help box with exit 2 that ``no_args_is_help`` prints; ``--help`` shows the help."""

    def parse_args(self, ctx, args: list[str]) -> list[str]:
        if not args and not ctx.resilient_parsing:
            commands = ", ".join(self.list_commands(ctx))
            what = "a command" if ctx.parent is None else "a subcommand"
            raise CLICK_ERRORS["UsageError"](f"{ctx.info_name} needs {what}: {commands}", ctx=ctx)
        return super().parse_args(ctx, args)


class OneLineErrors(NeedsCommand):
    """The command line's own mistakes (an unknown command or option, a value of the wrong type, a
    missing argument) and a command's ``UsageError`` as one ``error:`` line and exit code 2."""

    def main(self, *args, standalone_mode: bool = True, **kwargs):
        if not standalone_mode:
            return super().main(*args, standalone_mode=False, **kwargs)
        try:
            code = super().main(*args, standalone_mode=False, **kwargs)
        except CLICK_ERRORS["ClickException"] as exc:
            message = " ".join(exc.format_message().split()).rstrip(".")
            context = getattr(exc, "ctx", None)
            if isinstance(exc, CLICK_ERRORS["UsageError"]) and context is not None:
                message += f" (see `{context.command_path} --help`)"
            typer.echo(f"error: {message[0].lower()}{message[1:]}", err=True)
            sys.exit(2)
        except UsageError as exc:
            typer.echo(error_line(str(exc)), err=True)
            sys.exit(2)
        except typer.Abort:
            typer.echo("Aborted!", err=True)
            sys.exit(1)
        sys.exit(code if isinstance(code, int) else 0)


app = typer.Typer(
    cls=OneLineErrors,
    add_completion=False,
    help="Train, evaluate and compare RL driving agents.",
)


def _print_version(given: bool) -> None:
    if given:
        from drivelab import __version__

        typer.echo(f"drivelab {__version__}")
        raise typer.Exit()


@app.callback()
def _options(
    version: bool = typer.Option(
        False, "--version", callback=_print_version, is_eager=True, help="Print drivelab's version and exit."
    ),
) -> None:
    """Train, evaluate and compare RL driving agents."""


def error_line(message: str) -> str:
    """``error: message`` as one line: a line break in the message (a folder's name can hold one)
    is written ``\\n`` (``\\r``)."""
    return "error: " + message.replace("\r", "\\r").replace("\n", "\\n")


def _parse_pairs(pairs: list[str], what: str) -> dict:
    from drivelab.yaml_io import parse_yaml

    values = {}
    for pair in pairs:
        key, sep, value = pair.partition("=")
        if not sep or not key:
            raise UsageError(f"{what} {pair!r} must look like key=value")
        if key.strip() in values:
            raise UsageError(f"{what} gives {key.strip()!r} twice")
        try:
            values[key.strip()] = parse_yaml(value)
        except yaml.YAMLError:
            raise UsageError(f"{what} {pair!r} has a value that is not valid YAML") from None
    return values


def _command_line() -> str | None:
    """The command as typed, for reports (None when not called as the ``drivelab`` script)."""
    if Path(sys.argv[0]).name != "drivelab":
        return None
    return shlex.join(["drivelab", *sys.argv[1:]])


@app.command()
def envs() -> None:
    """List scenarios, sensors, action kinds, reward presets and algorithms, one per line."""
    from drivelab.agents.registry import ALGORITHMS
    from drivelab.envs.actions import make_action
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
    for name, spec in ALGORITHMS.items():
        typer.echo(f"algo      {name:<18} {spec.description} (actions: {', '.join(spec.action_kinds)})")


# train's options that are run fields
RUN_OPTIONS = ("algo", "env", "obs", "action", "reward", "steps", "seed", "traffic", "backend", "name",
               "eval_every", "eval_episodes", "checkpoint_every", "n_envs", "eval_maps",
               "init_from")  # fmt: skip


def _rlad_switches(given: dict) -> dict:
    """RLAD's ablation flags among train's ``given`` options as the hyper-parameters they stand for
    (other algorithms reject them as unknown hyper-parameters)."""
    chosen = {key: False for key in ("alix", "aux", "augment") if given[f"no_{key}"]}
    if given["waypoint_encoder"] is not None:
        chosen["waypoint_encoder"] = given["waypoint_encoder"]
    return chosen


def _with_hyperparams(values: dict, hyperparams: list[str], switches: dict | None = None) -> dict:
    """The ``--config`` file's ``hyperparams`` (none or empty: {}) updated with the ``-H`` pairs
    and the switches; a one-line error when the file's field is not a mapping."""
    given = values.get("hyperparams") or {}
    if not isinstance(given, dict):
        raise UsageError(f"config field 'hyperparams' must be a mapping, got {type(given).__name__}")
    return {**given, **_parse_pairs(hyperparams, "--hyperparams"), **(switches or {})}


def _new_run_config(given: dict):
    """The config of a new run from train's ``given`` options: the ``--config`` file's fields, the
    options given over them, and drivelab's shipped hyper-parameters under the ``-H`` ones."""
    from drivelab.config import build_config
    from drivelab.hyperparams import with_shipped_hyperparams
    from drivelab.yaml_io import load_yaml

    values = load_yaml(given["config"]) if given["config"] is not None else {}
    values.update({key: given[key] for key in RUN_OPTIONS if given[key] is not None})
    if given["video"]:
        values["eval_video"] = True
    switches = _rlad_switches(given)
    if given["hyperparams"] or switches:
        values["hyperparams"] = _with_hyperparams(values, given["hyperparams"], switches)
    return build_config(with_shipped_hyperparams(values))


def train_config(arguments: list[str]):
    """The config ``drivelab train ARGUMENTS`` would train, without training: for a script that
    reuses a run only when it is the run those arguments make (paths as from the current folder).
    A ``--resume`` command has no config of its own: refused."""
    command = typer.main.get_command(app).get_command(None, "train")  # type: ignore[attr-defined]
    with command.make_context("train", list(arguments)) as context:
        given = context.params
    if given["resume"] is not None:
        raise UsageError("train_config: --resume trains the run's own config")
    return _new_run_config(given)


def run_default(field: str) -> str:
    """What ``--help`` shows as the default of a run field's option (None there: the ``--config``
    file's value, else this): RunConfig's default; the scenario's own for action and reward."""
    if field in ("action", "reward"):
        highway = SCENARIOS[RunConfig.env]
        value = highway.action_kinds[0] if field == "action" else highway.default_reward
        return f"the scenario's own; {RunConfig.env}: {value}"
    if field == "name":
        return "ALGO-ENV-sSEED-DATE-TIME"
    if field == "eval_maps":
        return "the training maps"
    if field == "init_from":
        return "random weights"
    value = FIELDS[field].default
    return ",".join(value) if isinstance(value, tuple) else str(value)


def _run_option(field: str, help: str | None = None):
    """An option of run field ``field``: None unless given (then the ``--config`` file's value, else
    the default), its help ending in the default, as the other options' with a default in words."""
    shown = f"(default: {run_default(field)})"
    return typer.Option(None, help=f"{help} {shown}" if help else shown, show_default=False)


@app.command()
def train(
    context: typer.Context,
    algo: str | None = typer.Option(None, help=", ".join(ALGO_NAMES) + " (required here or in --config)"),
    env: str | None = _run_option("env", "scenario: " + ", ".join(SCENARIOS)),
    obs: str | None = _run_option("obs", "sensor or comma list, e.g. lidar,topdown or lidar:beams=120"),
    action: str | None = _run_option("action", ", ".join(ACTIONS)),
    reward: str | None = _run_option("reward", "preset, term=weight list, or preset,term=weight"),
    steps: int | None = _run_option("steps", "total environment steps"),
    seed: int | None = _run_option("seed"),
    traffic: str | None = _run_option("traffic", "empty, regular or dense"),
    backend: str | None = _run_option(
        "backend", "auto (fast where it runs the scenario), fast (compiled port) or highway"
    ),
    config: Path | None = typer.Option(None, help="YAML file of run fields (CLI options win over it)"),
    name: str | None = _run_option("name", "run directory name"),
    runs_dir: Path = typer.Option(Path("runs"), help="where run directories are created"),
    eval_every: int | None = _run_option(
        "eval_every", "steps between evaluations, at most --steps (0: 5 per run)"
    ),
    eval_episodes: int | None = _run_option("eval_episodes", "episodes per periodic evaluation"),
    video: bool = typer.Option(False, "--video", help="record a video at each periodic evaluation"),
    checkpoint_every: int | None = _run_option(
        "checkpoint_every", "steps between checkpoints (0: 10 per run)"
    ),
    n_envs: int | None = _run_option("n_envs", "worlds stepped together (SB3 and own agents)"),
    eval_maps: str | None = _run_option("eval_maps", "blocks: evaluate on maps START:COUNT (unseen maps)"),
    init_from: str | None = _run_option(
        "init_from", "ppo_own, a2c_own: start from this run's or shipped agent's policy (e.g. a dagger run)"
    ),
    hyperparams: list[str] = typer.Option(
        [],
        "--hyperparams",
        "-H",
        help="algorithm override key=value (default: drivelab/hyperparams/ALGO.yaml's)",
    ),
    resume: Path | None = typer.Option(
        None, help="continue this run directory from its checkpoint (none yet: train it again from 0)"
    ),
    no_alix: bool = typer.Option(False, "--no-alix", help="rlad/drq: no A-LIX (-H alix=false)"),
    no_aux: bool = typer.Option(False, "--no-aux", help="rlad/drq: no traffic-light loss (-H aux=false)"),
    no_augment: bool = typer.Option(False, "--no-augment", help="rlad/drq: no DrQ shifts (-H augment=false)"),
    waypoint_encoder: str | None = typer.Option(
        None, help="rlad/drq: wayconv1d or mlp (-H waypoint_encoder=...)"
    ),
) -> None:
    """Train an agent and write a run directory."""
    from drivelab.config import check_eval_every
    from drivelab.training.run import TrainingInterrupted
    from drivelab.training.run import resume as resume_run
    from drivelab.training.run import train as train_run

    given = context.params
    try:
        if resume is not None:
            others = [given[key] is not None for key in (*RUN_OPTIONS, "config") if key != "steps"]
            if any(others) or hyperparams or _rlad_switches(given) or video:
                raise UsageError("--resume takes the run's own config; only --steps may be given with it")
            run_dir = resume_run(resume, steps)
        else:
            new_config = _new_run_config(given)
            check_eval_every(new_config)
            run_dir = train_run(new_config, runs_dir)
    except TrainingInterrupted as stop:
        typer.echo(
            f"\ninterrupted at step {stop.steps}: checkpoint saved; "
            f"continue with `drivelab train --resume {stop.run_dir}`",
            err=True,
        )
        raise typer.Exit(130) from None
    _print_last_evaluation(run_dir)
    typer.echo(f"run directory: {run_dir}")


def _print_last_evaluation(run_dir: Path) -> None:
    """The metrics of a run's last periodic evaluation, as ``evaluate`` prints its own."""
    from drivelab.training.compare import last_evaluation
    from drivelab.training.evaluate import load_run_config

    report = last_evaluation(run_dir)
    if report is not None:
        config = load_run_config(run_dir)
        title = f"{config.algo} on {config.env} at step {report['step']}: {report['episodes']} episodes"
        _print_metrics(title, report, config.env)


RUN_OR_AGENT = "a run directory written by drivelab train, or a shipped agent's name (drivelab zoo)"
SIDE_BY_SIDE_HELP = (
    "the video shows the agent's image observation beside the scene (default: when it has one)"
)
OUT_HELP = "folder for the reports (default: the run directory; for a shipped agent runs/zoo-NAME)"


@app.command()
def evaluate(
    run_dir: str = typer.Argument(..., metavar="RUN_DIR|NAME", help=RUN_OR_AGENT),
    episodes: int = typer.Option(10, help="evaluation episodes"),
    video: bool = typer.Option(False, "--video", help="write an mp4 (or gif) of the first episode"),
    side_by_side: bool | None = typer.Option(None, "--side-by-side/--scene-only", help=SIDE_BY_SIDE_HELP),
    stochastic: bool = typer.Option(
        False, "--stochastic", help="sample actions instead of the greedy policy"
    ),
    out: Path | None = typer.Option(None, help=OUT_HELP),
    maps: str | None = typer.Option(
        None, help="blocks: play maps START:COUNT instead (writes eval-maps-START-COUNT.json)"
    ),
) -> None:
    """Evaluate a run's model: print the driving metrics and write eval.json."""
    from drivelab.training.evaluate import evaluate_run, report_name
    from drivelab.training.zoo import report_dir, resolve

    _one_torch_thread()

    path, name = resolve(run_dir)
    out_dir = report_dir(run_dir, out)
    report = evaluate_run(
        path, episodes=episodes, video=video, deterministic=not stochastic, out_dir=out_dir, maps=maps,
        side_by_side=side_by_side, progress=True,
    )  # fmt: skip
    _print_metrics(f"{name or report['algo']} on {report['env']}: {report['episodes']} episodes", report)
    if "video" in report:
        typer.echo(f"video: {report['video']}")
    written = report_name(maps)
    typer.echo(
        f"run directory: {path}  ({written} written)"
        if out_dir is None
        else f"{written} written in {out_dir}"
    )


def _print_metrics(title: str, report: dict, scenario: str | None = None) -> None:
    """An evaluation report's driving metrics as a table (``scenario``: the report's)."""
    from rich.console import Console
    from rich.table import Table

    from drivelab.training.evaluate import metrics_rows

    table = Table(title=title)
    table.add_column("metric")
    table.add_column("value", justify="right")
    for label, value in metrics_rows(report, scenario or report.get("env")):
        table.add_row(label, value)
    Console().print(table)


@app.command()
def zoo() -> None:
    """List the shipped agents: name, scenario, algorithm, observation, measured metrics."""
    from drivelab.training.zoo import headline, shipped_agents

    agents = shipped_agents()
    if not agents:
        typer.echo("no shipped agents (benchmarks/zoo_build.py packs them)")
    width = max((len(agent.name) for agent in agents), default=0)
    for agent in agents:
        card = agent.card
        typer.echo(f"{agent.name:<{width}}  {card['env']:<10} {card['algo']:<8} obs {','.join(card['obs'])}")
        typer.echo(f"{'':<{width}}  {headline(card)}")


def _one_torch_thread() -> None:
    """Evaluating and enjoying act on one observation at a time, where torch's threads only add
    hand-offs."""
    import torch

    torch.set_num_threads(1)


@app.command()
def enjoy(
    agent: str = typer.Argument(..., metavar="NAME|RUN_DIR", help=RUN_OR_AGENT),
    episodes: int = typer.Option(3, help="episodes to drive"),
    video: Path | None = typer.Option(None, help="write the episodes to this .mp4 (or .gif)"),
    side_by_side: bool | None = typer.Option(None, "--side-by-side/--scene-only", help=SIDE_BY_SIDE_HELP),
    seed: int | None = typer.Option(
        None, help="episode e is that of the env seeded SEED + e (default: the fixed evaluation episodes)"
    ),
) -> None:
    """Drive an agent greedily on its scenario, print each episode and the metrics; nothing else is
    written."""
    from drivelab.training.zoo import enjoy as drive

    _one_torch_thread()

    def progress(index: int, metrics: dict) -> None:
        outcome = "success" if metrics["success"] else "crash" if metrics["crashed"] else "no success"
        typer.echo(
            f"episode {index + 1}/{episodes}: {outcome}, return {metrics['return']:.2f}, "
            f"{metrics['length']} steps, {metrics['mean_speed_mps']:.1f} m/s, "
            f"{1000 * metrics['distance_km']:.0f} m"
        )

    report = drive(
        agent, episodes=episodes, video=video, seed=seed, on_episode=progress, side_by_side=side_by_side
    )
    episodes_text = "fixed evaluation episodes" if seed is None else f"episodes of seeds {seed}+e"
    _print_metrics(
        f"{report['agent']} ({report['algo']}) on {report['env']}: {episodes} {episodes_text}", report
    )
    if "video" in report:
        typer.echo(f"video: {report['video']} ({report['video_frames']} frames)")


@app.command()
def compare(
    run_dirs: list[Path] = typer.Argument(None, help="run directories written by drivelab train"),
    runs: list[str] = typer.Option([], "--runs", help="glob of run directories, e.g. 'runs/*' (repeatable)"),
    out: Path = typer.Option(Path("reports/comparison"), "--out", "-o", help="report directory to write"),
    title: str = typer.Option("drivelab comparison", help="heading of report.md"),
    confidence: float = typer.Option(0.9, help="coverage of the bootstrap intervals"),
) -> None:
    """Group runs over seeds; write tables (Markdown, CSV), learning curves and bar charts."""
    from drivelab.training.compare import compare as compare_runs

    report = compare_runs(
        [*(run_dirs or []), *runs], out, title=title, command=_command_line(), confidence=confidence
    )
    typer.echo(f"report: {report / 'report.md'}")


def _print_outcome_table(title: str, outcomes: list[dict], what: str) -> None:
    """A table of sweep or tuning outcomes (``sweep.run_cell``'s), one row per ``what``."""
    from rich.console import Console
    from rich.table import Table

    table = Table(title=title)
    for column in (what, "did", "result", "seconds"):
        table.add_column(column, justify="right" if column == "seconds" else "left")
    for o in outcomes:
        result = f"FAILED: {o['error']}" if not o["ok"] else "ok"
        result = f"pruned at step {o['stopped']}" if o["ok"] and o.get("stopped") is not None else result
        table.add_row(o["name"], o["action"], result, f"{o['seconds']:.1f}")
    Console().print(table)


def _exit_if_failed(outcomes: list[dict], what: str, folder: Path, then: str) -> None:
    """One error line and exit code 1 when a run (``what``: "run" or "trial") of ``outcomes`` failed."""
    failed = sum(not o["ok"] for o in outcomes)
    if failed:
        message = f"{failed} {what}(s) failed; see {folder / '.sweep-logs'}/<{what}>.log{then}"
        typer.echo(error_line(message), err=True)
        raise typer.Exit(1)


def _print_outcomes(outcomes: list[dict], runs_dir: Path) -> None:
    _print_outcome_table(f"runs in {runs_dir}", outcomes, "run")
    _exit_if_failed(outcomes, "run", runs_dir, ", then re-run the same command to finish them")


def _interrupted() -> None:
    typer.echo("\ninterrupted: checkpoints saved; run the same command again to resume", err=True)
    raise typer.Exit(130)


EXECUTOR_HELP = "pool (local processes, default) or ray (Ray tasks); not the simulation --backend"


@app.command()
def sweep(
    sweep_file: Path = typer.Argument(..., help="sweep YAML: base, grid, overrides (see docs/compare.md)"),
    runs_dir: Path | None = typer.Option(
        None, help="where run directories go (default: the file's runs_dir)"
    ),
    executor: str = typer.Option("pool", help=EXECUTOR_HELP),
    workers: int | None = typer.Option(None, help="parallel runs (default: one per core)"),
    address: str | None = typer.Option(None, help="existing Ray cluster address (with --executor ray)"),
    report: Path | None = typer.Option(None, help="also write a comparison report of the sweep's runs here"),
    dry_run: bool = typer.Option(False, "--dry-run", help="print what each run needs and stop"),
) -> None:
    """Run a grid of runs; a re-run skips finished runs and resumes interrupted ones."""
    from drivelab.training.compare import load_run, write_report
    from drivelab.training.sweep import load_sweep, preview, run_dirs, run_sweep

    try:
        spec = load_sweep(sweep_file, runs_dir)
        if dry_run:
            for cell, action in preview(spec):
                typer.echo(f"{action:<8} {spec.runs_dir / cell.config.name}")
            return
        outcomes = run_sweep(spec, executor=executor, workers=workers, address=address)
    except KeyboardInterrupt:
        _interrupted()
    _print_outcomes(outcomes, spec.runs_dir)
    if report is not None:
        records = [load_run(d) for d in run_dirs(spec)]
        written = write_report(records, report, title=f"sweep {sweep_file.name}", command=_command_line())
        typer.echo(f"report: {written / 'report.md'}")


@app.command()
def tune(
    study_file: Path = typer.Argument(..., help="study YAML: run fields, space, n_trials, metric"),
    study_dir: Path | None = typer.Option(
        None, help="where the study and its trial runs go (default: the file's study_dir)"
    ),
    n_trials: int | None = typer.Option(None, help="trials of the study in all (default: the file's)"),
    executor: str = typer.Option("pool", help=EXECUTOR_HELP),
    workers: int | None = typer.Option(None, help="trials at once (default: one per core)"),
    address: str | None = typer.Option(None, help="existing Ray cluster address (with --executor ray)"),
    write_best: Path | None = typer.Option(
        None, help="also set the env's entry of this RL Zoo hyper-parameter file to the best values"
    ),
) -> None:
    """Tune hyper-parameters with Optuna (TPE, median pruning); a re-run continues the study."""
    from drivelab.training.tune import check_zoo_file, load_study, run_study
    from drivelab.training.tune import write_best as write_best_file

    try:
        study = load_study(study_file, study_dir, n_trials)
        if write_best is not None:
            check_zoo_file(write_best)
        summary = run_study(study, executor, workers, address, command=_command_line())
        written = write_best_file(study, summary, write_best) if write_best is not None else None
    except KeyboardInterrupt:
        _interrupted()
    _print_outcome_table(
        f"study {study.name}: {study.metric} ({study.direction})", summary["outcomes"], "trial"
    )
    best = summary["best"]
    if best is not None:
        typer.echo(f"best: {best['run_dir']} {study.metric} {best['value']:.4g} {best['params']}")
    typer.echo(f"study directory: {study.study_dir}  (summary.md, trials.csv, best-hyperparams.yml)")
    if written is not None:
        typer.echo(f"wrote {written}")
    _exit_if_failed(summary["outcomes"], "trial", study.study_dir, "; re-running the command replaces them")


def _split_rewards(values: list[str]) -> list[str]:
    """``--rewards`` values → reward specs. ``;`` separates specs; with commas, a piece without
    ``=`` starts a new spec and ``term=weight`` pieces join the spec before them."""
    specs: list[str] = []
    for value in values:
        for chunk in value.split(";"):
            current: list[str] = []
            for piece in (p.strip() for p in chunk.split(",") if p.strip()):
                if "=" not in piece and current:
                    specs.append(",".join(current))
                    current = []
                current.append(piece)
            if current:
                specs.append(",".join(current))
    return specs


@app.command()
def ablate(
    env: str = typer.Option("highway", help="scenario"),
    algo: str = typer.Option(..., help="algorithm"),
    rewards: list[str] = typer.Option(
        [],
        help="rewards to compare: presets p1,p2 (a term=w piece joins the preset before it; ';' separates)",
    ),
    drop_terms: str | None = typer.Option(None, help="terms of --reward to drop one at a time: t1,t2"),
    reward: str = typer.Option("highway", help="the reward that --drop-terms ablates"),
    seeds: int = typer.Option(3, help="seeds per reward (0..N-1)"),
    steps: int = typer.Option(10_000, help="training steps per run"),
    obs: str | None = _run_option("obs", "sensors"),
    action: str | None = _run_option("action", ", ".join(ACTIONS)),
    traffic: str | None = _run_option("traffic", "empty, regular or dense"),
    backend: str | None = _run_option("backend", "simulation backend: auto, fast or highway"),
    config: Path | None = typer.Option(None, help="YAML of further run fields shared by every run"),
    hyperparams: list[str] = typer.Option([], "--hyperparams", "-H", help="algorithm override key=value"),
    eval_episodes: int = typer.Option(10, help="final evaluation episodes per run"),
    runs_dir: Path = typer.Option(Path("runs"), help="where run directories go"),
    out: Path | None = typer.Option(
        None, "--out", "-o", help="report directory (default reports/ablate-ALGO-ENV)"
    ),
    executor: str = typer.Option("pool", help=EXECUTOR_HELP),
    workers: int | None = typer.Option(None, help="parallel runs (default: one per core)"),
    address: str | None = typer.Option(None, help="existing Ray cluster address (with --executor ray)"),
) -> None:
    """Train one agent under several rewards (or a reward minus one term at a time) and compare."""
    from drivelab.training.ablate import ablate as run_ablation
    from drivelab.yaml_io import load_yaml

    try:
        base = load_yaml(config) if config is not None else {}
        given = {"obs": obs, "action": action, "traffic": traffic, "backend": backend}
        base.update({k: v for k, v in given.items() if v is not None})
        if hyperparams:
            base["hyperparams"] = _with_hyperparams(base, hyperparams)
        for key in ("algo", "env", "steps", "seed", "reward", "name"):
            if key in base:
                raise UsageError(f"--config may not set {key!r} for an ablation (use the options)")
        drops = [t.strip() for t in drop_terms.split(",") if t.strip()] if drop_terms else None
        report, outcomes = run_ablation(
            env, algo, rewards=_split_rewards(rewards) or None, drop_terms=drops, base_reward=reward,
            seeds=seeds, steps=steps, base=base, runs_dir=runs_dir, out_dir=out,
            eval_episodes=eval_episodes, executor=executor, workers=workers, address=address,
            command=_command_line(),
        )  # fmt: skip
    except KeyboardInterrupt:
        _interrupted()
    _print_outcomes(outcomes, runs_dir)
    typer.echo(f"report: {report / 'report.md'}")


@app.command("convert-run")
def convert_run(
    run_dir: Path = typer.Argument(..., help="a run directory of the old pickle format that you trust"),
) -> None:
    """Rewrite a run saved by an earlier drivelab (pickles inside) in the safe format.

    Loading the old files executes whatever they hold: convert only runs you trust."""
    from drivelab.training.convert import convert_run as convert

    written = convert(run_dir)
    for path in written:
        typer.echo(f"rewrote {path}")
    typer.echo(f"run directory: {run_dir}  ({'converted' if written else 'already in the safe format'})")


@app.command()
def export(
    run_dir: str = typer.Argument(..., metavar="RUN_DIR|NAME", help=RUN_OR_AGENT + " (dqn, ppo, a2c, sac)"),
    out: Path = typer.Argument(..., help="the .zip to write (not inside the run directory)"),
) -> None:
    """Write a run's SB3 model in stable-baselines3's own format, for PPO.load (DQN, A2C, SAC.load).

    For your own trusted use: SB3's format holds pickles, which SB3's load executes. drivelab
    itself never reads the exported file; its runs keep their pickle-free format."""
    from drivelab.training.export import export_sb3

    written, sb3_class = export_sb3(run_dir, out)
    typer.echo(f"wrote {written}: stable_baselines3.{sb3_class}.load({str(written)!r}) reads it")


benchmark_app = typer.Typer(cls=NeedsCommand, help="Driving benchmarks of trained runs.")
app.add_typer(benchmark_app, name="benchmark")


@benchmark_app.command("nocrash")
def benchmark_nocrash(
    run_dir: str = typer.Argument(
        ..., metavar="RUN_DIR|NAME", help="a run directory trained in the town, or a shipped town agent"
    ),
    town: str = typer.Option("test", help="layout to drive in: test (unseen) or train"),
    episodes: int = typer.Option(25, help="episodes per traffic level"),
    level: str = typer.Option("regular", help="traffic level of the infraction table"),
    out: Path | None = typer.Option(None, help=OUT_HELP),
) -> None:
    """NoCrash-style success per traffic level and infractions per km (writes nocrash.json/.md)."""
    from drivelab.training.nocrash import nocrash, report_markdown
    from drivelab.training.zoo import report_dir, resolve

    path, _ = resolve(run_dir)
    out_dir = report_dir(run_dir, out)
    report = nocrash(path, town=town, episodes=episodes, infraction_level=level, out_dir=out_dir)
    typer.echo(report_markdown(report))


perception_app = typer.Typer(cls=NeedsCommand, help="Perception models: train the lane CNN.")
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

    from drivelab.perception.lane_cnn import WEIGHTS_PATH
    from drivelab.training.lane_dataset import train_lane_detector

    torch.set_num_threads(min(2, torch.get_num_threads()))
    summary = train_lane_detector(
        frames=frames, epochs=epochs, seed=seed, out=out or WEIGHTS_PATH, log=typer.echo
    )
    size_kib, seconds = summary["bytes"] / 1024, summary["seconds"]
    typer.echo(f"weights: {summary['weights']} ({size_kib:.0f} KiB, trained in {seconds:.0f} s)")


# a gallery's map is 256 pixels a side (3.2 inches at 80 dpi, maps_gallery.draw_gallery) and
# matplotlib's Agg draws images of at most 2**16 pixels a side
GALLERY_MAX_SIDE_MAPS = 2**16 // 256


def _map_seeds(text: str) -> tuple[int, int]:
    """``start:count`` as (start, count), checked."""
    start, sep, count = text.partition(":")
    if not sep or not start.strip().isdigit() or not count.strip().isdigit() or int(count) < 1:
        raise UsageError(f"--seeds {text!r} must look like start:count, e.g. 0:8")
    return int(start), int(count)


@app.command()
def maps(
    map_spec: str = typer.Option(
        "3", "--map", help="a block string such as OSX, or a number of random blocks"
    ),
    seeds: str = typer.Option(
        "0:8", help="map seeds start:count (the blocks scenario's start_seed, num_scenarios)"
    ),
    lane_count: int = typer.Option(3, help="lanes per direction (0: 2 or 3 per map)"),
    columns: int = typer.Option(4, help="maps per row"),
    out: Path = typer.Option(Path("maps.png"), "--out", "-o", help="PNG to write"),
) -> None:
    """Draw a gallery of procedural maps (the blocks scenario's) to a PNG."""
    from drivelab.scenarios.blocks.gallery import draw_gallery
    from drivelab.scenarios.blocks.spawn import MapSet

    if out.suffix.lower() != ".png" or out.is_dir():
        raise UsageError(f"--out {str(out)!r} must name a .png file")
    start, count = _map_seeds(seeds)
    spec = int(map_spec) if map_spec.strip().isdigit() else map_spec
    config = {"map": spec, "start_seed": start, "num_scenarios": count}
    map_set = MapSet.from_config({**config, "lane_count": lane_count or None})
    if columns < 1:
        raise UsageError("--columns must be >= 1")
    rows = -(-count // columns)
    if max(rows, columns) > GALLERY_MAX_SIDE_MAPS:
        raise UsageError(
            f"--seeds {seeds!r} with --columns {columns} draws a gallery of {rows} x {columns} maps: at "
            f"most {GALLERY_MAX_SIDE_MAPS} a side fit in one PNG (matplotlib's 65,536 pixels)"
        )
    path = draw_gallery([map_set.generate(seed) for seed in range(start, start + count)], out, columns)
    typer.echo(f"gallery: {path}")


def main() -> None:
    """Entry point of the ``drivelab`` console script."""
    app()


if __name__ == "__main__":
    main()
