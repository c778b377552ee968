"""Issue 19's competence targets for the highway-env scenarios, measured: one named training recipe,
3 training seeds, >= 100 episodes of the scenario's fixed evaluation set per seed.

    nice -n 10 env OMP_NUM_THREADS=1 NUMBA_NUM_THREADS=1 \\
        .venv/bin/python benchmarks/highway_competence.py [--env highway] [--recipe NAME] \\
        [--seeds 0,1,2] [--episodes 100] [--steps N]

Targets (issue 19), on the evaluation metric (never the training reward):

- highway (regular traffic): crash rate <= 5 % at mean speed >= 25 m/s;
- merge, roundabout, intersection: crash rate <= 5 % and success rate >= 90 %.

Each seed is trained with ``drivelab train`` (the recipe's arguments, ``--seed S``) into the
git-ignored ``benchmarks/runs/competence-<env>-<recipe>-s<seed>`` and evaluated with ``drivelab
evaluate RUN --episodes N`` (the scenario's evaluation set: the same episodes for every run, none
of them a training episode). A run with its final model is not trained again, one stopped with
only a checkpoint is continued (``drivelab train --resume``), and an ``eval.json`` of the same
number of episodes is reused: a stopped benchmark continues where it was.

Intervals (90 %): the crash and success rates pooled over every seed's episodes (Wilson score
interval, as benchmarks/town_competence.py); the mean speed (the mean over episodes of each
episode's mean speed) by a two-level percentile bootstrap, seeds resampled and then each drawn
seed's episodes, so that the spread between seeds counts, not only the spread between episodes
(with one seed it is the episodes' bootstrap); and each metric's mean over seeds (percentile
bootstrap over the seeds, ``drivelab.training.stats.bootstrap_ci``). Verdict: **met** only when
every interval clears its target (the crash interval's upper end <= 5 %, the speed interval's lower
end >= 25 m/s, the success interval's lower end >= 90 %); **not met** when an interval lies wholly
on the wrong side; otherwise **undecided**. Writes ``benchmarks/results/<env>_competence.json``
and ``.md``.
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

import numpy as np
from scipy.stats import binomtest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from drivelab.training.stats import bootstrap_ci  # noqa: E402

sys.path.insert(0, str(Path(__file__).parent))
from leaderboard import UNTUNED_PPO  # noqa: E402
from provenance import Parser, check_reuse, cpu_isa, readable, whole, wholes  # noqa: E402

RUNS = ROOT / "benchmarks" / "runs"
RESULTS = ROOT / "benchmarks" / "results"
CONFIDENCE = 0.90
RESAMPLES = 10_000

# Per scenario: (metric, "max" or "min", threshold). Crash and success are rates, speed in m/s.
TARGETS: dict[str, list[tuple[str, str, float]]] = {
    "highway": [("crash_rate", "max", 0.05), ("mean_speed_mps", "min", 25.0)],
    "merge": [("crash_rate", "max", 0.05), ("success_rate", "min", 0.90)],
    "roundabout": [("crash_rate", "max", 0.05), ("success_rate", "min", 0.90)],
    "intersection": [("crash_rate", "max", 0.05), ("success_rate", "min", 0.90)],
}
COMMON = ["--obs", "kinematics", "--action", "meta", "--traffic", "regular", "--eval-episodes", "10"]
# highway-env's documented PPO values, pinned: these recipes were trained before drivelab's tuned
# values became the scenario entries of drivelab/hyperparams/ppo.yaml (leaderboard.py's UNTUNED_PPO)
UNTUNED = shlex.split(UNTUNED_PPO)
# Training recipes: the arguments of ``drivelab train`` after ``--env ENV`` (the script adds
# --steps, --eval-every, --seed, --runs-dir and --name). ``steps`` is the recipe's budget.
RECIPES: dict[str, dict] = {
    "ppo-default": {  # highway-env's documented PPO values, highway's reward: the first highway-ppo
        "steps": 100_000,
        "train": ["--algo", "ppo", *COMMON, "--reward", "highway", "--n-envs", "16", *UNTUNED, "-H",
                  "gamma=0.8"],
    },
    "ppo-fast": {  # the best of the seed-0 screen (benchmarks/results/highway_competence.md)
        "steps": 500_000,
        "train": ["--algo", "ppo", *COMMON, "--reward", "highway_fast", "--n-envs", "16", *UNTUNED, "-H",
                  "gamma=0.95"],
    },
}  # fmt: skip


def train_arguments(env: str, recipe: str, steps: int, seed: int, name: str) -> list[str]:
    return [
        "train", "--env", env, *RECIPES[recipe]["train"], "--steps", str(steps),
        "--eval-every", str(max(steps // 2, 1)), "--seed", str(seed),
        "--runs-dir", "benchmarks/runs", "--name", name,
    ]  # fmt: skip


def run(arguments: list[str]) -> dict[str, float]:
    """Run a drivelab command with one thread; its wall and CPU seconds."""
    print("$ drivelab " + shlex.join(arguments), flush=True)
    before, start = os.times(), time.perf_counter()
    env = {**os.environ, "OMP_NUM_THREADS": "1", "NUMBA_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}
    subprocess.run([sys.executable, "-m", "drivelab.cli", *arguments], check=True, env=env, cwd=ROOT)
    after = os.times()
    cpu = (after.children_user - before.children_user) + (after.children_system - before.children_system)
    return {"wall_s": time.perf_counter() - start, "cpu_s": cpu}


def add(timings: dict, key: str, timing: dict[str, float]) -> None:
    """Accumulate ``timing`` under ``key`` (a resumed training adds to the first part)."""
    old = timings.get(key, {"wall_s": 0.0, "cpu_s": 0.0})
    timings[key] = {k: old[k] + timing[k] for k in ("wall_s", "cpu_s")}


def measure(env: str, recipe: str, seed: int, steps: int, episodes: int) -> dict:
    """Train (unless done) and evaluate (unless done) one seed; its record with every episode."""
    name = f"competence-{env}-{recipe}-s{seed}"
    run_dir = RUNS / name
    train = train_arguments(env, recipe, steps, seed, name)
    evaluate = ["evaluate", f"benchmarks/runs/{name}", "--episodes", str(episodes)]
    timing_file = run_dir / "competence_timing.json"
    timings = json.loads(timing_file.read_text()) if timing_file.is_file() else {}
    if (run_dir / "config.yaml").is_file():
        check_reuse(run_dir, train, ROOT)
    if not (run_dir / "model.zip").is_file():
        if run_dir.is_dir():  # stopped: continue from its last checkpoint
            add(timings, "train", run(["train", "--resume", f"benchmarks/runs/{name}"]))
        else:
            add(timings, "train", run(train))
        timing_file.write_text(json.dumps(timings))
    report_file = run_dir / "eval.json"
    if not report_file.is_file() or json.loads(report_file.read_text())["episodes"] != episodes:
        timings["evaluate"] = run(evaluate)
        timing_file.write_text(json.dumps(timings))
    report = json.loads(report_file.read_text())
    per_episode = report.pop("per_episode")
    report.pop("run", None)
    return {
        "recipe": recipe, "seed": seed, "steps": steps, "timings": timings,
        "commands": ["drivelab " + shlex.join(train), "drivelab " + shlex.join(evaluate)],
        "metrics": report,
        "episodes": {
            "crashed": [int(e["crashed"]) for e in per_episode],
            "success": [int(e["success"]) for e in per_episode],
            "mean_speed_mps": [float(e["mean_speed_mps"]) for e in per_episode],
        },
    }  # fmt: skip


def wilson(successes: int, trials: int) -> tuple[float, float]:
    interval = binomtest(successes, trials).proportion_ci(confidence_level=CONFIDENCE, method="wilson")
    return float(interval.low), float(interval.high)


def nested_bootstrap(groups: list[list[float]], seed: int = 0) -> tuple[float, float]:
    """Percentile interval of the pooled mean: draw the groups (seeds) with replacement, then within
    each drawn group its values (episodes) with replacement; one group: the values' bootstrap."""
    rng = np.random.default_rng(seed)
    arrays = [np.asarray(g, dtype=float) for g in groups]
    means = np.empty(RESAMPLES)
    for r in range(RESAMPLES):
        picks = rng.integers(len(arrays), size=len(arrays)) if len(arrays) > 1 else [0]
        drawn = [arrays[i][rng.integers(arrays[i].size, size=arrays[i].size)] for i in picks]
        means[r] = np.concatenate(drawn).mean()
    tail = (1 - CONFIDENCE) / 2 * 100
    low, high = np.percentile(means, [tail, 100 - tail])
    return float(low), float(high)


