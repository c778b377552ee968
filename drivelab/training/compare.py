"""Comparisons: read run directories (never re-train), group them over seeds, write a report
directory (report.md, summary.csv, runs.csv, learning_curves.png, metrics.png and
report-manifest.json; see docs/compare.md).

A run's final metrics come from its ``eval.json`` when it has one, else from the last row of its
``evaluations.csv``."""

from __future__ import annotations

import contextlib
import csv
import dataclasses
import fcntl
import glob
import json
import math
import os
import platform
import shutil
import tempfile
import time
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path

from drivelab.config import RunConfig
from drivelab.errors import UsageError
from drivelab.hyperparams import shipped_hyperparams
from drivelab.scenarios import SCENARIOS
from drivelab.training.evaluate import load_run_config
from drivelab.training.metrics import METRICS as REGISTRY
from drivelab.training.metrics import labels
from drivelab.training.safe_files import remove_empty_folders, remove_file, write_failure
from drivelab.training.stats import CONFIDENCE, Summary, summarize
from drivelab.training.stats import percent as percent_of

GROUP_FIELDS = ("algo", "env", "obs", "reward", "action")
HYPERPARAMS_FIELD = "hyperparams"  # CSV column of a group's changed hyper-parameters, ``key=value,…``
# ... or this word for a group on the shipped values (not empty: pandas would read NaN, and groupby
# drops NaN keys)
SHIPPED = "shipped"
SUMMARY_FIELDS = tuple(f.name for f in dataclasses.fields(Summary))  # summary.csv's numbers

# the metrics a comparison reads, checks, tabulates and plots (labels: ``metrics.py``)
METRICS: dict[str, str] = labels(
    ("mean_return", "success_rate", "crash_rate", "mean_distance_km", "mean_speed_mps", "mean_length",
     "collisions_per_km", "off_road_per_km", "route_completion")
)  # fmt: skip


@dataclass(frozen=True)
class RunRecord:
    """What a comparison needs from one run directory.

    :param run_dir: the run directory.
    :param config: its resolved config.
    :param final: final metrics (keys of ``METRICS``; a value may be None).
    :param source: "eval.json" or "evaluations.csv", where ``final`` came from.
    :param curve: (step, mean evaluation return) of every periodic evaluation.
    """

    run_dir: Path
    config: RunConfig
    final: dict
    source: str
    curve: tuple[tuple[int, float], ...]


def group_key(config: RunConfig) -> tuple[str, ...]:
    """(algorithm, scenario, sensors, reward, action[, hyper-parameter changes]): runs that differ
    only in seed share it. Hyper-parameters that differ from the shipped ones are a sixth part,
    ``key=value,…``."""
    key = (config.algo, config.env, ",".join(config.obs), config.reward, config.action)
    shipped = shipped_hyperparams(config.algo, config.env)
    changed = {k: v for k, v in sorted(config.hyperparams.items()) if k not in shipped or shipped[k] != v}
    return key + (",".join(f"{k}={v}" for k, v in changed.items()),) if changed else key


def find_runs(patterns: Iterable[str | Path]) -> list[Path]:
    """Run directories named by paths or glob patterns (``runs/*``), in order, without repeats; a
    UsageError for a pattern that matches none or a path that is not one."""
    found: list[Path] = []
    for pattern in patterns:
        text = str(pattern)
        if glob.has_magic(text):
            matches = [Path(p) for p in sorted(glob.glob(text)) if (Path(p) / "config.yaml").is_file()]
            if not matches:
                raise UsageError(f"no run directory matches {text!r}")
        else:
            load_run_config(Path(text))  # one-line error for a missing or foreign directory
            matches = [Path(text)]
        found.extend(m for m in matches if m not in found)
    if not found:
        raise UsageError("no run directories given (pass RUN_DIR... or --runs 'runs/*')")
    return found


def _float_or_none(value) -> float | None:
    if value is None or value == "":
        return None
    if isinstance(value, bool) or not isinstance(value, (int, float, str)):
        raise ValueError(value)
    return float(value)


