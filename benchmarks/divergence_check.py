"""Cost of the divergence check (``drivelab/training/divergence.py``) in training runs, per agent.

    .venv/bin/python benchmarks/divergence_check.py [--steps 1000] [--repeats 2] [--cases dqn,ppo,...]

For each case: the median time of one ``non_finite_weights`` over the agent's weights (200 calls
after a warm-up), and whole ``drivelab train`` runs (``run.train``, highway, fast backend, one
evaluation episode at the end) with the checks as shipped and with every check off, alternating,
``--repeats`` times. A run checks at most once per ``CHECK_EVERY_STEPS`` steps (and at evaluations
and checkpoints), so its overhead is at most check time / (``CHECK_EVERY_STEPS`` x step time); the
table gives that bound and the measured difference of the medians of whole runs (noise included:
the bound is far below it). Torch on one thread. Writes ``results/divergence_check.{json,md}``.
"""

from __future__ import annotations

import json
import os
import platform
import shutil
import sys
import tempfile
import time
from pathlib import Path

os.environ.setdefault("PYGAME_HIDE_SUPPORT_PROMPT", "1")

import numpy as np  # noqa: E402
import torch  # noqa: E402

sys.path.insert(0, str(Path(__file__).parent))
from provenance import Parser, command_line, cpu_isa, names, whole  # noqa: E402

from drivelab.agents.registry import get_algo  # noqa: E402
from drivelab.config import build_config  # noqa: E402
from drivelab.envs.core import DriveEnv  # noqa: E402
from drivelab.training import run  # noqa: E402
from drivelab.training.divergence import CHECK_EVERY_STEPS, model_weights, non_finite_weights  # noqa: E402

RESULTS = Path(__file__).parent / "results"
TOWN = {"env": "town", "action": "target_speed", "reward": "roach"}
# name -> run fields; the agents' default networks (SB3's from drivelab/hyperparams)
CASES = {
    "dqn": {"algo": "dqn", "obs": "kinematics", "action": "meta"},
    "ppo": {"algo": "ppo", "obs": "kinematics", "action": "meta"},
    "a2c": {"algo": "a2c", "obs": "kinematics", "action": "meta"},
    "sac": {"algo": "sac", "obs": "kinematics", "action": "continuous",
            "hyperparams": {"learning_starts": 200}},
    "dueling_ddqn": {"algo": "dueling_ddqn", "obs": "lidar:stack=3,ego_state:features=10:stack=3",
                     "action": "grid"},
    "ppo-cnn": {"algo": "ppo", "obs": "topdown", "action": "continuous",
                "hyperparams": {"features_extractor": "seed"}},
    "ppo_own-cnn": {"algo": "ppo_own", "obs": "topdown", "action": "continuous"},
    "a2c_own-cnn": {"algo": "a2c_own", "obs": "topdown", "action": "continuous",
                    "hyperparams": {"n_steps": 16}},
    "bc": {"algo": "bc", "obs": "waypoints,measurements", **TOWN},
    "rlad": {"algo": "rlad", "obs": ["camera", "waypoints", "measurements:stack=3"], **TOWN,
             "hyperparams": {"learning_starts": 20, "buffer_size": 2000}},
}  # fmt: skip
# (steps, repeats) at most, for cases too slow for the others' runs: RLAD's updates take about 0.4 s
# on one CPU thread
SHORT = {"rlad": (300, 1)}


def config_of(case: str, steps: int, name: str):
    values = {
        "env": "highway", "traffic": "regular", "backend": "fast", "steps": steps, "seed": 0, "name": name,
        "eval_every": steps, "eval_episodes": 1, "checkpoint_every": steps, **CASES[case],
    }  # fmt: skip
    if values["env"] == "town":
        del values["backend"]
    return build_config(values)


def check_seconds(case: str, calls: int = 200) -> tuple[float, int, int]:
    """(median seconds of one check, weight tensors, weights) of the case's fresh agent."""
    config = config_of(case, 1000, "probe")
    env = DriveEnv(**config.env_kwargs())
    agent = get_algo(config.algo).build(config.algo, env, 0, dict(config.hyperparams), None)
    weights = model_weights(agent)
    non_finite_weights(agent)
    times = []
    for _ in range(calls):
        start = time.perf_counter()
        non_finite_weights(agent)
        times.append(time.perf_counter() - start)
    env.close()
    return float(np.median(times)), len(weights), sum(tensor.numel() for _, tensor in weights)


