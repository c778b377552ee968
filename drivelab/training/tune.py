"""Tuning: an Optuna study over run directories (TPE sampler, median pruner on the periodic
evaluations), its trials run on the local process pool or as Ray tasks like a sweep's cells.

A study file is a run config (any ``RunConfig`` field but ``name``; ``steps`` is each trial's
budget) plus the study's own keys::

    name: ppo-highway            # study name (default <algo>-<env>); folder runs/tune/<name>
    study_dir: runs/tune/ppo     # optional; --study-dir wins
    algo: ppo
    env: highway
    steps: 20000                 # budget per trial
    eval_every: 4000             # periodic evaluations: reported to the pruner
    eval_episodes: 5
    final_eval_episodes: 20      # the objective: the metric over these episodes (eval.json)
    n_trials: 30                 # trials of the study in all (a re-run adds only the missing ones)
    metric: mean_return          # or success_rate, crash_rate, mean_speed_mps, ...
    direction: maximize          # default: minimize for crash_rate, else maximize
    sampler: {seed: 0, n_startup_trials: 5}       # TPE
    pruner: {n_startup_trials: 3, n_warmup_steps: 4000}   # median
    hyperparams: {n_epochs: 5}   # fixed values over the shipped file's
    space:                       # the hyper-parameters searched
      learning_rate: {type: float, low: 1.0e-5, high: 1.0e-3, log: true}
      gamma: {type: float, low: 0.8, high: 0.99}
      n_steps: {type: int, low: 64, high: 1024, log: true}
      batch_size: {type: categorical, choices: [32, 64, 128]}

Every trial is a run directory ``<study_dir>/trial-NNNN``, trained with the study's seed and
evaluated on the scenario's validation episodes (``VALIDATION_START`` on), never on the test
episodes of the reports. The study lives in ``<study_dir>/study.journal``: a killed study, run
again, resumes its running trials, then asks for the missing ones; with a sampler seed, trial n
draws with seed + n. At the end it writes ``summary.md``, ``summary.json``, ``trials.csv`` and
``best-hyperparams.yml`` (RL Zoo's format)."""

from __future__ import annotations

import contextlib
import fcntl
import itertools
import json
import math
import shlex
from dataclasses import dataclass, field
from decimal import Decimal
from pathlib import Path

import yaml
from tqdm import tqdm

from drivelab.config import FIELDS, RunConfig, build_config, check_eval_every, check_steps
from drivelab.errors import UsageError
from drivelab.hyperparams import with_shipped_hyperparams, zoo_yaml
from drivelab.training.metrics import METRICS as REGISTRY
from drivelab.training.seeds import VALIDATION_START
from drivelab.training.sweep import cell_action, check_workers, execute, executor_ready, run_cell, skipped
from drivelab.yaml_io import load_yaml, parse_yaml_1_1, read_text_bounded

STUDY_KEYS = ("name", "study_dir", "n_trials", "metric", "direction", "space", "sampler", "pruner",
              "final_eval_episodes")  # fmt: skip
RUN_KEYS = tuple(key for key in FIELDS if key != "name")
# metrics of an evaluation (``evaluate.aggregate``) that are numbers for every scenario, and the
# direction a study takes on them unless told
TUNABLE = ("mean_return", "success_rate", "crash_rate", "mean_speed_mps", "mean_distance_km", "mean_length")
METRICS = {name: REGISTRY[name].better for name in TUNABLE}
PARAM_TYPES = ("float", "int", "log", "categorical")  # log: a float searched on a log scale
JOURNAL, SPEC_FILE, LOCK_FILE = "study.journal", "study.yaml", ".study.lock"
BEST_FILE = "best-hyperparams.yml"
MACHINE_KEYS = ("device",)  # settings of the machine, not hyper-parameters: left out of best-hyperparams