def verdict(direction: str, threshold: float, low: float, high: float) -> str:
    if direction == "max":
        return "met" if high <= threshold else ("not met" if low > threshold else "undecided")
    return "met" if low >= threshold else ("not met" if high < threshold else "undecided")


def summarise(env: str, records: list[dict]) -> dict:
    """Pooled values, intervals and verdicts of the target metrics (plus the other metrics' means)."""
    rows = {}
    for metric, direction, threshold in TARGETS[env]:
        per_seed = [r["metrics"][metric] for r in records]
        if metric == "mean_speed_mps":
            groups = [r["episodes"]["mean_speed_mps"] for r in records]
            pooled = float(np.mean(np.concatenate(groups)))
            low, high = nested_bootstrap(groups)
            method = "bootstrap over seeds then episodes"
        else:
            key = "crashed" if metric == "crash_rate" else "success"
            hits = sum(sum(r["episodes"][key]) for r in records)
            trials = sum(len(r["episodes"][key]) for r in records)
            pooled, (low, high) = hits / trials, wilson(hits, trials)
            method = "Wilson, pooled episodes"
        seeds_ci = bootstrap_ci(per_seed) if len(per_seed) > 1 else (per_seed[0], per_seed[0])
        rows[metric] = {
            "per_seed": per_seed, "pooled": pooled, "ci90": [low, high], "interval": method,
            "mean_over_seeds_ci90": [float(seeds_ci[0]), float(seeds_ci[1])],
            "target": {"direction": direction, "threshold": threshold},
            "verdict": verdict(direction, threshold, low, high),
        }  # fmt: skip
    verdicts = [row["verdict"] for row in rows.values()]
    overall = "not met" if "not met" in verdicts else "undecided"
    overall = "met" if all(v == "met" for v in verdicts) else overall
    others = ("success_rate", "crash_rate", "mean_speed_mps", "mean_return", "mean_distance_km")
    others += ("mean_length",)
    return {
        "seeds": [r["seed"] for r in records],
        "episodes": sum(len(r["episodes"]["crashed"]) for r in records),
        "targets": rows,
        "verdict": overall,
        "per_seed_metrics": {key: [r["metrics"][key] for r in records] for key in others},
    }


