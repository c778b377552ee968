"""Environment throughput: raw highway-env against drivelab on the same scenario config, and
the per-frame cost of every sensor.

    .venv/bin/python benchmarks/env_throughput.py [--steps 300] [--repeats 5]

Raw and drivelab runs are interleaved within each repeat, and the reported speed ratio is the
median of the per-repeat ratios, so machine noise hits both sides alike.
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

import gymnasium  # noqa: E402
import highway_env  # noqa: E402, F401  (registers highway-fast-v0)
import numpy as np  # noqa: E402

from drivelab.envs.core import DriveEnv  # noqa: E402
from drivelab.perception.sensors import make_sensor  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from provenance import Parser, cpu_isa, whole  # noqa: E402

RESULTS = Path(__file__).parent / "results"


def steps_per_second(env, actions: np.ndarray, seed: int) -> float:
    """Policy steps per second over ``actions``, resetting whenever an episode ends."""
    env.reset(seed=seed)
    episode = 0
    start = time.perf_counter()
    for action in actions:
        _, _, terminated, truncated, _ = env.step(int(action))
        if terminated or truncated:
            episode += 1
            env.reset(seed=seed + episode)
    return len(actions) / (time.perf_counter() - start)


def sensor_costs_ms(worlds: list, repeats: int) -> dict[str, float]:
    """Median milliseconds per observe() call of each sensor over recorded WorldStates."""
    costs = {}
    for spec in ("kinematics", "lidar", "lidar:beams=120", "topdown", "birdeye"):
        sensor = make_sensor(spec)
        sensor.reset(worlds[0], np.random.default_rng(0))
        runs = []
        for _ in range(repeats):
            start = time.perf_counter()
            for world in worlds:
                sensor.observe(world)
            runs.append((time.perf_counter() - start) / len(worlds) * 1000)
        costs[spec] = statistics.median(runs)
    return costs


def main() -> None:
    parser = Parser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=whole(), default=300)
    parser.add_argument("--repeats", type=whole(), default=5)
    args = parser.parse_args()
    actions = np.random.default_rng(0).integers(0, 5, size=args.steps)

    raw = gymnasium.make("highway-fast-v0")  # Kinematics observation, 20 vehicles, 3 lanes
    ours = DriveEnv(
        "highway", obs="kinematics", action="meta", reward="highway", traffic="regular", backend="highway"
    )
    raw_rates, our_rates, ratios = [], [], []
    for repeat in range(args.repeats):
        raw_rate = steps_per_second(raw, actions, seed=repeat)
        our_rate = steps_per_second(ours, actions, seed=repeat)
        raw_rates.append(raw_rate)
        our_rates.append(our_rate)
        ratios.append(our_rate / raw_rate)
        print(f"repeat {repeat}: highway-env {raw_rate:.1f} steps/s, drivelab {our_rate:.1f} steps/s")

    worlds = []
    ours.reset(seed=0)
    for action in actions[:100]:
        _, _, terminated, truncated, _ = ours.step(int(action))
        worlds.append(ours.world)
        if terminated or truncated:
            ours.reset(seed=len(worlds))
    costs = sensor_costs_ms(worlds, args.repeats)

    result = {
        "command": "python " + " ".join(sys.argv),
        "machine": f"{cpu_isa()}, {os.cpu_count()} cores, "
        f"Python {platform.python_version()}, numpy {np.__version__}",
        "date": time.strftime("%Y-%m-%d"),
        "steps_per_repeat": args.steps,
        "repeats": args.repeats,
        "highway_env_steps_per_s_median": statistics.median(raw_rates),
        "drivelab_steps_per_s_median": statistics.median(our_rates),
        "speed_ratio_median": statistics.median(ratios),
        "sensor_ms_per_frame_median": costs,
    }
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / "env_throughput.json").write_text(json.dumps(result, indent=2))
    lines = [
        "# Environment throughput",
        "",
        f"Command: `{result['command']}`  ",
        f"Machine: {result['machine']}  ",
        f"Date: {result['date']}; {args.repeats} repeats of {args.steps} policy steps, interleaved.",
        "",
        "Scenario: highway-env `highway-fast-v0` (3 lanes, 20 vehicles, 5 Hz simulation, 1 Hz policy,",
        "Kinematics observation) against drivelab `highway` + `kinematics` with the same config,",
        "the same random meta-action sequence.",
        "",
        "| | steps/s (median) |",
        "|---|---|",
        f"| raw highway-env | {result['highway_env_steps_per_s_median']:.1f} |",
        f"| drivelab | {result['drivelab_steps_per_s_median']:.1f} |",
        f"| **drivelab / highway-env (median of per-repeat ratios)** "
        f"| **{result['speed_ratio_median']:.2f}x** |",
        "",
        "Per-frame sensor cost on 100 recorded highway WorldStates:",
        "",
        "| sensor | ms per frame (median) |",
        "|---|---|",
        *[f"| `{name}` | {ms:.3f} |" for name, ms in costs.items()],
        "",
    ]
    (RESULTS / "env_throughput.md").write_text("\n".join(lines))
    print("\n".join(lines))


if __name__ == "__main__":
    main()