def _final_metrics(values: dict, path: Path) -> dict:
    """The ``METRICS`` of ``values`` (a row or eval.json) as floats or None; a UsageError naming the
    file and the metric for a value no evaluation writes."""
    final = {}
    for key in METRICS:
        given = values.get(key)
        try:
            value = _float_or_none(given)
        except ValueError:
            raise UsageError(f"{str(path)!r}: metric {key!r} is not a number: {given!r}") from None
        if value is not None and not math.isfinite(value):
            raise UsageError(f"{str(path)!r}: metric {key!r} is not a finite number: {given!r}")
        if value is not None and REGISTRY[key].values == "rate" and not 0.0 <= value <= 1.0:
            raise UsageError(f"{str(path)!r}: metric {key!r} is a rate, which lies in [0, 1], not {given!r}")
        if value is not None and REGISTRY[key].values != "signed" and value < 0:
            raise UsageError(f"{str(path)!r}: metric {key!r} cannot be negative: {given!r}")
        final[key] = value
    return final


def read_evaluations(path: Path) -> tuple[list[tuple[int, float]], dict]:
    """(step, mean return) of every row of an evaluations.csv, and its last row."""
    curve: list[tuple[int, float]] = []
    last_row: dict = {}
    try:
        with path.open(newline="", encoding="utf-8") as handle:
            for row in csv.DictReader(handle):
                curve.append((int(row["step"]), float(row["mean_return"])))
                last_row = row
                if not math.isfinite(curve[-1][1]) or curve[-1][0] < 0:
                    field = "step" if curve[-1][0] < 0 else "mean_return"
                    raise UsageError(
                        f"{str(path)!r} (row {len(curve)}): {field!r} is not a finite number of an "
                        f"evaluation: {row[field]!r}"
                    )
    except UsageError:
        raise
    except (KeyError, TypeError, ValueError, csv.Error) as exc:  # UnicodeDecodeError is a ValueError
        line = f" (row {len(curve) + 1})" if curve or not isinstance(exc, KeyError) else ""
        raise UsageError(
            f"{str(path)!r} is not an evaluations.csv written by drivelab train{line}: {type(exc).__name__}"
        ) from None
    return curve, last_row


def last_evaluation(run_dir: Path) -> dict | None:
    """A run's last periodic evaluation (numbers as numbers, None where empty), or None."""
    path = Path(run_dir) / "evaluations.csv"
    _, row = read_evaluations(path) if path.is_file() else ([], {})
    if not row:
        return None
    return {key: None if value == "" else int(value) if key in ("step", "episodes") else float(value)
            for key, value in row.items()}  # fmt: skip


def _check_names(config: RunConfig, path: Path) -> None:
    """A UsageError when a run's config names an algorithm or a scenario drivelab does not have."""
    from drivelab.agents.registry import ALGORITHMS

    if config.algo not in ALGORITHMS:
        raise UsageError(f"{str(path)!r}: field 'algo' names no drivelab algorithm: {config.algo!r}")
    if config.env not in SCENARIOS:
        raise UsageError(f"{str(path)!r}: field 'env' names no drivelab scenario: {config.env!r}")


def load_run(run_dir: str | Path) -> RunRecord:
    """Read a run's config, final metrics and evaluation curve."""
    run_dir = Path(run_dir)
    config = load_run_config(run_dir)
    _check_names(config, run_dir / "config.yaml")
    evaluations = run_dir / "evaluations.csv"
    curve, last_row = read_evaluations(evaluations) if evaluations.is_file() else ([], {})
    eval_json = run_dir / "eval.json"
    if eval_json.is_file():
        try:
            report = json.loads(eval_json.read_text(encoding="utf-8"))
        except (json.JSONDecodeError, UnicodeDecodeError):
            raise UsageError(f"{str(eval_json)!r} is not valid JSON") from None
        if not isinstance(report, dict):
            raise UsageError(f"{str(eval_json)!r} is not an eval.json written by drivelab evaluate")
        steps = report.get("model_steps", config.steps)  # an eval.json of an older drivelab has none
        if not isinstance(steps, int) or isinstance(steps, bool) or steps < config.steps:
            raise UsageError(
                f"{str(eval_json)!r} evaluated the model of step {steps!r}, not the run's final one of "
                f"{config.steps} steps (evaluated before its training ended); evaluate the finished run "
                "again, or remove it to compare the run's periodic evaluations"
            )
        final, source = _final_metrics(report, eval_json), "eval.json"
    elif last_row:
        final, source = _final_metrics(last_row, evaluations), "evaluations.csv"
    else:
        raise UsageError(f"run {str(run_dir)!r} has no evaluation yet (no eval.json, no evaluations.csv)")
    return RunRecord(run_dir, config, final, source, tuple(curve))