def run_seconds(case: str, steps: int, checks: bool, root: Path) -> float:
    """Seconds of a whole run (``run.train``) with the divergence checks on or off."""
    check_weights = run.RunCallback.check_weights
    if not checks:
        run.RunCallback.check_weights = lambda callback, steps: None
    try:
        start = time.perf_counter()
        run_dir = run.train(config_of(case, steps, f"{case}-{checks}"), root)
        seconds = time.perf_counter() - start
    finally:
        run.RunCallback.check_weights = check_weights
    shutil.rmtree(run_dir)
    return seconds


def main() -> None:
    parser = Parser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=whole(CHECK_EVERY_STEPS), default=1000, help="steps of each run")
    parser.add_argument("--repeats", type=whole(), default=2)
    parser.add_argument("--cases", type=names(CASES), default=list(CASES))
    args = parser.parse_args()
    torch.set_num_threads(1)
    rows = []
    with tempfile.TemporaryDirectory(prefix="divergence-check-") as folder:
        for case in args.cases:
            check_s, tensors, weights = check_seconds(case)
            runs: dict[str, list[float]] = {"on": [], "off": []}
            run_seconds(case, CHECK_EVERY_STEPS, True, Path(folder))  # warm-up: numba, torch, caches
            most_steps, most_repeats = SHORT.get(case, (args.steps, args.repeats))
            steps, repeats = min(args.steps, most_steps), min(args.repeats, most_repeats)
            for _ in range(repeats):
                for checks in (True, False):
                    seconds = run_seconds(case, steps, checks, Path(folder))
                    runs["on" if checks else "off"].append(seconds)
            on, off = float(np.median(runs["on"])), float(np.median(runs["off"]))
            step_s = off / steps
            row = {
                "case": case, "algo": CASES[case]["algo"], "steps": steps, "repeats": repeats,
                "weight_tensors": tensors, "weights": weights,
                "check_ms": check_s * 1e3, "run_step_ms": step_s * 1e3,
                "bound_percent": 100 * check_s / (CHECK_EVERY_STEPS * step_s),
                "every_step_percent": 100 * check_s / step_s,
                "runs_on_s": runs["on"], "runs_off_s": runs["off"],
                "measured_percent": 100 * (on - off) / off,
            }  # fmt: skip
            rows.append(row)
            print(json.dumps(row), flush=True)
    result = {
        "command": command_line(),
        "machine": f"{cpu_isa()}, {os.cpu_count()} cores (shared), "
        f"Python {platform.python_version()}, torch {torch.__version__} on 1 thread",
        "date": time.strftime("%Y-%m-%d"),
        "check_every_steps": CHECK_EVERY_STEPS,
        "steps": args.steps,
        "repeats": args.repeats,
        "rows": rows,
    }
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / "divergence_check.json").write_text(json.dumps(result, indent=2) + "\n")
    lines = [
        "# Cost of the divergence check in training runs",
        "",
        f"Command: `{result['command']}`  ",
        f"Machine: {result['machine']}; date {result['date']}. Runs of {args.steps} steps (highway, fast "
        f"backend; the town for bc and rlad), {args.repeats} repeats alternating checks on and off "
        f"(fewer where the row says).",
        "",
        f"Bound: one check per {CHECK_EVERY_STEPS} steps / the step time of the runs without checks. "
        "Measured: difference of the median run times, on against off (noise of a shared machine).",
        "",
        "| case | weights | one check (ms) | step (ms) | bound | a check every step | measured | runs |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for row in rows:
        lines.append(
            f"| {row['case']} | {row['weights']:,} in {row['weight_tensors']} tensors "
            f"| {row['check_ms']:.3f} | {row['run_step_ms']:.2f} | {row['bound_percent']:.3f} % "
            f"| {row['every_step_percent']:.1f} % "
            f"| {row['measured_percent']:+.1f} % | {row['repeats']} x 2 of {row['steps']} steps |"
        )
    (RESULTS / "divergence_check.md").write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
