"""RLAD and its three ablations × 3 seeds in the training town, then NoCrash on the test town.

    .venv/bin/python benchmarks/rlad_ablation.py [--steps N] [--episodes 25] [--workers 1]

1. ``drivelab sweep benchmarks/sweeps/rlad-ablation.yaml`` (re-running resumes unfinished runs);
2. ``drivelab benchmark nocrash RUN`` for every run (success per traffic level, infractions);
3. ``drivelab compare`` of the runs (learning curves with 90 % bands, bootstrap intervals) into
   ``benchmarks/results/rlad-ablation/`` plus ``nocrash.md``: NoCrash success per variant and level,
   mean and 90 % bootstrap interval over seeds.

``--steps`` (and ``--eval-every``) shrink the budget for a check of the pipeline; such runs go
to their own runs directory and report directory so they never mix with the real ones.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from drivelab.config import load_yaml
from drivelab.training.compare import group_label, group_runs, load_run, write_report
from drivelab.training.nocrash import LEVELS, nocrash
from drivelab.training.stats import summarize
from drivelab.training.sweep import expand_sweep, run_dirs, run_sweep

HERE = Path(__file__).parent
SWEEP = HERE / "sweeps" / "rlad-ablation.yaml"


def nocrash_table(reports: dict[Path, dict], records: list) -> str:
    """Markdown: NoCrash success (%) per group and traffic level, mean [90 % CI] over seeds."""
    lines = ["| variant | seeds | " + " | ".join(LEVELS) + " |", "|---|---|" + "---|" * len(LEVELS)]
    for key, runs in group_runs(records).items():
        cells = []
        for level in LEVELS:
            values = [100 * reports[r.run_dir]["levels"][level]["success_rate"] for r in runs]
            s = summarize(values)
            cells.append(f"{s.mean:.0f} [{s.ci_low:.0f}, {s.ci_high:.0f}]" if s.n > 1 else f"{s.mean:.0f}")
        lines.append(f"| {group_label(key)} | {len(runs)} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--steps", type=int, default=None, help="training steps per run (default: the file's)"
    )
    parser.add_argument("--eval-every", type=int, default=None, help="steps between periodic evaluations")
    parser.add_argument("--episodes", type=int, default=25, help="NoCrash episodes per traffic level")
    parser.add_argument("--workers", type=int, default=1, help="parallel runs (one per core at most)")
    parser.add_argument("--hyperparams", default=None, help="JSON of extra hyper-parameters for every run")
    parser.add_argument(
        "--duration-s", type=float, default=None, help="episode time limit (default: the town's)"
    )
    parser.add_argument("--out", type=Path, default=None, help="report directory")
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
    outcomes = run_sweep(sweep, workers=args.workers)
    failed = [o["name"] for o in outcomes if not o["ok"]]
    if failed:
        sys.exit(f"runs failed: {', '.join(failed)} (logs in {sweep.runs_dir / '.sweep-logs'})")
    directories = run_dirs(sweep)
    reports = {d: nocrash(d, town="test", episodes=args.episodes) for d in directories}
    records = [load_run(d) for d in directories]
    command = "python " + " ".join(sys.argv)
    report = write_report(records, out, title="RLAD ablation in the town", command=command)
    text = [
        "# NoCrash (test town): success % per traffic level",
        "",
        f"Command: `{command}`  ",
        f"{args.episodes} episodes per level and run; mean [90 % bootstrap interval] over seeds. "
        f"Training budget: {sweep.cells[0].config.steps:,} steps per run (the paper trains 10^6).",
        "",
        nocrash_table(reports, records),
        "",
    ]
    (report / "nocrash.md").write_text("\n".join(text))
    print("\n".join(text))
    print(f"report: {report / 'report.md'}")


if __name__ == "__main__":
    main()