def conditions(config: RunConfig) -> dict[str, str]:
    """What a run was trained and evaluated on beside its scenario: traffic, simulator ("auto" read
    as the one it picks), environment options and evaluation maps, as printable values."""
    backend = config.backend
    if backend == "auto" and config.env in SCENARIOS:
        backend = "fast" if SCENARIOS[config.env].fast_backend else "highway"
    return {
        "traffic": config.traffic,
        "backend": backend,
        **{name: str(value) for name, value in sorted(config.env_options.items())},
        "eval_maps": str(config.eval_maps) if config.eval_maps is not None else "the training maps",
    }


def _scenario_labels(records: Sequence[RunRecord]) -> list[str]:
    """Each run's scenario as its group shows it: the name, followed by the ``conditions`` and
    ``steps`` that differ among ``records`` (``highway (traffic=dense)``); the name alone where all
    agree."""
    values = [{**conditions(record.config), "steps": str(record.config.steps)} for record in records]
    names = dict.fromkeys(name for value in values for name in value)
    varying = [name for name in names if len({value.get(name, "default") for value in values}) > 1]
    parts = [", ".join(f"{name}={value.get(name, 'default')}" for name in varying) for value in values]
    return [f"{r.config.env} ({p})" if p else r.config.env for r, p in zip(records, parts, strict=True)]


def group_runs(records: Sequence[RunRecord]) -> dict[tuple[str, ...], list[RunRecord]]:
    """Runs grouped by ``group_key``, groups in order of first appearance, runs sorted by seed. Runs
    whose ``conditions`` or training budgets differ are different groups, their scenario labelled
    with the difference (``_scenario_labels``). Two runs of one config, seed and budget are one
    sample, not two: a UsageError naming them."""
    groups: dict[tuple[str, ...], list[RunRecord]] = {}
    seen: dict[tuple[str, int], RunRecord] = {}
    for record, scenario in zip(records, _scenario_labels(records), strict=True):
        config = record.config
        same = seen.setdefault((config.identity(), config.steps), record)  # the identity has the seed
        if same is not record:
            raise UsageError(
                f"runs {str(same.run_dir)!r} and {str(record.run_dir)!r} are the same run (one config, "
                f"seed {config.seed}, {config.steps} steps): a seed counts once in a group; "
                "compare one of them"
            )
        key = group_key(config)
        groups.setdefault((key[0], scenario, *key[2:]), []).append(record)
    return {key: sorted(runs, key=lambda r: (r.config.seed, str(r.run_dir))) for key, runs in groups.items()}


def summarize_groups(
    groups: dict[tuple[str, ...], list[RunRecord]], confidence: float = CONFIDENCE
) -> dict[tuple[str, ...], dict[str, Summary]]:
    """{group: {metric: Summary over the group's runs}}."""
    return {
        key: {metric: summarize([r.final[metric] for r in runs], confidence) for metric in METRICS}
        for key, runs in groups.items()
    }


# --- writing ---------------------------------------------------------------------------------
def machine_description() -> str:
    """CPU model, core count, OS and Python version of this machine, for reports."""
    cpu = platform.processor() or platform.machine()
    cpuinfo = Path("/proc/cpuinfo")
    if cpuinfo.is_file():
        for line in cpuinfo.read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    system = f"{platform.system()} {platform.release()}"
    return f"{cpu}, {os.cpu_count()} cores, {system}, Python {platform.python_version()}"


def _fmt(value: float, digits: int = 3) -> str:
    return "n/a" if value is None or math.isnan(value) else f"{value:.{digits}f}"


