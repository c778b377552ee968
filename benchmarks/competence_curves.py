"""Learning curves against wall time: the leaderboard's RL recipes that meet their scenario's target,
seed 0, judged at points along training on the scenario's fixed evaluation episodes.

    .venv/bin/python benchmarks/competence_curves.py [--rows roundabout/ppo_own,racetrack/ppo_own]
        [--points 8] [--episodes 50]

Each recipe (its ``benchmarks/leaderboard.py`` command, seed 0) is trained once, with its own
budget, in this process, and stopped after each of ``--points`` periodic evaluations (one episode,
``on_evaluation``): ``train``, then ``resume`` up to the next stop. A stopped and resumed run equals
the uninterrupted one (drivelab's resume guarantee, ``tests/training/test_resume.py``), schedules
over the budget (``linear_lr``) included, and periodic evaluations do not change training, so the
chunks are the recipe's own run (checked for the roundabout's: the final model equals the recipe's
uninterrupted run value for value). At each stop the checkpoint is evaluated (``evaluate_run``:
``--episodes`` fixed evaluation episodes; the 100 unseen maps, each once, for a row judged on them)
and the time counted is the training calls' wall time alone, one thread, the points' evaluations
excluded; a stop puts the run back to the start of the rollout its evaluation fell in, so each stop
adds one rollout's training played twice. A point "meets" the target when its rates on those
episodes are on the target's side (a point estimate; the leaderboard's verdict pools 3 seeds × 100
episodes). Writes ``benchmarks/results/competence_curves.{json,md,png}``; runs go to
``benchmarks/runs/curves/``.
"""

from __future__ import annotations

import json
import os
import shutil
import sys
import time
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("NUMBA_NUM_THREADS", "1")

sys.path.insert(0, str(Path(__file__).resolve().parent))
import leaderboard  # noqa: E402
from provenance import Parser, provenance, stop, whole  # noqa: E402

ROOT = leaderboard.ROOT
RUNS = ROOT / "benchmarks" / "runs" / "curves"
RESULTS = ROOT / "benchmarks" / "results"
ROWS = ("roundabout/ppo_own", "racetrack/ppo_own")  # the RL rows that meet their target (leaderboard.md)
# the rate each curve plots: clean laps on the racetrack (its target), success elsewhere
RATE = {"racetrack": ("lap_rate", "clean laps")}


def entry_of(row: str) -> leaderboard.Entry:
    scenario, _, name = row.partition("/")
    for entry in leaderboard.ENTRIES:
        if (entry.scenario, entry.name) == (scenario, name):
            return entry
    stop(f"no leaderboard row {row!r} (rows are SCENARIO/NAME, as in leaderboard.md)")


def meets(metrics: dict, targets: dict) -> bool:
    """Whether one evaluation's rates are on every target's side (a point estimate)."""
    return all(
        metrics[key] >= value if side == ">=" else metrics[key] <= value
        for key, (side, value) in targets.items()
    )


def chunk_steps(total: int, rollout: int, points: int) -> list[int]:
    """``points`` step counts up to ``total``, each a whole number of rollouts (the last: ``total``)."""
    steps = sorted(
        {max(rollout, round(total * (i + 1) / points / rollout) * rollout) for i in range(points - 1)}
    )
    return [s for s in steps if s < total] + [total]


