"""Backend speed: the fast backend against highway-env on the same scenario configs, one run.

    .venv/bin/python benchmarks/backend_speed.py [--steps 600] [--repeats 5]

Both backends run the same DriveEnv (the kinematics sensor, the scenario's default reward) and
the same random action sequence, resetting at episode ends (resets are part of the cost). Repeats
interleave the two backends; the reported speed-up is the median of the per-repeat ratios. A
second table times the town with RLAD's observation (84x84 camera, waypoints, measurements). K
worlds stepped together are measured by ``benchmarks/batch_speed.py``.
"""

from __future__ import annotations

import json
import os
import platform
import statistics
import sys
import time
from pathlib import Path

os.environ.setdefault("PYGAME_HIDE_SUPPORT_PROMPT", "1")

import numpy as np  # noqa: E402

from drivelab.envs.core import (
    DriveEnv,  # noqa: E402
)
from drivelab.scenarios import FAST_SCENARIOS as SUPPORTED  # noqa: E402
from drivelab.scenarios import SCENARIOS  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from provenance import Parser, cpu_isa, whole  # noqa: E402

RESULTS = Path(__file__).parent / "results"
RLAD_OBS = "camera:stack=3,waypoints,measurements:stack=3"  # RLAD's observation (seed 000)


def steps_per_second(env: DriveEnv, steps: int, seed: int) -> float:
    rng = np.random.default_rng(seed)
    env.action_space.seed(seed)
    actions = [env.action_space.sample() for _ in range(steps)]
    env.reset(seed=seed)
    start = time.perf_counter()
    for action in actions:
        _, _, terminated, truncated, _ = env.step(action)
        if terminated or truncated:
            env.reset(seed=int(rng.integers(1 << 30)))
    return steps / (time.perf_counter() - start)


def main() -> None:
    parser = Parser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=whole(5), default=600)
    parser.add_argument("--repeats", type=whole(), default=5)
    args = parser.parse_args()
    rows = []
    # every scenario with a highway-env reference (the block maps run on the compiled core only)
    cases = [(name, "kinematics") for name, scenario in SCENARIOS.items() if scenario.reference_backend]
    cases += [("town", RLAD_OBS)]
    for name, obs in cases:
        scenario = SCENARIOS[name]
        action = "meta" if "meta" in scenario.action_kinds else "continuous"
        make = lambda backend: DriveEnv(name, obs=obs, action=action, backend=backend)  # noqa: B023, E731
        reference = make("highway")
        fast = make("fast") if name in SUPPORTED else None
        if fast is not None:
            steps_per_second(fast, 50, seed=0)  # compile the kernels before timing
        slow_rates, fast_rates, ratios = [], [], []
        for repeat in range(args.repeats):
            slow_rates.append(steps_per_second(reference, args.steps // 5, repeat))
            if fast is not None:
                fast_rates.append(steps_per_second(fast, args.steps, repeat))
                ratios.append(fast_rates[-1] / slow_rates[-1])
        row = {
            "scenario": name,
            "obs": obs,
            "action": action,
            "highway_steps_per_s": statistics.median(slow_rates),
            "fast_steps_per_s": statistics.median(fast_rates) if fast_rates else None,
            "speedup_median": statistics.median(ratios) if ratios else None,
        }
        rows.append(row)
        print(row)
    result = {
        "command": "python " + " ".join(sys.argv),
        "machine": f"{cpu_isa()}, {os.cpu_count()} cores, Python {platform.python_version()}",
        "date": time.strftime("%Y-%m-%d"),
        "repeats": args.repeats,
        "rows": rows,
    }
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / "backend_speed.json").write_text(json.dumps(result, indent=2))
    fmt = lambda value, spec: "not supported yet" if value is None else format(value, spec)  # noqa: E731
    lines = [
        "# Backend speed: fast against highway-env",
        "",
        f"Command: `{result['command']}`  ",
        f"Machine: {result['machine']}; date {result['date']}; {args.repeats} interleaved repeats.",
        "",
        "DriveEnv with the kinematics sensor and the scenario's default reward, default (regular)",
        "traffic, random actions, resets included, one thread. highway-env runs a fifth of the steps",
        "per repeat (it is slow).",
        "",
        "| scenario | action | highway-env steps/s | fast steps/s | speed-up (median ratio) |",
        "|---|---|---|---|---|",
        *[
            f"| {r['scenario']} | {r['action']} | {r['highway_steps_per_s']:.1f} | "
            f"{fmt(r['fast_steps_per_s'], '.0f')} | {fmt(r['speedup_median'], '.1f')}"
            f"{'x' if r['speedup_median'] else ''} |"
            for r in rows
            if r["obs"] == "kinematics"
        ],
        "",
        f"The town with RLAD's observation (`{RLAD_OBS}`), per step:",
        "",
        "| scenario | highway-env ms/step | fast ms/step | speed-up (median ratio) |",
        "|---|---|---|---|",
        *[
            f"| {r['scenario']} | {1000 / r['highway_steps_per_s']:.2f} | "
            f"{1000 / r['fast_steps_per_s']:.2f} | {r['speedup_median']:.1f}x |"
            for r in rows
            if r["obs"] == RLAD_OBS
        ],
        "",
        "K worlds stepped together: `benchmarks/batch_speed.py`.",
        "",
    ]
    (RESULTS / "backend_speed.md").write_text("\n".join(lines))
    print("\n".join(lines))


if __name__ == "__main__":
    main()