def _markdown(
    groups: dict[tuple[str, ...], list[RunRecord]],
    summaries: dict[tuple[str, ...], dict[str, Summary]],
    confidence: float,
    title: str,
    command: str | None,
) -> str:
    percent = percent_of(confidence)
    notes = [f"Written {time.strftime('%Y-%m-%d %H:%M:%S %Z')} by drivelab on {machine_description()}."]
    if command:
        notes.append(f"Made with:\n\n```bash\n{command}\n```")
    notes.append(
        f"Each run contributes one value per metric (its final evaluation). Over the seeds of a group:"
        f" the mean, a {percent} % percentile-bootstrap confidence interval of the mean"
        f" (scipy.stats.bootstrap, 10,000 resamples) and the interquartile mean (IQM, rliable's"
        f" trimmed mean; with fewer than 4 seeds it equals the mean)."
    )
    if len({key[3] for key in groups}) > 1:
        notes.append(
            "The groups differ in reward, and each run's return is measured with its own reward:"
            " compare returns across rewards with care; the driving metrics (success, crashes, speed,"
            " distance) do not depend on the reward."
        )
    scenarios = list(dict.fromkeys(runs[0].config.env for runs in groups.values()))
    if len(scenarios) > 1:
        notes.append(
            f"The groups drive different scenarios ({', '.join(scenarios)}), each evaluated on its own"
            " scenario's episodes: a metric compares how each agent does at its own task, not the"
            " agents at one task."
        )
    goalless = [name for name in scenarios if name in SCENARIOS and SCENARIOS[name].arrival == "none"]
    if goalless:
        notes.append(
            f"{', '.join(goalless)} {'has' if len(goalless) == 1 else 'have'} no goal to reach: there,"
            " success is the time limit reached with no collision and no off-road event, which a slow,"
            " careful policy also scores; read speed and distance beside it."
        )
    budgets = sorted({runs[0].config.steps for runs in groups.values()})
    if len(budgets) > 1:
        notes.append(
            f"The runs were trained for different budgets ({', '.join(f'{b:,}' for b in budgets)} steps),"
            " and each budget is a group of its own (`steps=` in its scenario): as in rliable and RL Zoo,"
            " final scores compare at one budget; across budgets they say how training goes on."
        )
    notes += [
        f"**Warning:** group {' · '.join(key)} has several runs with the same seed; each counts as"
        " a separate sample, which narrows its interval."
        for key, runs in groups.items()
        if len({r.config.seed for r in runs}) < len(runs)
    ]
    lines = [f"# {title}"]
    for note in notes:
        lines += ["", note]
    lines += [
        "",
        "## Groups",
        "",
        "| group (algo · env · obs · reward · action [· hyper-parameters]) | seeds | steps | runs |",
        "|---|---|---|---|",
    ]
    for key, runs in groups.items():
        seeds = ", ".join(str(r.config.seed) for r in runs)
        steps = ", ".join(sorted({str(r.config.steps) for r in runs}))
        names = ", ".join(f"`{r.run_dir.name}` ({r.source})" for r in runs)
        lines.append(f"| {' · '.join(key)} | {seeds} | {steps} | {names} |")
    for metric, label in METRICS.items():
        if all(summaries[key][metric].n == 0 for key in groups):
            continue
        lines += [
            "",
            f"## {label}",
            "",
            f"| group | n | mean | {percent} % CI | IQM |",
            "|---|---|---|---|---|",
        ]
        for key in groups:
            s = summaries[key][metric]
            lines.append(
                f"| {' · '.join(key)} | {s.n} | {_fmt(s.mean)} | [{_fmt(s.ci_low)}, {_fmt(s.ci_high)}]"
                f" | {_fmt(s.iqm)} |"
            )
    lines += ["", "![learning curves](learning_curves.png)", "", "![metrics](metrics.png)", ""]
    return "\n".join(lines)


def _group_columns(key: tuple[str, ...]) -> dict[str, str]:
    """A group key as CSV columns: the ``GROUP_FIELDS`` and ``hyperparams`` (or ``SHIPPED``)."""
    return {**dict(zip(GROUP_FIELDS, key[:5], strict=True)), HYPERPARAMS_FIELD: ",".join(key[5:]) or SHIPPED}


def _write_csvs(folder: Path, groups, summaries) -> None:
    """summary.csv (one row per group and metric) and runs.csv (one row per run)."""
    import pandas as pd

    summary = [
        {**_group_columns(key), "metric": metric, **dataclasses.asdict(summaries[key][metric])}
        for key in groups
        for metric in METRICS
    ]
    columns = [*GROUP_FIELDS, HYPERPARAMS_FIELD, "metric", *SUMMARY_FIELDS]
    # an interval of fewer than 2 runs is "nan" (a number that is not defined), as in report.md
    pd.DataFrame(summary, columns=columns).to_csv(folder / "summary.csv", index=False, na_rep="nan")
    runs = [
        {
            "run_dir": str(r.run_dir),
            **_group_columns(key),
            "seed": r.config.seed,
            "steps": r.config.steps,
            "source": r.source,
            **r.final,
        }
        for key, group in groups.items()
        for r in group
    ]
    columns = ["run_dir", *GROUP_FIELDS, HYPERPARAMS_FIELD, "seed", "steps", "source", *METRICS]
    pd.DataFrame(runs, columns=columns).to_csv(folder / "runs.csv", index=False)


