"""What limits the intersection: fixed longitudinal plans on its 100 fixed evaluation episodes, on
drivelab's compiled core and on highway-env's own Python simulation.

    nice -n 10 env OMP_NUM_THREADS=1 NUMBA_NUM_THREADS=1 \\
        .venv/bin/python benchmarks/intersection_probe.py [--episodes 100] [--backends fast,highway]

Every learner on the intersection so far (PPO, 24 tuning trials, 15 observed vehicles,
highway-env's three longitudinal meta-actions) drives through at full speed. The plans here need
no learning: hold the top speed throughout, brake for W seconds first and then go, or brake
throughout, with highway-env's intersection action space (``DiscreteMetaAction`` without lane
changes: slower, idle, faster; one decision a second) and its 13 s episodes. Success is arriving
at the exit, crash any collision: the evaluation metric of the leaderboard. Writes
``benchmarks/results/intersection_probe.{json,md}``.
"""

from __future__ import annotations

import json
import os
import platform
import shlex
import sys
import time
from pathlib import Path

from scipy.stats import binomtest

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import drivelab  # noqa: E402
from drivelab.training.seeds import evaluation_seeds  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from provenance import Parser, cpu_isa, names, whole  # noqa: E402

RESULTS = ROOT / "benchmarks" / "results"
SLOWER, IDLE, FASTER = 0, 1, 2  # highway-env's ACTIONS_LONGI
# plan: seconds of braking before going at full speed (13: the whole episode)
PLANS = {
    "full speed throughout": 0,
    "brake 2 s, then go": 2,
    "brake 4 s, then go": 4,
    "brake 6 s, then go": 6,
    "brake throughout": 13,
}


def play(backend: str, brake_s: int, episodes: int) -> dict:
    """Success and crash counts of one plan over the first ``episodes`` evaluation episodes."""
    env = drivelab.make(
        "intersection", obs="kinematics", action="meta", action_options={"lateral": False}, backend=backend
    )
    arrived = crashed = 0
    for seed in evaluation_seeds(episodes):
        env.reset(seed=int(seed))
        step, done = 0, False
        while not done:
            _, _, terminated, truncated, info = env.step(SLOWER if step < brake_s else FASTER)
            step, done = step + 1, terminated or truncated
        metrics = info["episode_metrics"]
        arrived += int(metrics["success"] > 0)
        crashed += int(metrics["collisions"] > 0)
    return {"episodes": episodes, "success": arrived, "crash": crashed}


def wilson_text(count: int, n: int) -> str:
    """A rate ``count`` / ``n`` in % with its 90 % Wilson interval: ``42 [34, 50]``."""
    interval = binomtest(count, n).proportion_ci(confidence_level=0.9, method="wilson")
    return f"{100 * count / n:.0f} [{100 * interval.low:.0f}, {100 * interval.high:.0f}]"


def header(title: str, result: dict) -> list[str]:
    """A probe's results file's first lines: its title, command, machine and date."""
    return [
        f"# {title}",
        "",
        f"Command: `{result['command']}`  ",
        f"Machine: {result['machine']}; {result['date']}.",
        "",
    ]


def markdown(result: dict) -> str:
    lines = [
        *header("Intersection: fixed plans on the 100 evaluation episodes", result),
        "Action space: highway-env's intersection meta-actions (slower, idle, faster), one a second, 13 s",
        "episodes, regular traffic. Rates in %, with their 90 % Wilson interval.",
        "",
        "| plan | backend | success % | crash % |",
        "|---|---|---|---|",
    ]
    for row in result["rows"]:
        n = row["episodes"]
        lines.append(
            f"| {row['plan']} | {row['backend']} | {wilson_text(row['success'], n)} | "
            f"{wilson_text(row['crash'], n)} |"
        )
    return "\n".join(lines) + "\n"


def run_probe(name: str, description: str, plans: dict, play, markdown, backends: str) -> None:
    """A probe's command line: ``--episodes`` and ``--backends`` (default ``backends``), every
    plan's value played on every backend (``play(backend, value, episodes)`` → its counts), the
    rows written to ``benchmarks/results/<name>.{json,md}``; bad input: one ``error:`` line, exit 2."""
    parser = Parser(description=description)
    parser.add_argument("--episodes", type=whole(), default=100)
    parser.add_argument(
        "--backends",
        type=names(("fast", "highway")),
        default=backends,
        help="fast (compiled core), highway (highway-env)",
    )
    args = parser.parse_args()
    chosen = args.backends
    rows = []
    for plan, value in plans.items():
        for backend in chosen:
            rows.append({"plan": plan, "backend": backend, **play(backend, value, args.episodes)})
            print(rows[-1], flush=True)
    result = {
        "command": (f"python benchmarks/{name}.py " + shlex.join(sys.argv[1:])).strip(),
        "machine": f"{cpu_isa()}, {os.cpu_count()} cores, Python {platform.python_version()}",
        "date": time.strftime("%Y-%m-%d"),
        "rows": rows,
    }
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / f"{name}.json").write_text(json.dumps(result, indent=1))
    (RESULTS / f"{name}.md").write_text(markdown(result))
    print(markdown(result))


if __name__ == "__main__":
    run_probe("intersection_probe", __doc__.split("\n\n")[0], PLANS, play, markdown, "fast,highway")
