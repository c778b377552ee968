"""NoCrash in the town: the rule-based expert and PPO (SB3) trained on the training town, both
evaluated on the test town at every traffic level (RLAD's Tables III and IV, seed 000).

    .venv/bin/python benchmarks/nocrash_town.py [--ppo-steps 40000] [--episodes 25] [--level regular]

Each agent is trained with ``drivelab train`` (the expert only drives: it learns nothing) into
``benchmarks/runs/<name>`` and evaluated with ``drivelab benchmark nocrash``; a run that already
has its model (or its ``nocrash.json`` for the same number of episodes) is reused, so the script
can assemble results of runs made earlier with the same commands. Writes
``benchmarks/results/nocrash_town.json`` and ``.md``.

PPO reads ``waypoints``, ``measurements`` and the privileged ``affordances`` (like Roach, a
privileged agent: it is told the light, the leader and pedestrians; it does not see pixels).
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

ROOT = Path(__file__).resolve().parents[1]
RUNS = ROOT / "benchmarks" / "runs"
RESULTS = ROOT / "benchmarks" / "results"
DRIVELAB = [sys.executable, "-m", "drivelab.cli"]
COMMON = ["--env", "town", "--action", "target_speed", "--seed", "0", "--runs-dir", "benchmarks/runs"]


def agents(ppo_steps: int) -> dict[str, list[str]]:
    """Run name → ``drivelab train`` arguments."""
    return {
        "expert-town": [
            "--algo", "expert", "--obs", "waypoints,affordances", "--steps", "500", "--eval-episodes", "3",
        ],
        "ppo-town": [
            "--algo", "ppo", "--obs", "waypoints,measurements,affordances", "--reward", "roach",
            "--traffic", "regular", "--steps", str(ppo_steps),
            "--eval-every", "10000", "--eval-episodes", "2",
        ],
    }  # fmt: skip


def run(arguments: list[str]) -> float:
    """Run a drivelab command (OMP_NUM_THREADS=1); its CPU seconds."""
    print("$ drivelab " + shlex.join(arguments), flush=True)
    before = os.times()
    subprocess.run(DRIVELAB + arguments, check=True, env={**os.environ, "OMP_NUM_THREADS": "1"}, cwd=ROOT)
    after = os.times()
    return (after.children_user - before.children_user) + (after.children_system - before.children_system)


def main() -> None:
    formatter = argparse.RawDescriptionHelpFormatter
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=formatter)
    parser.add_argument("--ppo-steps", type=int, default=40_000)
    parser.add_argument("--episodes", type=int, default=25)
    parser.add_argument("--level", default="regular", help="traffic level of the infraction table")
    args = parser.parse_args()

    reports, commands = {}, {}
    for name, arguments in agents(args.ppo_steps).items():
        run_dir = RUNS / name
        train = ["train", *arguments, *COMMON, "--name", name]
        evaluate = ["benchmark", "nocrash", str(run_dir.relative_to(ROOT)), "--town", "test",
                    "--episodes", str(args.episodes), "--level", args.level]  # fmt: skip
        commands[name] = ["drivelab " + shlex.join(train), "drivelab " + shlex.join(evaluate)]
        if not (run_dir / "model.zip").is_file():
            run(train)
        saved = run_dir / "nocrash.json"
        if not saved.is_file() or json.loads(saved.read_text())["episodes_per_level"] != args.episodes:
            run(evaluate)
        reports[name] = json.loads(saved.read_text())

    result = {
        "script": "python benchmarks/nocrash_town.py " + shlex.join(sys.argv[1:]),
        "machine": f"{platform.machine()}, {os.cpu_count()} cores (shared), "
        f"Python {platform.python_version()}",
        "date": time.strftime("%Y-%m-%d"),
        "commands": commands,
        "reports": reports,
    }
    RESULTS.mkdir(parents=True, exist_ok=True)
    (RESULTS / "nocrash_town.json").write_text(json.dumps(result, indent=2))
    (RESULTS / "nocrash_town.md").write_text(markdown(result))
    print((RESULTS / "nocrash_town.md").read_text())


def _percent(value) -> str:
    return "n/a" if value is None else f"{100 * value:.0f}"


def _number(value) -> str:
    return "n/a" if value is None else f"{value:.2f}"


def _success(report: dict, level: str) -> str:
    return _percent(report["levels"][level]["success_rate"])


def markdown(result: dict) -> str:
    """Table III (success per level, one column per agent) and Table IV (one row per agent)."""
    from drivelab.training.nocrash import INFRACTIONS, LEVELS

    reports = result["reports"]
    names = list(reports)
    any_report = reports[names[0]]
    lines = [
        "# NoCrash in the test town: the rule-based expert and PPO",
        "",
        f"Machine: {result['machine']}; {result['date']}. Reproduce with `{result['script']}`, which runs:",
        "",
        *[f"- `{command}`" for name in names for command in result["commands"][name]],
        "",
        f"{any_report['episodes_per_level']} episodes per traffic level on the test town's 25 fixed routes "
        "(the same seeds for every agent); success = reaching the target within the route's time limit "
        "without a collision, a red light run, being blocked or leaving the route.",
        "",
        "## Success % per traffic level (RLAD's Table III)",
        "",
        "| traffic | " + " | ".join(names) + " |",
        "|---|" + "---|" * len(names),
        *[f"| {level} | {' | '.join(_success(reports[n], level) for n in names)} |" for level in LEVELS],
        "",
        f"## Infractions, {any_report['infraction_level']} traffic (RLAD's Table IV)",
        "",
        "| agent | " + " | ".join(label for label, _ in INFRACTIONS) + " |",
        "|---|" + "---|" * len(INFRACTIONS),
    ]
    for name in names:
        row = reports[name]["levels"][reports[name]["infraction_level"]]
        cells = [(_percent if label.endswith("%") else _number)(row[key]) for label, key in INFRACTIONS]
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    main()
