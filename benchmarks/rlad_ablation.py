"""RLAD and its three ablations × 3 seeds in the training town, then NoCrash on the test town.

    .venv/bin/python benchmarks/rlad_ablation.py [--steps N] [--episodes 25] [--workers 1]

1. ``drivelab sweep benchmarks/sweeps/rlad-ablation.yaml`` (re-running resumes unfinished runs);
2. ``drivelab benchmark nocrash RUN`` for every run (success per traffic level, infractions);
3. ``drivelab compare`` of the runs (learning curves with 90 % bands, bootstrap intervals) into
   ``benchmarks/results/rlad-ablation/`` plus ``nocrash.md``: NoCrash success per variant and level,
   mean and 90 % bootstrap interval over seeds.

``--report-only`` rewrites ``nocrash.md`` from the runs' ``nocrash.json`` files (e.g. after the runs
were made on another machine and only their small files were brought back).

``--steps`` (and ``--eval-every``) shrink the budget for a check of the pipeline; such runs go
to their own runs directory and report directory so they never mix with the real ones.
"""

from __future__ import annotations

import argparse
import json
import multiprocessing
import sys
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import torch

from drivelab.training.checkpoints import file_sha256
from drivelab.training.compare import group_runs, load_run, write_report
from drivelab.training.nocrash import INFRACTIONS, LEVELS, NOCRASH_SEED, nocrash
from drivelab.training.stats import summarize
from drivelab.training.sweep import expand_sweep, run_dirs, run_sweep
from drivelab.yaml_io import load_yaml

HERE = Path(__file__).parent
SWEEP = HERE / "sweeps" / "rlad-ablation.yaml"


def variant(record) -> str:
    """The paper's name of a run's variant, from the switches in its hyper-parameters."""
    hyperparams = record.config.hyperparams or {}
    off = [
        name
        for name, is_off in (
            ("no A-LIX", hyperparams.get("alix") is False),
            ("no traffic-light loss", hyperparams.get("aux") is False),
            ("MLP waypoints", hyperparams.get("waypoint_encoder") == "mlp"),
            ("no augmentation", hyperparams.get("augment") is False),
        )
        if is_off
    ]
    return ", ".join(off) or "RLAD"


def interval(values: list[float], digits: int = 0) -> str:
    """``mean [90 % bootstrap interval]`` over seeds (the mean alone for one seed)."""
    s = summarize(values)
    if s.n < 2:
        return f"{s.mean:.{digits}f}"
    return f"{s.mean:.{digits}f} [{s.ci_low:.{digits}f}, {s.ci_high:.{digits}f}]"