def curve(entry: leaderboard.Entry, points: int, episodes: int) -> dict:
    from drivelab.cli import train_config
    from drivelab.config import build_config, steps_per_update
    from drivelab.training.evaluate import evaluate_run, report_name
    from drivelab.training.run import StoppedByEvaluation, resume, train

    run_dir = RUNS / f"{entry.scenario}-{entry.name}-s0"
    if run_dir.exists():
        shutil.rmtree(run_dir)
    os.chdir(ROOT)  # the recipe's --config paths are the repository's
    config = train_config(entry.command(0)[1:])
    total = config.steps
    rollout, _ = steps_per_update(config.algo, config.hyperparams, config.n_envs)
    every = chunk_steps(total, rollout, points)[0]
    staged = build_config({**config.to_dict(), "eval_every": every, "eval_episodes": 1, "eval_maps": None})
    maps = leaderboard.UNSEEN_MAPS if entry.judge == "maps" else None
    if maps is not None:
        episodes = int(maps.split(":")[1])  # each unseen map once, as the leaderboard judges
    key, label = RATE.get(entry.scenario, ("success_rate", "success"))
    targets = leaderboard.TARGETS.get(entry.scenario, {})
    rows, wall, steps = [], 0.0, 0
    stopped_at = [0]  # the periodic evaluation the run last stopped after

    def stop_at_new(step: int, summary: dict) -> bool:
        """Stop after an evaluation not stopped at before: a stop puts the run back to its rollout's
        start, so the resumed run plays that rollout, and its evaluation, again."""
        if step <= stopped_at[0]:
            return True
        stopped_at[0] = step
        return False

    while steps < total:
        start = time.perf_counter()
        try:
            if steps == 0:
                train(staged, RUNS, on_evaluation=stop_at_new)
            else:
                resume(run_dir, on_evaluation=stop_at_new)
            reached = total
        except StoppedByEvaluation as stopped:
            reached = stopped.steps
        wall += time.perf_counter() - start
        if reached <= steps:
            stop(f"{run_dir}: resuming at step {steps:,} stopped again there")
        steps = reached
        out = RUNS / "eval" / f"{run_dir.name}-{steps}"
        evaluate_run(run_dir, episodes=episodes, out_dir=out, maps=maps)
        metrics = leaderboard._metrics(json.loads((out / report_name(maps)).read_text()))
        point = {
            "steps": steps,
            "train_wall_s": wall,
            "rate": metrics[key],
            "crash_rate": metrics["crash_rate"],
        }
        rows.append({**point, "meets_target": meets(metrics, targets)})
        print(
            f"{entry.scenario}/{entry.name}: {steps:,} steps, {wall / 60:.2f} min: {label} "
            f"{100 * metrics[key]:.0f} %, crash {100 * metrics['crash_rate']:.0f} %",
            flush=True,
        )
    first = next((row["train_wall_s"] for row in rows if row["meets_target"]), None)
    return {"row": f"{entry.scenario}/{entry.name}", "command": "drivelab " + " ".join(entry.command(0)),
            "rate": label, "rate_key": key, "targets": targets, "episodes": episodes, "points": rows,
            "first_point_meeting_target_s": first}  # fmt: skip


def plot(curves: list[dict], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axis = plt.subplots(figsize=(7.5, 4.2))
    for record in curves:
        minutes = [p["train_wall_s"] / 60 for p in record["points"]]
        rates = [100 * p["rate"] for p in record["points"]]
        axis.plot(minutes, rates, "o-", label=f"{record['row']} ({record['rate']})")
    lines = sorted({100 * r["targets"][r["rate_key"]][1] for r in curves if r["rate_key"] in r["targets"]})
    for value in lines:
        axis.axhline(value, color="gray", ls="--", lw=1, label=f"target {value:.0f} %")
    axis.set_xlabel("training wall minutes, one thread (evaluations excluded)")
    axis.set_ylabel("% of evaluation episodes")
    axis.set_ylim(-3, 103)
    axis.legend(loc="lower right", fontsize=8)
    axis.set_title("RL from scratch, seed 0: competence against wall time", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def markdown(result: dict) -> str:
    lines = [
        "## Competence against wall time: the RL recipes that meet their target",
        "",
        f"`{result['command']}` on {result['machine']}, {result['date']}. Seed 0 of each leaderboard recipe,",
        "trained once and stopped after periodic evaluations; each stop's checkpoint evaluated on "
        f"{result['episodes']} fixed",
        "evaluation episodes (a row judged on the 100 unseen block maps: each map once); the",
        "minutes are the training calls' wall time, one thread, evaluations excluded. The leaderboard's",
        "verdict (3 seeds x 100 episodes) is the yardstick; a curve's point is one seed's estimate.",
        "",
        "![curves](competence_curves.png)",
        "",
        "| row | rate plotted | first point on the target's side (min) "
        "| points: steps, minutes, rate %, crash % |",
        "|---|---|---|---|",
    ]
    for record in result["curves"]:
        reached = record["first_point_meeting_target_s"]
        points = "; ".join(f"{p['steps']:,}, {p['train_wall_s'] / 60:.2f}, {100 * p['rate']:.0f}, "
                           f"{100 * p['crash_rate']:.0f}" for p in record["points"])  # fmt: skip
        shown = "–" if reached is None else f"{reached / 60:.2f}"
        lines.append(f"| {record['row']} | {record['rate']} | {shown} | {points} |")
    return "\n".join(lines) + "\n"


def main() -> None:
    parser = Parser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--rows", default=",".join(ROWS))
    parser.add_argument("--points", type=whole(), default=8)
    parser.add_argument("--episodes", type=whole(), default=50)
    args = parser.parse_args()
    entries = [entry_of(row) for row in args.rows.split(",")]
    curves = [curve(entry, args.points, args.episodes) for entry in entries]
    command = ("python benchmarks/competence_curves.py " + " ".join(sys.argv[1:])).strip()
    result = {**provenance(command), "episodes": args.episodes, "curves": curves}
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / "competence_curves.json").write_text(json.dumps(result, indent=1))
    plot(curves, RESULTS / "competence_curves.png")
    (RESULTS / "competence_curves.md").write_text(markdown(result))
    print(markdown(result))


if __name__ == "__main__":
    main()