@dataclass(frozen=True)
class Param:
    """One searched hyper-parameter: ``kind`` "float", "int" or "categorical"; ``low``/``high``,
    ``log`` and ``step`` for numbers; ``choices`` for a categorical (non-scalar choices are offered
    to Optuna as their JSON text)."""

    name: str
    kind: str
    low: float | None = None
    high: float | None = None
    log: bool = False
    step: float | None = None
    choices: tuple = ()

    def extremes(self) -> list:
        """The values that bound the search (checked against the algorithm before any trial)."""
        return list(self.choices) if self.kind == "categorical" else [self.low, self.high]

    def suggest(self, trial):
        """This parameter's value for an Optuna ``trial``."""
        if self.kind == "float":
            return trial.suggest_float(self.name, self.low, self.high, log=self.log, step=self.step)
        if self.kind == "int":
            return trial.suggest_int(self.name, int(self.low), int(self.high), log=self.log,
                                     step=int(self.step or 1))  # fmt: skip
        if all(_scalar(c) for c in self.choices):
            return trial.suggest_categorical(self.name, list(self.choices))
        return json.loads(trial.suggest_categorical(self.name, [json.dumps(c) for c in self.choices]))

    def decode(self, value):
        """A value as Optuna stored it → the hyper-parameter's value."""
        if self.kind == "categorical" and not all(_scalar(c) for c in self.choices):
            return json.loads(value)
        return value


def _scalar(value) -> bool:
    return value is None or isinstance(value, (bool, int, float, str))


@dataclass(frozen=True)
class Study:
    """A validated study file: the run fields every trial shares and how the search goes."""

    name: str
    run: dict  # RunConfig fields but name; hyperparams: fixed values over the shipped file's
    space: tuple[Param, ...]
    n_trials: int
    metric: str
    direction: str
    final_eval_episodes: int
    study_dir: Path
    sampler: dict = field(default_factory=dict)  # TPESampler keywords (seed, n_startup_trials)
    pruner: dict = field(default_factory=dict)  # MedianPruner keywords
    spec: dict = field(default_factory=dict)  # the file as read (identity of the study)

    def trial_config(self, number: int, params: dict) -> RunConfig:
        """The run config of trial ``number`` with the searched ``params`` (decoded values)."""
        values = {**self.run, "hyperparams": {**self.run.get("hyperparams", {}), **params}}
        return build_config(with_shipped_hyperparams({**values, "name": trial_name(number)}))

    def identity(self) -> dict:
        """What a study directory must match to continue: everything but ``n_trials`` and where."""
        return {k: v for k, v in self.spec.items() if k not in ("n_trials", "study_dir")}


def trial_name(number: int) -> str:
    """Run directory name of trial ``number``: ``trial-0007``."""
    return f"trial-{number:04d}"


# --- reading ---------------------------------------------------------------------------------
def _integer(value, what: str, low: int) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or value < low:
        raise UsageError(f"{what} must be an integer >= {low}, got {value!r}")
    return value