MANIFEST = "report-manifest.json"  # the files a report directory's drivelab report consists of
REPORT_FILES = ("report.md", "summary.csv", "runs.csv", "learning_curves.png", "metrics.png")
TMP_PREFIX = ".report.tmp-"  # the folder a report is written into before its files are moved out


def _is_report_tmp(folder: Path) -> bool:
    """Whether ``folder`` is a ``TMP_PREFIX…`` folder (not a link) holding only files of a report."""
    if not folder.name.startswith(TMP_PREFIX) or folder.is_symlink() or not folder.is_dir():
        return False
    try:
        return all(
            p.name in (*REPORT_FILES, MANIFEST) and p.is_file() and not p.is_symlink()
            for p in folder.iterdir()
        )
    except OSError:
        return False


def _tmp_folders(out_dir: Path) -> list[Path]:
    """The folders in ``out_dir`` that ``publish_dir`` writes reports into."""
    return sorted(p for p in out_dir.iterdir() if _is_report_tmp(p))


def _remove_stale_tmp_folders(out_dir: Path, keep: Path) -> None:
    """Remove the temporary folders of reports killed while they were written; one that another
    process holds locked (``publish_dir``), or that holds anything else, stays."""
    for folder in _tmp_folders(out_dir):
        if folder == keep:
            continue
        try:
            handle = os.open(folder, os.O_RDONLY | os.O_DIRECTORY | os.O_NOFOLLOW)
        except OSError:
            continue  # gone meanwhile
        try:
            # refused: a report being written now, or a file system without locks (NFS): it stays
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
            for name in (*REPORT_FILES, MANIFEST):
                with contextlib.suppress(OSError):
                    remove_file(folder / name)
            folder.rmdir()  # refused when something else is in it now: it stays
        except OSError:
            pass
        finally:
            os.close(handle)


def _new_tmp_folder(out_dir: Path) -> tuple[Path, int]:
    """A new temporary folder in ``out_dir`` for ``publish_dir`` and a descriptor of it holding its
    lock (none on a file system without locks), so that another report's cleanup leaves it alone."""
    while True:
        tmp = Path(tempfile.mkdtemp(prefix=TMP_PREFIX, dir=out_dir))
        try:
            handle = os.open(tmp, os.O_RDONLY | os.O_DIRECTORY)
        except FileNotFoundError:
            continue  # removed before it was opened
        except OSError:
            shutil.rmtree(tmp, ignore_errors=True)
            raise
        try:
            fcntl.flock(handle, fcntl.LOCK_EX)
        except OSError:
            return tmp, handle  # no locks on this file system
        with contextlib.suppress(FileNotFoundError):
            if os.path.samestat(os.fstat(handle), os.stat(tmp)):
                return tmp, handle
        os.close(handle)  # removed before it was locked


def previous_report_files(out_dir: Path) -> list[str] | None:
    """The files a previous drivelab report wrote into ``out_dir`` (its manifest included), None
    when it holds none; a manifest naming anything but a report's files is a UsageError."""
    manifest = out_dir / MANIFEST
    if manifest.is_file():
        try:
            files = json.loads(manifest.read_text(encoding="utf-8"))["files"]
        except (ValueError, KeyError, TypeError):
            raise UsageError(f"{str(manifest)!r} is corrupted; move the report away by hand") from None
        if not isinstance(files, list) or not all(isinstance(name, str) for name in files):
            raise UsageError(f"{str(manifest)!r} is corrupted; move the report away by hand")
        foreign = [name for name in files if name not in REPORT_FILES]
        if foreign:
            raise UsageError(
                f"{str(manifest)!r} lists {foreign[0]!r}, which no drivelab report writes: it is not a "
                "manifest of drivelab's, and compare deletes nothing by it; choose another --out"
            )
        return [*files, MANIFEST]
    if (out_dir / "report.md").is_file():
        return [name for name in REPORT_FILES if (out_dir / name).exists()]
    return None