def nocrash_tables(reports: dict[Path, dict], records: list) -> str:
    """Markdown: NoCrash success (%) per variant and traffic level, then the infractions in regular
    traffic; each cell the mean [90 % CI] over seeds."""
    groups = group_runs(records)
    lines = ["| variant | seeds | " + " | ".join(LEVELS) + " |", "|---|---|" + "---|" * len(LEVELS)]
    for runs in groups.values():
        cells = [
            interval([100 * reports[r.run_dir]["levels"][lv]["success_rate"] for r in runs]) for lv in LEVELS
        ]
        lines.append(f"| {variant(runs[0])} | {len(runs)} | " + " | ".join(cells) + " |")
    lines += [
        "",
        "Regular traffic:",
        "",
        "| variant | " + " | ".join(label for label, _ in INFRACTIONS) + " |",
    ]
    lines.append("|---|" + "---|" * len(INFRACTIONS))
    for runs in groups.values():
        cells = []
        for label, key in INFRACTIONS:
            scale, digits = (100, 0) if label.endswith("%") else (1, 1)
            values = [reports[r.run_dir]["levels"]["regular"][key] for r in runs]
            cells.append("n/a" if None in values else interval([scale * v for v in values], digits))
        lines.append(f"| {variant(runs[0])} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def saved_nocrash(run_dir: Path) -> dict:
    """The run's nocrash.json on the test town (``--report-only``)."""
    path = run_dir / "nocrash.json"
    if not path.exists():
        sys.exit(f"{path} is missing: run without --report-only to evaluate")
    report = json.loads(path.read_text())
    if report.get("town") != "test":
        sys.exit(f"{path} evaluated the {report.get('town')!r} town, not the test town")
    return report


def nocrash_once(run_dir: Path, episodes: int) -> dict:
    """NoCrash on the test town, or the run's nocrash.json when it already holds that evaluation
    (same episodes and seed) of this very final model (its SHA-256), so a re-run after an
    interruption only evaluates what is missing."""
    saved, final = run_dir / "nocrash.json", run_dir / "model.zip"
    if saved.exists() and final.is_file():
        report = json.loads(saved.read_text())
        wanted = {"town": "test", "episodes_per_level": episodes, "seed": NOCRASH_SEED}
        wanted["model_sha256"] = file_sha256(final)
        if all(report.get(key) == value for key, value in wanted.items()):
            return report
    return nocrash(run_dir, town="test", episodes=episodes)


def _one_thread() -> None:
    torch.set_num_threads(1)  # one evaluation per core: no oversubscription


def nocrash_all(directories: list[Path], episodes: int, workers: int) -> dict[Path, dict]:
    """``nocrash_once`` for every run, ``workers`` runs at a time (fresh interpreters)."""
    if workers <= 1:
        return {d: nocrash_once(d, episodes) for d in directories}
    context = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(max_workers=workers, mp_context=context, initializer=_one_thread) as pool:
        futures = {d: pool.submit(nocrash_once, d, episodes) for d in directories}
        return {d: future.result() for d, future in futures.items()}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--steps", type=int, default=None, help="training steps per run (default: the file's)"
    )
    parser.add_argument("--eval-every", type=int, default=None, help="steps between periodic evaluations")
    parser.add_argument("--episodes", type=int, default=25, help="NoCrash episodes per traffic level")
    parser.add_argument(
        "--workers", type=int, default=1, help="parallel runs and NoCrash evaluations (one per core at most)"
    )
    parser.add_argument("--hyperparams", default=None, help="JSON of extra hyper-parameters for every run")
    parser.add_argument(
        "--duration-s", type=float, default=None, help="episode time limit (default: the town's)"
    )
    parser.add_argument("--out", type=Path, default=None, help="report directory")
    parser.add_argument(
        "--report-only",
        action="store_true",
        help="rewrite nocrash.md from the runs' nocrash.json (no training, no evaluation)",
    )
    args = parser.parse_args()
    spec = load_yaml(SWEEP)
    tiny = args.steps is not None
    if tiny:
        spec["base"] = {**spec["base"], "steps": args.steps, "eval_every": args.eval_every or args.steps}
        spec["runs_dir"] = spec["runs_dir"] + f"-{args.steps}steps"
    if args.hyperparams:
        spec["base"] = {**spec["base"], "hyperparams": json.loads(args.hyperparams)}
    if args.duration_s is not None:
        spec["base"] = {**spec["base"], "env_options": {"duration_s": args.duration_s}}
    out = args.out or HERE / "results" / ("rlad-ablation" + (f"-{args.steps}steps" if tiny else ""))
    sweep = expand_sweep(spec)
    directories = run_dirs(sweep)
    command = "python " + " ".join(sys.argv)
    if args.report_only:
        reports = {d: saved_nocrash(d) for d in directories}
        records = [load_run(d) for d in directories]
        report = out
        report.mkdir(parents=True, exist_ok=True)
        made = "runs, evaluations and their machine: report.md"
    else:
        outcomes = run_sweep(sweep, workers=args.workers)
        failed = [o["name"] for o in outcomes if not o["ok"]]
        if failed:
            sys.exit(f"runs failed: {', '.join(failed)} (logs in {sweep.runs_dir / '.sweep-logs'})")
        reports = nocrash_all(directories, args.episodes, args.workers)
        records = [load_run(d) for d in directories]
        report = write_report(records, out, title="RLAD ablation in the town", command=command)
        made = "machine: report.md"
    episodes = {r["episodes_per_level"] for r in reports.values()}
    text = [
        "# NoCrash (test town): RLAD and its ablations",
        "",
        f"Command: `{command}` ({made})  ",
        f"{', '.join(map(str, sorted(episodes)))} episodes per traffic level and run, on the test town's "
        "fixed routes; mean [90 % bootstrap interval] over seeds. "
        f"Training budget: {sweep.cells[0].config.steps:,} steps per run (the paper trains 10^6).",
        "",
        "Success %:",
        "",
        nocrash_tables(reports, records),
        "",
    ]
    (report / "nocrash.md").write_text("\n".join(text))
    print("\n".join(text))
    print(f"report: {report / 'report.md'}")


if __name__ == "__main__":
    main()
