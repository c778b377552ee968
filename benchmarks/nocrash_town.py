"""NoCrash in the town: the rule-based expert and PPO (SB3) trained on the training town, both
evaluated on the test town at every traffic level (RLAD's Tables III and IV, seed 000).

    .venv/bin/python benchmarks/nocrash_town.py [--ppo-steps 1000000] [--n-envs 32] [--episodes 25]
        [--level regular]

Each agent is trained with ``drivelab train`` (the expert only drives: it learns nothing) into
``benchmarks/runs/<name>`` and evaluated with ``drivelab benchmark nocrash``; a run that already
has its model (or its ``nocrash.json`` for the same number of episodes) is reused, so the script
can assemble results of runs made earlier with the same commands; a run a kill left without its
model is resumed from its last checkpoint (its training time then goes unrecorded). Writes
``benchmarks/results/nocrash_town.json`` and ``.md``.

PPO reads ``waypoints``, ``measurements`` and the privileged ``affordances`` (like Roach, a
privileged agent: it is told the light, the leader and pedestrians; it does not see pixels). It
trains on ``--n-envs`` town worlds stepped together on the compiled core (SB3's rollouts of all
worlds at once), with minibatches of 256 (the rollouts are ``n_envs`` times larger than SB3's
single-world default of 64 was chosen for). The training's wall time is reported.
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

sys.path.insert(0, str(Path(__file__).resolve().parent))
from provenance import Parser, check_reuse, cpu_isa, training_command, whole  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
RUNS = ROOT / "benchmarks" / "runs"
RESULTS = ROOT / "benchmarks" / "results"
DRIVELAB = [sys.executable, "-m", "drivelab.cli"]
SCENARIO = ["--env", "town", "--action", "target_speed"]
COMMON = [*SCENARIO, "--seed", "0", "--runs-dir", "benchmarks/runs"]
PPO_STEPS, N_ENVS = 1_000_000, 32  # the committed runs' (also the leaderboard's town rows)


def agents(ppo_steps: int = PPO_STEPS, n_envs: int = N_ENVS) -> dict[str, list[str]]:
    """Run name → ``drivelab train`` arguments, without ``COMMON`` and ``--name``."""
    return {
        "expert-town": [
            "--algo", "expert", "--obs", "waypoints,affordances", "--steps", "500", "--eval-episodes", "3",
        ],
        "ppo-town": [
            "--algo", "ppo", "--obs", "waypoints,measurements,affordances", "--reward", "roach",
            "--traffic", "regular", "--steps", str(ppo_steps), "--n-envs", str(n_envs),
            "-H", "batch_size=256",
            "--eval-every", str(min(ppo_steps, max(10_000, ppo_steps // 10))), "--eval-episodes", "2",
        ],
    }  # fmt: skip


def run(arguments: list[str]) -> tuple[float, float]:
    """Run a drivelab command (OMP_NUM_THREADS=1); its (wall, CPU) seconds."""
    print("$ drivelab " + shlex.join(arguments), flush=True)
    before, start = os.times(), time.perf_counter()
    subprocess.run(DRIVELAB + arguments, check=True, env={**os.environ, "OMP_NUM_THREADS": "1"}, cwd=ROOT)
    after = os.times()
    cpu = (after.children_user - before.children_user) + (after.children_system - before.children_system)
    return time.perf_counter() - start, cpu


def train_and_nocrash(run_dir: Path, train: list[str], evaluate: list[str], episodes: int):
    """Bring the run in ``run_dir`` to its end with ``drivelab TRAIN`` (a finished run of the same
    config is reused; one a kill left is resumed), then its NoCrash report with ``drivelab
    EVALUATE`` unless ``nocrash.json`` already holds ``episodes`` per level. Returns (the report,
    the training's wall and CPU seconds, or None when unknown: a reused run without them, a resumed
    one)."""
    timing = None
    if (run_dir / "config.yaml").is_file():
        check_reuse(run_dir, train, ROOT)
    if not (run_dir / "model.zip").is_file():
        command, resumed = training_command(run_dir, train, ROOT)
        wall, cpu = run(command)
        if not resumed:  # a resumed run's time is its last part's only
            timing = {"train_wall_s": wall, "train_cpu_s": cpu}
            (run_dir / "train_timing.json").write_text(json.dumps(timing))
    elif (run_dir / "train_timing.json").is_file():
        timing = json.loads((run_dir / "train_timing.json").read_text())
    saved = run_dir / "nocrash.json"
    if not saved.is_file() or json.loads(saved.read_text())["episodes_per_level"] != episodes:
        run(evaluate)
    return json.loads(saved.read_text()), timing


def main() -> None:
    formatter = argparse.RawDescriptionHelpFormatter
    parser = Parser(description=__doc__, formatter_class=formatter)
    parser.add_argument("--ppo-steps", type=whole(), default=PPO_STEPS)
    parser.add_argument("--n-envs", type=whole(), default=N_ENVS, help="town worlds PPO trains on together")
    parser.add_argument("--episodes", type=whole(), default=25)
    parser.add_argument(
        "--level",
        choices=("empty", "regular", "dense"),
        default="regular",
        help="traffic level of the infraction table",
    )
    args = parser.parse_args()

    reports, commands, timings = {}, {}, {}
    for name, arguments in agents(args.ppo_steps, args.n_envs).items():
        run_dir = RUNS / name
        train = ["train", *arguments, *COMMON, "--name", name]
        evaluate = ["benchmark", "nocrash", str(run_dir.relative_to(ROOT)), "--town", "test",
                    "--episodes", str(args.episodes), "--level", args.level]  # fmt: skip
        commands[name] = ["drivelab " + shlex.join(train), "drivelab " + shlex.join(evaluate)]
        reports[name], timing = train_and_nocrash(run_dir, train, evaluate, args.episodes)
        if timing is not None:
            timings[name] = timing

    result = {
        "script": "python benchmarks/nocrash_town.py " + shlex.join(sys.argv[1:]),
        "machine": f"{cpu_isa()}, {os.cpu_count()} cores (shared), "
        f"Python {platform.python_version()}",
        "date": time.strftime("%Y-%m-%d"),
        "commands": commands,
        "timings": timings,
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
        *[
            f"Training {name}: {t['train_wall_s'] / 60:.1f} min wall, {t['train_cpu_s'] / 60:.1f} min CPU."
            for name, t in result.get("timings", {}).items()
        ],
        "",
        f"{any_report['episodes_per_level']} episodes per traffic level on the test town's 25 fixed routes "
        "(the same seeds for every agent); success = reaching the target within the route's time limit "
        "with no collision, the arrival step included (seed 000: routes completed without collision). "
        "A red light run, being blocked or leaving the route ends the episode short of the target; "
        "on the arrival step itself they are infractions only.",
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