def _check_out_dir(out_dir: Path) -> list[str]:
    """The previous report's files in ``out_dir``; a UsageError where writing could harm other files."""
    if not out_dir.exists():
        return []
    if not out_dir.is_dir():
        raise UsageError(f"--out {str(out_dir)!r} is a file, not a directory")
    previous = previous_report_files(out_dir)
    ours = set(_tmp_folders(out_dir))  # a report killed while it was written left one: not the user's
    if previous is None and any(p not in ours for p in out_dir.iterdir()):
        raise UsageError(
            f"--out {str(out_dir)!r} is not empty and holds no drivelab report; choose another --out "
            "(compare never deletes or overwrites files it did not write)"
        )
    for name in previous or []:
        if (out_dir / name).is_dir() and not (out_dir / name).is_symlink():
            raise UsageError(
                f"{str(out_dir / name)!r} is a folder, not a file of a drivelab report; choose another --out "
                "(compare never deletes or overwrites files it did not write)"
            )
    return previous or []


def publish_dir(out_dir: Path, fill) -> Path:
    """Write a report with ``fill(folder)`` into a temporary folder inside ``out_dir``, then move
    its files into ``out_dir`` and list them in ``report-manifest.json``.

    A failure leaves ``out_dir`` as it was (a failed write is one line). Of a previous report only
    the files its manifest lists are replaced or removed; a non-empty ``out_dir`` without a report
    is refused. The temporary folder of a killed report is removed by the next one."""
    out_dir = Path(out_dir)
    previous = _check_out_dir(out_dir)
    created = [p for p in (out_dir, *out_dir.parents) if not p.exists()]
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
        # locked while in use: a later report removes it only if this process was killed meanwhile
        tmp, lock = _new_tmp_folder(out_dir)
    except OSError as exc:
        remove_empty_folders(created)
        raise write_failure(exc, out_dir, what=f"a report in {str(out_dir)!r}") from None
    try:
        fill(tmp)
        written = sorted(p.name for p in tmp.iterdir())
        clashes = [name for name in written if os.path.lexists(out_dir / name) and name not in previous]
        if clashes:
            raise UsageError(f"{str(out_dir / clashes[0])!r} exists and is not from a drivelab report")
        for name in previous:
            (out_dir / name).unlink(missing_ok=True)  # a file (``_check_out_dir``), or a link itself
        for name in written:
            os.replace(tmp / name, out_dir / name)
        (tmp / MANIFEST).write_text(json.dumps({"files": written}, indent=2) + "\n")
        os.replace(tmp / MANIFEST, out_dir / MANIFEST)
    except BaseException as exc:
        shutil.rmtree(tmp, ignore_errors=True)
        remove_empty_folders(created)
        if isinstance(exc, OSError):  # a full disk, most often
            raise write_failure(exc, out_dir, what=f"a report in {str(out_dir)!r}") from None
        raise
    finally:
        os.close(lock)
    shutil.rmtree(tmp, ignore_errors=True)
    _remove_stale_tmp_folders(out_dir, keep=tmp)
    return out_dir


def write_report(
    records: Sequence[RunRecord],
    out_dir: str | Path,
    title: str = "drivelab comparison",
    command: str | None = None,
    confidence: float = CONFIDENCE,
) -> Path:
    """Group ``records`` over seeds and write the report directory ``out_dir`` atomically."""
    from drivelab.training.compare_plots import plot_learning_curves, plot_metric_bars

    groups = group_runs(records)
    summaries = summarize_groups(groups, confidence)

    def fill(folder: Path) -> None:
        (folder / "report.md").write_text(_markdown(groups, summaries, confidence, title, command))
        _write_csvs(folder, groups, summaries)
        plot_learning_curves(groups, folder / "learning_curves.png", confidence)
        plot_metric_bars(groups, summaries, folder / "metrics.png", confidence)

    return publish_dir(Path(out_dir), fill)


def compare(
    runs: Iterable[str | Path],
    out_dir: str | Path,
    title: str = "drivelab comparison",
    command: str | None = None,
    confidence: float = CONFIDENCE,
) -> Path:
    """Read the run directories named by ``runs`` (paths or globs) and write a comparison report.

    :param runs: run directories or glob patterns such as ``runs/*``.
    :param out_dir: report directory to (re)write.
    :param title: heading of report.md.
    :param command: the command line that made the report, quoted in report.md.
    :param confidence: coverage of the bootstrap intervals (0.9: 90 %)."""
    if not 0.0 < confidence < 1.0:
        raise UsageError(f"--confidence must be between 0 and 1, got {confidence}")
    records = [load_run(path) for path in find_runs(runs)]
    return write_report(records, out_dir, title=title, command=command, confidence=confidence)
