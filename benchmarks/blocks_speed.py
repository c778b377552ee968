"""Blocks speed: seed 003's "OSX" map at MetaDrive's default traffic density (0.1) on the compiled
core, with 240-beam LiDAR observations, one world and K worlds, one thread.

    OMP_NUM_THREADS=1 NUMBA_NUM_THREADS=1 .venv/bin/python benchmarks/blocks_speed.py \
        [--steps 3000] [--repeats 5] [--worlds 64]

Interleaved repeats of:

- the simulator alone (``BlocksSimulator.step``, one world, no sensor, reward or rules);
- one world: a VectorDriveEnv of K = 1 with ``obs="lidar"`` (240 beams, 50 m) and the
  ``metadrive`` reward, the action MetaDrive's own profile script takes (no steering, full
  throttle: ``metadrive/examples/profile_metadrive.py``), resets included (the ego leaves the road
  at the roundabout, every few seconds);
- ``--worlds`` K worlds in one VectorDriveEnv, the same action in every world (every world's steps
  counted).

Each rate is the median over repeats, the K-worlds ratio the median of the per-repeat ratios.
MetaDrive's published figure is beside them: "+1000 FPS on a standard PC" (its README; up to
1,500 FPS, +2,000 on a MacBook Pro in its documentation), measured by its profile script without
rendering and with 0.05 density on 1000 maps (shared/notes/METADRIVE-NOTES.md section 7): a step
there is one 0.1 s decision with LiDAR, as here. Writes ``benchmarks/results/blocks_speed.json``
and ``.md``.
"""

from __future__ import annotations

import json
import os
import platform
import statistics
import sys
import time
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("NUMBA_NUM_THREADS", "1")

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from provenance import Parser, command_line, cpu_isa, whole  # noqa: E402

RESULTS = Path(__file__).parent / "results"
OPTIONS = {"map": "OSX", "traffic_density": 0.1}  # MetaDrive's default density
METADRIVE_FPS = "+1000 FPS (README), up to 1,500 (docs), +2,000 on a MacBook Pro"
THROTTLE = np.array([0.0, 1.0], dtype=np.float32)  # [steering, acceleration]: profile_metadrive.py's


def simulator_rate(steps: int, seed: int) -> float:
    """Steps/s of ``BlocksSimulator.step`` alone, one world, full throttle, reset off the road."""
    from drivelab.scenarios import get_scenario
    from drivelab.sim.core.backend import fast_simulator

    simulator = fast_simulator(get_scenario("blocks"), "regular", "continuous", 1, OPTIONS)
    one = np.ones(1, dtype=bool)
    simulator.reset_where(one, np.array([seed]))
    controls = THROTTLE[::-1][None].astype(float)  # the simulator's order: [acceleration, steering]
    start = time.perf_counter()
    for step in range(steps):
        batch = simulator.step(controls)
        if batch.events.off_road[0] or batch.events.collided[0]:
            simulator.reset_where(one, np.array([seed + step]))
    return steps / (time.perf_counter() - start)


def vector_rate(worlds: int, steps: int, seed: int) -> float:
    """Env steps/s of all ``worlds`` of one VectorDriveEnv (LiDAR 240, metadrive reward)."""
    from drivelab.envs.vector import VectorDriveEnv

    vector = VectorDriveEnv(worlds, scenario="blocks", obs="lidar", backend_options=OPTIONS)
    actions = np.tile(THROTTLE, (worlds, 1))
    vector.reset(seed=seed)
    for _ in range(3):
        vector.step(actions)
    batches = max(steps // worlds, 20)
    start = time.perf_counter()
    for _ in range(batches):
        vector.step(actions)
    return batches * worlds / (time.perf_counter() - start)


def main() -> None:
    parser = Parser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=whole(), default=3000)
    parser.add_argument("--repeats", type=whole(), default=5)
    parser.add_argument("--worlds", type=whole(), default=64)
    args = parser.parse_args()
    simulator_rate(50, 0), vector_rate(1, 50, 0), vector_rate(2, 50, 0)  # compile before timing
    rates = {"simulator": [], "one_world": [], "k_worlds": []}
    for repeat in range(args.repeats):
        rates["simulator"].append(simulator_rate(args.steps, repeat))
        rates["one_world"].append(vector_rate(1, args.steps, repeat))
        rates["k_worlds"].append(vector_rate(args.worlds, args.steps * 4, repeat))
        print(repeat, {key: round(values[-1]) for key, values in rates.items()}, flush=True)
    ratios = [k / one for k, one in zip(rates["k_worlds"], rates["one_world"], strict=True)]
    result = {
        "command": command_line(),
        "machine": f"{cpu_isa()}, {os.cpu_count()} cores, Python {platform.python_version()}",
        "date": time.strftime("%Y-%m-%d"),
        "repeats": args.repeats,
        "worlds": args.worlds,
        **{key: statistics.median(values) for key, values in rates.items()},
        "k_worlds_ratio": statistics.median(ratios),
        "metadrive_published": METADRIVE_FPS,
    }
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / "blocks_speed.json").write_text(json.dumps(result, indent=2))
    lines = [
        '# Blocks speed: "OSX", traffic density 0.1, LiDAR 240, one thread',
        "",
        f"Command: `{result['command']}`  ",
        f"Machine: {result['machine']}; date {result['date']}; {args.repeats} interleaved repeats.",
        "",
        "| what | steps/s |",
        "|---|---|",
        f"| simulator step alone, one world | {result['simulator']:.0f} |",
        f"| one world, VectorDriveEnv (LiDAR 240, metadrive reward, rules) | {result['one_world']:.0f} |",
        f"| K = {args.worlds} worlds, one VectorDriveEnv (all worlds' steps) | {result['k_worlds']:.0f} |",
        f"| K = {args.worlds} over one world (median per-repeat ratio) | {result['k_worlds_ratio']:.2f}x |",
        f"| MetaDrive, published (no rendering, its profile script) | {METADRIVE_FPS} |",
    ]
    (RESULTS / "blocks_speed.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
