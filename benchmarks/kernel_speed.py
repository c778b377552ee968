"""Traffic kernel cost per world-step on the fast backend (highway, regular traffic, meta control).

    NUMBA_NUM_THREADS=1 .venv/bin/python benchmarks/kernel_speed.py [--worlds 1,64,256] [--steps 200] [--wall]

K worlds in one FastSimulator, reset from seeds 0..K-1, driven with random meta-actions (worlds
reset where their episode ended, as a vector env does). Reports, per world-step, the CPU
microseconds (process time: steadier on a busy machine; with one numba thread it is the wall
time; ``--wall`` for wall-clock time, to compare thread counts) spent in the traffic kernel
alone (``traffic.simulate_worlds``) and in a whole ``step`` (controls, kernel, arrivals, route
projection and the WorldBatch export) with the resets.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

from drivelab.scenarios import SCENARIOS
from drivelab.sim.core import simulator as S
from drivelab.sim.core import traffic as T

sys.path.insert(0, str(Path(__file__).resolve().parent))
from provenance import Parser, whole, wholes  # noqa: E402

# the scenarios FastSimulator steps with meta-actions (the others have their own simulators or
# continuous egos)
METAACTION_SCENARIOS = ("highway", "merge", "roundabout", "intersection")


def measure(
    scenario: str, traffic: str, worlds: int, steps: int, clock=time.process_time
) -> tuple[float, float]:
    sim = S.FastSimulator(SCENARIOS[scenario], traffic, "meta", worlds)
    sim.reset_where(np.ones(worlds, dtype=bool), np.arange(worlds))
    rng = np.random.default_rng(0)
    kernel_s = 0.0
    original = T.simulate_worlds

    def timed(*args):
        nonlocal kernel_s
        start = clock()
        original(*args)
        kernel_s += clock() - start

    S.T.simulate_worlds = timed
    try:
        sim.step(rng.integers(5, size=worlds))  # compile outside the timing
        kernel_s, seed = 0.0, worlds
        start = clock()
        for _ in range(steps):
            batch = sim.step(rng.integers(5, size=worlds))
            done = batch.events.collided | batch.events.off_road | (batch.time_s >= sim.duration_s)
            if done.any():
                seeds = seed + np.arange(worlds)
                seed += worlds
                sim.reset_where(done, seeds)
        total_s = clock() - start
    finally:
        S.T.simulate_worlds = original
    return kernel_s / (steps * worlds) * 1e6, total_s / (steps * worlds) * 1e6


def main() -> None:
    parser = Parser()
    parser.add_argument("--scenario", choices=METAACTION_SCENARIOS, default="highway")
    parser.add_argument("--traffic", choices=("empty", "regular", "dense"), default="regular")
    parser.add_argument("--worlds", type=wholes(1), default="1,64")
    parser.add_argument("--steps", type=whole(), default=200)
    parser.add_argument("--wall", action="store_true", help="wall-clock time (to compare thread counts)")
    args = parser.parse_args()
    clock = time.perf_counter if args.wall else time.process_time
    for worlds in args.worlds:
        kernel, total = measure(args.scenario, args.traffic, worlds, args.steps, clock)
        print(f"K={worlds}: kernel {kernel:.1f} us/world-step, whole step {total:.1f} us/world-step")


if __name__ == "__main__":
    main()
