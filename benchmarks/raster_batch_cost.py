"""Cost per world-step of the raster sensors (topdown on highway, camera on the town) at K = 1 and K = 32.

    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/raster_batch_cost.py [--worlds 32] [--steps 6]

K worlds are recorded first (``tests/batch_worlds.py``: random actions, worlds resetting at
different steps, one backend each, so one road map per world); then the sensor observes every
step's K worlds, ``--repeats`` times. ``batched`` mode calls ``observe(batch, out)`` once per step;
``single`` mode (for code before the batched rasters) calls one sensor instance per world on its
WorldState. The figure is the median over repeats of the process CPU time per world-step, in µs (CPU time is
less disturbed by other jobs on a shared machine than wall time).
"""

from __future__ import annotations

import json
import statistics
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from drivelab.perception.sensors import make_sensor  # noqa: E402
from drivelab.world.batch import WorldBatch  # noqa: E402
from tests.batch_worlds import world_sequences  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from provenance import Parser, whole  # noqa: E402

CASES = {"topdown": ("highway", "topdown"), "camera": ("town", "camera")}


def per_world_step_us(sensor_spec: str, sequence, worlds: int, mode: str, repeats: int) -> float:
    steps = [(list(ws[:worlds]), started[:worlds]) for ws, started in sequence]
    batches = [(WorldBatch.stack(ws), started) for ws, started in steps]
    times = []
    for _ in range(repeats + 1):  # the first pass warms the per-map geometry
        if mode == "batched":
            sensor = make_sensor(sensor_spec)
            out = sensor.empty(worlds)
            started_at = time.process_time()
            for t, (batch, started) in enumerate(batches):
                if started.any():
                    rngs = [np.random.default_rng(k) for k in range(worlds)]
                    sensor.reset(batch, rngs, None if t == 0 else started)
                sensor.observe(batch, out)
        else:
            sensors = [make_sensor(sensor_spec) for _ in range(worlds)]
            started_at = time.process_time()
            for ws, started in steps:
                for k, (sensor, world) in enumerate(zip(sensors, ws, strict=True)):
                    if started[k]:
                        sensor.reset(world, np.random.default_rng(k))
                    sensor.observe(world)
        times.append((time.process_time() - started_at) / (len(steps) * worlds) * 1e6)
    return statistics.median(times[1:])


def main() -> None:
    parser = Parser(description=__doc__.splitlines()[0])
    parser.add_argument("--worlds", type=whole(), default=32)
    parser.add_argument("--steps", type=whole(), default=6)
    parser.add_argument("--repeats", type=whole(), default=5)
    parser.add_argument("--mode", choices=("batched", "single"), default="batched")
    args = parser.parse_args()
    results = {}
    for name, (scenario, spec) in CASES.items():
        sequence = world_sequences(scenario, num_worlds=args.worlds, steps=args.steps)
        for worlds in (1, args.worlds):
            cost = per_world_step_us(spec, sequence, worlds, args.mode, args.repeats)
            results[f"{name} {scenario} K={worlds}"] = round(cost, 1)
            print(
                f"{name:8s} {scenario:8s} K={worlds:3d} {args.mode}: {cost:8.1f} µs per world-step",
                flush=True,
            )
    print(json.dumps(results))


if __name__ == "__main__":
    main()