def markdown(result: dict) -> str:
    summary, env = result["summary"], result["env"]
    pct = lambda metric: metric.endswith("_rate")  # noqa: E731
    fmt = lambda metric, v: f"{100 * v:.1f} %" if pct(metric) else f"{v:.2f}"  # noqa: E731
    lines = [
        f"# {env.capitalize()} competence (issue 19): recipe `{result['recipe']}`",
        "",
        f"Command: `{result['script']}`  ",
        f"Machine: {result['machine']}; {result['date']}. Seeds {summary['seeds']}, each "
        f"{result['steps']:,} training steps and {result['episodes']} episodes of the fixed evaluation "
        f"set ({summary['episodes']} episodes pooled).",
        "",
        f"Recipe: `drivelab train --env {env} {shlex.join(RECIPES[result['recipe']]['train'])}`",
        "",
        "Verdict per target: **met** when its 90 % interval lies wholly on the target's side, **not met**",
        "when it lies wholly on the other side, **undecided** when it straddles the target.",
        "",
        "| metric | target | per seed | pooled [90 % interval] | interval | mean over seeds [90 %] "
        "| verdict |",
        "|---|---|---|---|---|---|---|",
    ]
    for metric, row in summary["targets"].items():
        per_seed = " / ".join(fmt(metric, v) for v in row["per_seed"])
        low, high = row["ci90"]
        mlow, mhigh = row["mean_over_seeds_ci90"]
        lines.append(
            f"| {metric} | {'≤' if row['target']['direction'] == 'max' else '≥'} "
            f"{fmt(metric, row['target']['threshold'])} | {per_seed} | {fmt(metric, row['pooled'])} "
            f"[{fmt(metric, low)}, {fmt(metric, high)}] | {row['interval']} "
            f"| [{fmt(metric, mlow)}, {fmt(metric, mhigh)}] | {row['verdict']} |"
        )
    lines += ["", f"**Overall: {summary['verdict']}.**", "", "Other metrics per seed:", ""]
    for key, values in summary["per_seed_metrics"].items():
        lines.append(f"- {key}: " + " / ".join(fmt(key, v) for v in values))
    lines += ["", "Commands and times (wall / CPU s, one thread, machine shared):", ""]
    for record in result["records"]:
        times = ", ".join(f"{k} {v['wall_s']:.0f} / {v['cpu_s']:.0f}" for k, v in record["timings"].items())
        lines.append(f"- seed {record['seed']} ({times}):")
        lines += [f"  - `{command}`" for command in record["commands"]]
    if result.get("notes"):
        lines += ["", result["notes"].rstrip("\n")]
    return "\n".join(lines) + "\n"


def main() -> None:
    parser = Parser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--env", choices=list(TARGETS), default="highway", help="scenario")
    parser.add_argument("--recipe", choices=list(RECIPES), default="ppo-default", help="training recipe")
    parser.add_argument("--seeds", type=wholes(), default="0,1,2", help="training seeds, comma-separated")
    parser.add_argument("--episodes", type=whole(), default=100, help="evaluation episodes per seed")
    parser.add_argument("--steps", type=whole(0), default=0, help="training steps (0: the recipe's budget)")
    parser.add_argument("--notes", type=readable, default=None, help="a Markdown file appended as notes")
    args = parser.parse_args()
    seeds, notes = args.seeds, args.notes or ""
    steps = args.steps or RECIPES[args.recipe]["steps"]
    records = [measure(args.env, args.recipe, seed, steps, args.episodes) for seed in seeds]
    result = {
        "script": "python benchmarks/highway_competence.py " + shlex.join(sys.argv[1:]),
        "machine": f"{cpu_isa()}, {os.cpu_count()} cores (shared), "
        f"Python {platform.python_version()}",
        "date": time.strftime("%Y-%m-%d"),
        "env": args.env,
        "recipe": args.recipe,
        "recipe_train": RECIPES[args.recipe]["train"],
        "episodes": args.episodes,
        "steps": steps,
        "notes": notes,
        "records": records,
        "summary": summarise(args.env, records),
    }
    RESULTS.mkdir(parents=True, exist_ok=True)
    (RESULTS / f"{args.env}_competence.json").write_text(json.dumps(result, indent=2))
    (RESULTS / f"{args.env}_competence.md").write_text(markdown(result))
    print((RESULTS / f"{args.env}_competence.md").read_text())


if __name__ == "__main__":
    main()
