"""Issue 19's town competence targets, measured: DAgger learners of the rule-based expert on the
test town's NoCrash protocol, 3 training seeds, >= 100 episodes per traffic level.

    nice -n 10 env OMP_NUM_THREADS=1 NUMBA_NUM_THREADS=1 \\
        .venv/bin/python benchmarks/town_competence.py [--seeds 0,1,2] [--episodes 100] [--notes FILE]

Two learners, each trained with ``drivelab train --algo dagger`` (the recipe of the shipped
``town-dagger`` agents) into ``benchmarks/runs/competence-<learner>-s<seed>`` and evaluated with
``drivelab benchmark nocrash --town test``:

- ``privileged``: waypoints + measurements + affordances (target 90 / 75 / 60 % empty / regular / dense);
- ``image``: top-down image with the lights + waypoints + measurements, no affordances (target
  70 / 50 / 35 %).

A run with its model (and its ``nocrash.json`` for the same number of episodes) is reused, so a
stopped benchmark continues where it was (a run without its model is resumed from its last
checkpoint; its training time then goes unrecorded). Intervals (90 %): the pooled success rate over every
seed's episodes (Wilson), and the mean over seeds (percentile bootstrap, as ``drivelab compare``).
Writes ``benchmarks/results/town_competence.json`` and ``.md``.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import shlex
import subprocess
import sys
import time
from pathlib import Path

from scipy.stats import binomtest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from drivelab.training.nocrash import LEVELS  # noqa: E402
from drivelab.training.stats import bootstrap_ci  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from provenance import Parser, check_reuse, cpu_isa, names, readable, training_command, whole, wholes  # noqa: E402

RUNS = ROOT / "benchmarks" / "runs"
RESULTS = ROOT / "benchmarks" / "results"
# (observation, demonstration steps, success targets) per learner. The recipe was chosen by the
# one-seed screen in benchmarks/results/town_competence.notes.md: demonstrations in dense traffic
# (more interactions to label than regular), 5 k-step rounds, 3 passes over the aggregate per
# round; 100 k steps for the privileged learner (300 k did no better), 50 k for the image learner
# (each round retrains on the whole aggregate, so its CNN's cost grows with the square of the steps)
LEARNERS = {
    "privileged": (
        "waypoints,measurements,affordances",
        100_000,
        {"empty": 0.90, "regular": 0.75, "dense": 0.60},
    ),
    "image": (
        "topdown:lights=true,waypoints,measurements",
        50_000,
        {"empty": 0.70, "regular": 0.50, "dense": 0.35},
    ),
}


def recipe(learner: str) -> str:
    """The learner's ``drivelab train`` arguments, without ``--seed``, ``--runs-dir`` and ``--name``
    (also the leaderboard's and the shipped ``town-dagger`` agents')."""
    obs, steps, _ = LEARNERS[learner]
    return (
        f"--algo dagger --env town --action target_speed --traffic dense --steps {steps} --n-envs 8 "
        f"--eval-every {steps // 2} --eval-episodes 2 -H round_steps=5000 -H epochs=3 -H beta_decay=0.5 "
        f"--obs {obs}"
    )


def train_arguments(learner: str, seed: int, name: str) -> list[str]:
    where = ["--seed", str(seed), "--runs-dir", "benchmarks/runs", "--name", name]
    return ["train", *shlex.split(recipe(learner)), *where]


def run(arguments: list[str]) -> dict[str, float]:
    """Run a drivelab command; its wall and CPU seconds."""
    print("$ drivelab " + shlex.join(arguments), flush=True)
    before, start = os.times(), time.perf_counter()
    env = {**os.environ, "OMP_NUM_THREADS": "1", "NUMBA_NUM_THREADS": "1"}
    subprocess.run([sys.executable, "-m", "drivelab.cli", *arguments], check=True, env=env, cwd=ROOT)
    after = os.times()
    cpu = (after.children_user - before.children_user) + (after.children_system - before.children_system)
    return {"wall_s": time.perf_counter() - start, "cpu_s": cpu}


def measure(learner: str, seed: int, episodes: int) -> dict:
    """Train (unless done) and evaluate (unless done) one learner and seed; its record."""
    name = f"competence-{learner}-s{seed}"
    run_dir = RUNS / name
    train = train_arguments(learner, seed, name)
    nocrash = [
        "benchmark",
        "nocrash",
        f"benchmarks/runs/{name}",
        "--town",
        "test",
        "--episodes",
        str(episodes),
    ]
    timing_file = run_dir / "competence_timing.json"
    if (run_dir / "config.yaml").is_file():
        check_reuse(run_dir, train, ROOT)
    if not (run_dir / "model.zip").is_file():
        command, resumed = training_command(run_dir, train, ROOT)
        timing = run(command)  # drivelab train makes the run directory
        timing_file.write_text(json.dumps({} if resumed else {"train": timing}))  # resumed: the last part's
    timings = json.loads(timing_file.read_text()) if timing_file.is_file() else {}
    report_file = run_dir / "nocrash.json"
    if not report_file.is_file() or json.loads(report_file.read_text())["episodes_per_level"] != episodes:
        timings["nocrash"] = run(nocrash)
        timing_file.write_text(json.dumps(timings))
    report = json.loads(report_file.read_text())
    return {
        "learner": learner, "seed": seed, "timings": timings,
        "commands": ["drivelab " + shlex.join(train), "drivelab " + shlex.join(nocrash)],
        "success": {level: report["levels"][level]["success_rate"] for level in LEVELS},
        "crash": {level: report["levels"][level]["crash_rate"] for level in LEVELS},
        "episodes": {level: report["levels"][level]["episodes"] for level in LEVELS},
    }  # fmt: skip


def summarise(records: list[dict]) -> dict:
    """Per learner and level: per-seed success, pooled rate with its Wilson interval, the mean
    over seeds with its bootstrap interval, and whether the target is met (the pooled interval's
    lower end at or above it: met; its upper end below: not met; else undecided)."""
    summary = {}
    for learner, (_, _, targets) in LEARNERS.items():
        mine = [r for r in records if r["learner"] == learner]
        if not mine:
            continue
        levels = {}
        for level in LEVELS:
            rates = [r["success"][level] for r in mine]
            n = [r["episodes"][level] for r in mine]
            wins = int(round(sum(rate * count for rate, count in zip(rates, n, strict=True))))
            interval = binomtest(wins, sum(n)).proportion_ci(confidence_level=0.9, method="wilson")
            low, high = float(interval.low), float(interval.high)
            verdict = (
                "met" if low >= targets[level] else ("not met" if high < targets[level] else "undecided")
            )
            seeds_ci = bootstrap_ci(rates) if len(rates) > 1 else (rates[0], rates[0])
            levels[level] = {
                "per_seed": rates, "pooled": wins / sum(n), "pooled_ci90": [low, high],
                "mean_over_seeds_ci90": [float(seeds_ci[0]), float(seeds_ci[1])],
                "crash_per_seed": [r["crash"][level] for r in mine],
                "target": targets[level], "verdict": verdict,
            }  # fmt: skip
        summary[learner] = {"seeds": [r["seed"] for r in mine], "levels": levels}
    return summary


def markdown(result: dict) -> str:
    lines = [
        "# Town competence (issue 19): DAgger learners on NoCrash, test town",
        "",
        f"Command: `{result['script']}`  ",
        f"Machine: {result['machine']}; {result['date']}. Each seed: {result['episodes']} NoCrash "
        "episodes per traffic level; the training and NoCrash commands of each are listed below.",
        "",
        "Verdict: **met** when the pooled success rate's 90 % Wilson interval lies at or above the target,",
        "**not met** when it lies below, **undecided** when it straddles it.",
        "",
        "| learner | level | target % | success % per seed | pooled % [90 % interval] "
        "| mean over seeds [90 %] | crash % per seed | verdict |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for learner, summary in result["summary"].items():
        for level, row in summary["levels"].items():
            per_seed = " / ".join(f"{100 * v:.0f}" for v in row["per_seed"])
            crash = " / ".join(f"{100 * v:.0f}" for v in row["crash_per_seed"])
            low, high = row["pooled_ci90"]
            mlow, mhigh = row["mean_over_seeds_ci90"]
            lines.append(
                f"| {learner} | {level} | {100 * row['target']:.0f} | {per_seed} | {100 * row['pooled']:.1f} "
                f"[{100 * low:.1f}, {100 * high:.1f}] | [{100 * mlow:.1f}, {100 * mhigh:.1f}] | {crash} "
                f"| {row['verdict']} |"
            )
    lines += ["", "Commands and times (wall / CPU s):", ""]
    for record in result["records"]:
        times = ", ".join(f"{k} {v['wall_s']:.0f} / {v['cpu_s']:.0f}" for k, v in record["timings"].items())
        lines.append(f"- {record['learner']} seed {record['seed']} ({times}):")
        lines += [f"  - `{command}`" for command in record["commands"]]
    if result.get("notes"):
        lines += ["", result["notes"].rstrip("\n")]
    return "\n".join(lines) + "\n"


def main() -> None:
    parser = Parser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seeds", type=wholes(), default="0,1,2", help="training seeds, comma-separated")
    parser.add_argument("--episodes", type=whole(), default=100, help="NoCrash episodes per traffic level")
    parser.add_argument(
        "--learners", type=names(LEARNERS), default=",".join(LEARNERS), help="which learners, comma-separated"
    )
    parser.add_argument("--notes", type=readable, default=None, help="a Markdown file appended as notes")
    args = parser.parse_args()
    seeds, learners, notes = args.seeds, args.learners, args.notes or ""

    records = [measure(learner, seed, args.episodes) for learner in learners for seed in seeds]
    result = {
        "script": "python benchmarks/town_competence.py " + shlex.join(sys.argv[1:]),
        "machine": f"{cpu_isa()}, {os.cpu_count()} cores (shared), "
        f"Python {platform.python_version()}",
        "date": time.strftime("%Y-%m-%d"),
        "episodes": args.episodes,
        "recipes": {learner: recipe(learner) for learner in learners},
        "notes": notes,
        "records": records,
        "summary": summarise(records),
    }
    RESULTS.mkdir(parents=True, exist_ok=True)
    (RESULTS / "town_competence.json").write_text(json.dumps(result, indent=2))
    (RESULTS / "town_competence.md").write_text(markdown(result))
    print((RESULTS / "town_competence.md").read_text())


if __name__ == "__main__":
    main()