def _number(value, what: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise UsageError(f"{what} must be a number, got {value!r}")
    return value


def _param(name: str, entry) -> Param:
    where = f"tune space {name!r}"
    if not isinstance(entry, dict) or "type" not in entry:
        raise UsageError(f"{where} must be a mapping with a 'type' ({', '.join(PARAM_TYPES)})")
    kind = entry["type"]
    if kind not in PARAM_TYPES:
        raise UsageError(f"{where} has unknown type {kind!r} (choose from {', '.join(PARAM_TYPES)})")
    allowed = {"type", "choices"} if kind == "categorical" else {"type", "low", "high", "log", "step"}
    if stray := sorted(set(entry) - allowed, key=str):
        raise UsageError(f"{where} of type {kind!r} has unknown key {stray[0]!r}")
    if kind == "categorical":
        choices = entry.get("choices")
        if not isinstance(choices, list) or not choices:
            raise UsageError(f"{where} needs 'choices', a non-empty list")
        return Param(name, "categorical", choices=tuple(choices))
    if "low" not in entry or "high" not in entry:
        raise UsageError(f"{where} needs 'low' and 'high'")
    low, high = _number(entry["low"], f"{where} 'low'"), _number(entry["high"], f"{where} 'high'")
    log = entry.get("log", kind == "log")
    if not isinstance(log, bool):
        raise UsageError(f"{where} 'log' must be true or false, got {log!r}")
    step = entry.get("step")
    if kind == "int" and not all(float(v).is_integer() for v in (low, high)):
        raise UsageError(f"{where} of type 'int' needs integer bounds, got {low!r} and {high!r}")
    if not low < high:
        raise UsageError(f"{where} needs low < high, got low {low!r} and high {high!r}")
    if log and low <= 0:
        raise UsageError(f"{where} is searched on a log scale: low must be > 0, got {low!r}")
    if step is not None:
        if log:
            raise UsageError(f"{where} cannot have both 'step' and a log scale")
        if _number(step, f"{where} 'step'") <= 0 or (kind == "int" and not float(step).is_integer()):
            raise UsageError(f"{where} 'step' must be a positive {'integer' if kind == 'int' else 'number'}")
        # Optuna would narrow high to the last step below it, with only a warning
        if (Decimal(str(high)) - Decimal(str(low))) % Decimal(str(step)) != 0:
            raise UsageError(f"{where} 'step' {step!r} must divide high - low ({high!r} - {low!r})")
    kind = "float" if kind == "log" else kind
    number = float if kind == "float" else int
    return Param(name, kind, number(low), number(high), log, step)


def _keywords(value, what: str, keys: tuple[str, ...]) -> dict:
    value = value or {}
    if not isinstance(value, dict):
        raise UsageError(f"tune '{what}' must be a mapping of {', '.join(keys)}")
    if stray := sorted(set(value) - set(keys), key=str):
        raise UsageError(f"tune '{what}' has unknown key {stray[0]!r} (known: {', '.join(keys)})")
    for key, number in value.items():
        _integer(number, f"tune {what} {key!r}", 0)
    return dict(value)


def read_study(spec: dict, study_dir: str | Path | None = None, n_trials: int | None = None) -> Study:
    """Validate a study mapping (see the module docstring); nothing is built or written.

    :param study_dir: overrides the file's ``study_dir`` (default ``runs/tune/<name>``).
    :param n_trials: overrides the file's ``n_trials``."""
    if not isinstance(spec, dict):
        raise UsageError("a tune file must be a mapping")
    if stray := sorted(set(spec) - set(STUDY_KEYS) - set(RUN_KEYS), key=str):
        known = ", ".join([*STUDY_KEYS, *RUN_KEYS])
        raise UsageError(f"unknown tune key {stray[0]!r} (known: {known})")
    if "algo" not in spec:
        raise UsageError("a tune file needs an 'algo'")
    if "steps" not in spec:
        raise UsageError("a tune file needs 'steps', the training budget of each trial")
    from drivelab.agents.registry import get_algo

    get_algo(str(spec["algo"]))
    n_trials = _integer(spec.get("n_trials") if n_trials is None else n_trials, "tune 'n_trials'", 1)
    metric = spec.get("metric", "mean_return")
    if metric not in METRICS:
        raise UsageError(f"unknown tune metric {metric!r} (choose from {', '.join(METRICS)})")
    direction = spec.get("direction", METRICS[metric])
    if direction not in ("maximize", "minimize"):
        raise UsageError(f"tune 'direction' must be maximize or minimize, got {direction!r}")
    final = _integer(spec.get("final_eval_episodes", 20), "tune 'final_eval_episodes'", 1)
    space = spec.get("space")
    if not isinstance(space, dict) or not space:
        raise UsageError("a tune file needs a non-empty 'space' mapping of hyper-parameters to search")
    params = tuple(_param(str(name), entry) for name, entry in space.items())
    run = {key: spec[key] for key in RUN_KEYS if key in spec}
    if not isinstance(run.get("hyperparams", {}), dict):
        raise UsageError("tune 'hyperparams' must be a mapping of fixed hyper-parameters")
    name = str(spec.get("name") or f"{spec['algo']}-{spec.get('env', RunConfig.env)}")
    where = Path(study_dir if study_dir is not None else spec.get("study_dir", Path("runs") / "tune" / name))
    sampler = _keywords(spec.get("sampler"), "sampler", ("seed", "n_startup_trials"))
    pruner = _keywords(spec.get("pruner"), "pruner", ("n_startup_trials", "n_warmup_steps"))
    return Study(name, run, params, n_trials, metric, direction, final, where, sampler, pruner, dict(spec))


def load_study(path: str | Path, study_dir: str | Path | None = None, n_trials: int | None = None) -> Study:
    """Read, validate and check (``check_study``) a study file."""
    study = read_study(load_yaml(path), study_dir, n_trials)
    check_study(study)
    return study


def check_study(study: Study) -> None:
    """Check a trial's run config as ``drivelab train`` does (``run.check_config``: the agent built)
    at the low and the high corner of the space and at each categorical choice, so that a value the
    algorithm refuses fails, as one line, before anything is written."""
    from drivelab.training.run import check_config

    low = {p.name: p.extremes()[0] for p in study.space}
    probes = [low, {p.name: p.extremes()[-1] for p in study.space}]
    probes += [
        {**low, p.name: choice} for p in study.space if p.kind == "categorical" for choice in p.choices
    ]
    new = not _continued(study)  # a study begun before these checks goes on as it was made
    if new:  # the pruner reads the periodic evaluations: at least one must run
        check_eval_every(study.trial_config(0, low))
    for params in probes:
        config = study.trial_config(0, params)
        check_config(config)
        if new:
            check_steps(config)  # a searched n_steps at its high corner: a rollout within the budget


# --- Optuna ----------------------------------------------------------------------------------
def _storage(study_dir: Path):
    import optuna
    from optuna.storages.journal import JournalFileBackend

    return optuna.storages.JournalStorage(JournalFileBackend(str(study_dir / JOURNAL)))


def _pruner(keywords: dict):
    import optuna

    return optuna.pruners.MedianPruner(**keywords)


def _sampler(keywords: dict, number: int = 0):
    """The study's TPE sampler; with a seed, trial ``number``'s: it draws with seed + number, so that a
    study killed and run again asks the same values as the study that was never stopped (given the
    same finished trials)."""
    import optuna

    keywords = dict(keywords)
    if "seed" in keywords:
        keywords["seed"] += number
    return optuna.samplers.TPESampler(**keywords)


def open_optuna_study(study: Study):
    """The study's Optuna study in ``<study_dir>/study.journal`` (created when new)."""
    import optuna

    optuna.logging.set_verbosity(optuna.logging.WARNING)  # tune prints its own progress
    return optuna.create_study(
        study_name=study.name,
        storage=_storage(study.study_dir),
        sampler=_sampler(study.sampler),
        pruner=_pruner(study.pruner),
        direction=study.direction,
        load_if_exists=True,
    )


@dataclass(frozen=True)
class TrialReporter:
    """``on_evaluation`` of a trial's run (it pickles): reports each periodic evaluation's metric to
    the trial and returns False when the median pruner prunes it."""

    study_dir: str
    study_name: str
    trial_id: int
    metric: str
    pruner: dict

    def __call__(self, step: int, summary: dict) -> bool:
        import optuna

        optuna.logging.set_verbosity(optuna.logging.WARNING)
        study = optuna.load_study(
            study_name=self.study_name, storage=_storage(Path(self.study_dir)), pruner=_pruner(self.pruner)
        )
        trial = optuna.trial.Trial(study, self.trial_id)
        if step not in trial.storage.get_trial(self.trial_id).intermediate_values:  # a resumed run
            trial.report(float(summary[self.metric]), step)  # reports its evaluations again
        return not trial.should_prune()


@contextlib.contextmanager
def _locked(study_dir: Path):
    """Hold ``<study_dir>/.study.lock``: one process runs a study at a time."""
    with (study_dir / LOCK_FILE).open("a") as handle:
        try:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            raise UsageError(f"study {str(study_dir)!r} is being run by another process") from None
        try:
            yield
        finally:
            fcntl.flock(handle, fcntl.LOCK_UN)


def _check_study_dir(study: Study) -> None:
    """A UsageError when the study directory holds something else than this study."""
    folder = study.study_dir
    if folder.exists() and not folder.is_dir():
        raise UsageError(f"study directory {str(folder)!r} is a file")
    if (folder / SPEC_FILE).is_file():
        if not _continued(study):
            raise UsageError(
                f"study directory {str(folder)!r} holds another study (its {SPEC_FILE} differs); "
                "remove it or choose another --study-dir"
            )
    elif folder.is_dir() and any(folder.iterdir()):
        raise UsageError(f"study directory {str(folder)!r} is not empty and holds no drivelab study")


def _spec(study: Study):
    """The study's identity as its study.yaml holds it (plain YAML values)."""
    return json.loads(json.dumps(study.identity()))


def _continued(study: Study) -> bool:
    """Whether the study directory's study.yaml is this very study's (``run_study`` refuses any other)."""
    try:
        return parse_yaml_1_1(read_text_bounded(study.study_dir / SPEC_FILE)) == _spec(study)
    except (OSError, UsageError, yaml.YAMLError):
        return False


# --- running ---------------------------------------------------------------------------------
def run_study(
    study: Study,
    executor: str = "pool",
    workers: int | None = None,
    address: str | None = None,
    command: str | None = None,
) -> dict:
    """Run the study's missing trials (``n_trials`` finished ones in all), the trials left running
    by a killed study first; write the summary and return it.

    :param executor: "pool" (local processes) or "ray" (Ray tasks), as for ``run_sweep``.
    :param workers: trials at once (default one per core). One worker runs them in this process.
    :param address: an existing Ray cluster; the study directory must be on storage its nodes share.
    :param command: the command line, written into the summary.
    :raises KeyboardInterrupt: a trial's run was interrupted (it resumes on the next run)."""
    from optuna.trial import Trial, TrialState

    from drivelab.training.evaluate import make_out_dir

    workers = check_workers(executor, workers, address)
    _check_study_dir(study)
    with contextlib.ExitStack() as held:
        # Ray first: a cluster that cannot be joined stops the study before it writes anything
        held.enter_context(executor_ready(executor, workers, address))
        folder = make_out_dir(study.study_dir.resolve(), "study folder")
        held.enter_context(_locked(folder))
        (folder / SPEC_FILE).write_text(yaml.safe_dump(_spec(study), sort_keys=False))
        optuna_study = open_optuna_study(study)
        trials = optuna_study.get_trials(deepcopy=False)
        stale = [t for t in trials if t.state == TrialState.RUNNING]  # its driver was killed
        finished = sum(t.state in (TrialState.COMPLETE, TrialState.PRUNED) for t in trials)
        new = max(0, study.n_trials - finished - len(stale))
        by_name: dict[str, int] = {}  # run name → trial number, of the trials running
        outcomes: list[dict] = []

        def tell(number: int, outcome: dict) -> None:
            if not outcome["ok"]:
                optuna_study.tell(number, state=TrialState.FAIL)
            elif outcome["stopped"] is not None:
                optuna_study.tell(number, state=TrialState.PRUNED)
            else:
                report = json.loads((folder / outcome["name"] / "eval.json").read_text())
                optuna_study.tell(number, float(report[study.metric]))
            outcomes.append(outcome)

        def jobs():  # Optuna's trial ids (``_trial_id``) name a trial in its storage, as Trial() takes it
            revived = (Trial(optuna_study, t._trial_id) for t in stale)  # suggest gives their stored values
            for trial in itertools.chain(revived, (optuna_study.ask() for _ in range(new))):
                if "seed" in study.sampler:  # Optuna draws with the study's sampler of the moment
                    optuna_study.sampler = _sampler(study.sampler, trial.number)
                config = study.trial_config(trial.number, {p.name: p.suggest(trial) for p in study.space})
                action = cell_action(folder / config.name, config, study.final_eval_episodes)
                if action == "skip":  # finished before its study was killed: only the tell is missing
                    tell(trial.number, skipped(config.name))
                    continue
                by_name[config.name] = trial.number
                reporter = TrialReporter(str(folder), study.name, trial._trial_id, study.metric, study.pruner)
                yield {"config_values": config.to_dict(), "runs_dir": str(folder), "action": action,
                       "eval_episodes": study.final_eval_episodes, "on_evaluation": reporter,
                       "eval_first": VALIDATION_START}  # fmt: skip

        with tqdm(
            total=len(stale) + new, desc=f"tune {study.name} ({executor}, {workers} workers)", unit="trial"
        ) as bar:
            # an interrupted trial's run raises KeyboardInterrupt here (``execute``): the trial stays
            # running in the journal and the next run resumes it
            for outcome in execute(run_cell, jobs(), executor, workers, in_flight=workers):
                tell(by_name.pop(outcome["name"]), outcome)
                state = "FAILED" if not outcome["ok"] else "ok" if outcome["stopped"] is None else "pruned"
                bar.set_postfix_str(f"{outcome['name']}: {state}")
                bar.update(1)
        summary = write_summary(study, optuna_study, command)
    summary["outcomes"] = outcomes
    return summary


# --- the summary -----------------------------------------------------------------------------
def trials_table(study: Study, optuna_study):
    """One row per trial (a pandas DataFrame): number, state, value, the searched values as Optuna
    stores them, the last step it reported, its seconds and run directory."""
    import pandas as pd

    rows = [
        {"number": trial.number, "state": trial.state.name.lower(), "value": trial.value, **trial.params,
         "last_step": max(trial.intermediate_values, default=None),
         "seconds": trial.duration.total_seconds() if trial.duration is not None else None,
         "run_dir": trial_name(trial.number)}
        for trial in optuna_study.get_trials(deepcopy=False)
    ]  # fmt: skip
    columns = ["number", "state", "value", *(p.name for p in study.space), "last_step", "seconds", "run_dir"]
    return pd.DataFrame(rows, columns=columns)


def best_entry(study: Study, params: dict) -> dict:
    """A trial's hyper-parameters as one RL Zoo entry (``best-hyperparams.yml``)."""
    from drivelab.agents.registry import get_algo
    from drivelab.envs.core import DriveEnv

    config = study.trial_config(0, params)
    entry: dict = {"n_timesteps": config.steps}
    if get_algo(config.algo).family == "sb3":
        from drivelab.agents.sb3 import policy_for

        env = DriveEnv(**config.env_kwargs())
        entry["policy"] = policy_for(env.observation_space)
        env.close()
    entry["env_kwargs"] = {k: v for k, v in config.env_kwargs().items() if k != "scenario"}
    entry.update({k: v for k, v in config.hyperparams.items() if k not in MACHINE_KEYS})
    return json.loads(json.dumps(entry))  # tuples → lists: plain YAML


def write_summary(study: Study, optuna_study, command: str | None = None) -> dict:
    """Write ``trials.csv``, ``summary.json``, ``summary.md`` and (once a trial finished)
    ``best-hyperparams.yml`` into the study directory; return the summary."""
    from optuna.trial import TrialState

    from drivelab.envs import gym_id

    folder = study.study_dir
    table = trials_table(study, optuna_study)
    table.to_csv(folder / "trials.csv", index=False)
    states = table["state"].value_counts().to_dict()
    complete = [t for t in optuna_study.get_trials(deepcopy=False) if t.state == TrialState.COMPLETE]
    summary: dict = {
        "study": study.name, "algo": study.run["algo"], "env": study.run.get("env", RunConfig.env),
        "metric": study.metric, "direction": study.direction, "steps_per_trial": study.run["steps"],
        "n_trials": study.n_trials, "states": {k: int(v) for k, v in states.items()},
        "command": command, "best": None,
    }  # fmt: skip
    if complete:
        decode = {p.name: p.decode for p in study.space}
        best = optuna_study.best_trial
        params = {name: decode[name](value) for name, value in best.params.items()}
        summary["best"] = {"number": best.number, "value": best.value, "params": params,
                           "run_dir": trial_name(best.number)}  # fmt: skip
        entry = best_entry(study, params)
        header = (
            f"Best trial of the drivelab tune study {study.name!r}: trial {best.number}, "
            f"{study.metric} {best.value:.4g} ({study.direction}) over {len(table)} trials of "
            f"{study.run['steps']} steps.\nCommand: {command or 'drivelab tune'}"
        )
        (folder / BEST_FILE).write_text(zoo_yaml({gym_id(summary["env"]): entry}, header))
    (folder / "summary.json").write_text(json.dumps(summary, indent=2, default=str))
    (folder / "summary.md").write_text(_markdown(study, summary, table))
    return summary


def _markdown(study: Study, summary: dict, table) -> str:
    lines = [f"# tune {study.name}", ""]
    if summary["command"]:
        lines += ["```", summary["command"], "```", ""]
    lines += [
        f"- {summary['algo']} on {summary['env']}, {summary['steps_per_trial']} steps per trial, "
        f"objective: {study.metric} ({study.direction}) over {study.final_eval_episodes} validation episodes "
        f"(evaluation episodes {VALIDATION_START:,} on, none of them a test episode)",
        f"- trials: {len(table)} of {study.n_trials} "
        f"({', '.join(f'{n} {s}' for s, n in sorted(summary['states'].items()))})",
    ]
    best = summary["best"]
    if best is not None:
        lines.append(
            f"- best: trial {best['number']} ({best['run_dir']}), {study.metric} {best['value']:.4g}"
        )
        lines += ["", "Best values (all of them, RL Zoo's format, in " + BEST_FILE + "):", "", "```yaml"]
        lines += [yaml.safe_dump(best["params"], sort_keys=False).rstrip(), "```"]
    header = [str(c) for c in table.columns]
    lines += ["", "| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    for row in table.itertuples(index=False):
        lines.append("| " + " | ".join(_cell(value) for value in row) + " |")
    return "\n".join(lines) + "\n"


def _cell(value) -> str:
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return ""
    if isinstance(value, float):
        return f"{value:.4g}"
    return str(value)


# --- writing the best values into a hyper-parameter file ---------------------------------------
def check_zoo_file(path: Path) -> dict:
    """The entries of the RL Zoo hyper-parameter file ``path`` that ``write_best`` may update (empty
    for a file not there yet); a UsageError for anything else, before the study runs."""
    if path.is_dir():
        raise UsageError(f"--write-best {str(path)!r} is a directory")
    if not path.exists():
        if not path.parent.is_dir():
            raise UsageError(f"--write-best {str(path)!r}: folder {str(path.parent)!r} does not exist")
        return {}
    if not path.is_file():  # /dev/null, a pipe: reads as empty, and the best values would vanish
        raise UsageError(f"--write-best {str(path)!r} is not a regular file")
    try:
        data = parse_yaml_1_1(read_text_bounded(path, "--write-best"))
    except (UsageError, yaml.YAMLError):
        raise UsageError(f"--write-best {str(path)!r} is not a YAML hyper-parameter file") from None
    if data is None:
        return {}
    if not isinstance(data, dict) or not all(isinstance(v, dict) for v in data.values()):
        raise UsageError(
            f"--write-best {str(path)!r} is not an RL Zoo hyper-parameter file (env id → mapping)"
        )
    return data


def write_best(study: Study, summary: dict, path: str | Path) -> Path:
    """Set the study's env entry of the RL Zoo file ``path`` to the best values, keeping the rest."""
    from drivelab.envs import gym_id

    path = Path(path)
    if summary["best"] is None:
        raise UsageError("no trial of the study has finished: nothing to write")
    entries = check_zoo_file(path)
    key = gym_id(summary["env"])
    entries[key] = yaml.safe_load((study.study_dir / BEST_FILE).read_text())[key]
    old = path.read_text(encoding="utf-8").splitlines() if path.exists() else []
    header = itertools.takewhile(lambda line: line.startswith("#"), old)
    comments = [line[2:] if line.startswith("# ") else line[1:] for line in header]
    note = (
        f"{key}: tuned by drivelab tune (study {summary['study']!r}, best {summary['metric']} "
        f"{summary['best']['value']:.4g} over {sum(summary['states'].values())} trials of "
        f"{summary['steps_per_trial']} steps): {summary['command'] or shlex.join(['drivelab', 'tune'])}"
    )
    path.write_text(zoo_yaml(entries, "\n".join([*comments, note])))
    return path
