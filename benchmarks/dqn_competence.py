"""Time to competence: SB3 DQN on highway with each backend, highway-env's documented settings.

    .venv/bin/python benchmarks/dqn_competence.py [--steps 20000] [--episodes 50] [--backends fast,highway]

DQN: MLP [256, 256], lr 5e-4, buffer 15k, batch 32, gamma 0.8, target update every 50 steps
(drivelab's SB3 defaults, taken from highway-env's example). Each backend trains with the same
seed, then its final model is evaluated on 50 episodes of the same backend. Wall time and the
process's CPU time are both reported: on a shared machine the CPU time is the steadier figure
(torch runs one thread: OMP_NUM_THREADS=1 unless the caller sets it; the results record it).
"""

from __future__ import annotations

import json
import os
import platform
import shutil
import sys
import time
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("PYGAME_HIDE_SUPPORT_PROMPT", "1")

from drivelab.config import build_config  # noqa: E402
from drivelab.training.evaluate import evaluate_run  # noqa: E402
from drivelab.training.run import train  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from provenance import Parser, command_line, cpu_isa, names, whole  # noqa: E402

RESULTS = Path(__file__).parent / "results"
RUNS = Path(__file__).parent / "runs"


def main() -> None:
    parser = Parser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=whole(), default=20_000)
    parser.add_argument("--episodes", type=whole(), default=50)
    parser.add_argument("--backends", type=names(("fast", "highway")), default="fast,highway")
    parser.add_argument("--seed", type=whole(0), default=0)
    args = parser.parse_args()
    rows = []
    for backend in args.backends:
        name = f"dqn-competence-{backend}-s{args.seed}"
        shutil.rmtree(RUNS / name, ignore_errors=True)
        config = build_config(
            {
                "algo": "dqn", "env": "highway", "obs": "kinematics", "action": "meta",
                "reward": "highway", "traffic": "regular", "backend": backend, "steps": args.steps,
                "seed": args.seed, "name": name, "eval_every": args.steps, "eval_episodes": 1,
            }
        )  # fmt: skip
        start, cpu_start = time.perf_counter(), time.process_time()
        run_dir = train(config, RUNS)
        train_s, train_cpu_s = time.perf_counter() - start, time.process_time() - cpu_start
        report = evaluate_run(run_dir, episodes=args.episodes)
        row = {
            "backend": backend,
            "train_wall_s": train_s,
            "train_cpu_s": train_cpu_s,
            "load_average_1min": os.getloadavg()[0],
            "eval_episodes": args.episodes,
            "crash_rate": report["crash_rate"],
            "mean_return": report["mean_return"],
            "std_return": report["std_return"],
            "mean_speed_mps": report["mean_speed_mps"],
        }
        rows.append(row)
        print(row, flush=True)
    result = {
        "command": command_line(),
        "machine": f"{cpu_isa()}, {os.cpu_count()} cores, Python {platform.python_version()}",
        "date": time.strftime("%Y-%m-%d"),
        "steps": args.steps,
        "seed": args.seed,
        "rows": rows,
    }
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / "dqn_competence.json").write_text(json.dumps(result, indent=2))
    lines = [
        "# Time to competence: SB3 DQN on highway, per backend",
        "",
        f"Command: `{result['command']}`  ",
        f"Machine: {result['machine']}; date {result['date']}; seed {args.seed}, "
        f"{args.steps} training steps.",
        "",
        "| backend | training wall time | training CPU time | crash rate | mean return ± std "
        "| mean speed (m/s) |",
        "|---|---|---|---|---|---|",
        *[
            f"| {r['backend']} | {r['train_wall_s'] / 60:.1f} min | {r['train_cpu_s'] / 60:.1f} min | "
            f"{r['crash_rate']:.2f} "
            f"({r['eval_episodes']} episodes) | {r['mean_return']:.2f} ± {r['std_return']:.2f} | "
            f"{r['mean_speed_mps']:.1f} |"
            for r in rows
        ],
        "",
    ]
    (RESULTS / "dqn_competence.md").write_text("\n".join(lines))
    print("\n".join(lines))


if __name__ == "__main__":
    main()
