"""Circuit speed: seed 004's follow-line and follow-lane on the compiled core against highway-env,
three ways, in one run.

    OMP_NUM_THREADS=1 NUMBA_NUM_THREADS=1 .venv/bin/python benchmarks/circuit_speed.py \
        [--steps 3000] [--repeats 5] [--worlds 64] [--baseline-repo PATH]

Per circuit, interleaved repeats of:

- the simulator alone (``FastBackend.step`` against ``HighwayBackend.step``: the ego's pedal and
  steering, two frames, the WorldState), a constant 40 % throttle, resetting when it leaves the road;
- one DriveEnv (the ``kinematics`` sensor and the circuit's default reward, as
  ``backend_speed.py``), random actions, resets included;
- ``--worlds`` K worlds in one VectorDriveEnv on the compiled core (every world's steps counted),
  against one highway-env DriveEnv.
- the parts of one compiled-core DriveEnv step, each called alone on a mid-episode world (µs per
  call): the circuits' compiled step (``CircuitStep.step``, what one DriveEnv runs), and the parts
  of the pipeline it replaces (the simulator's step, the rules, the reward, the metrics, the sensor
  and the infos), which every configuration it does not cover still runs;
- with ``--baseline-repo`` (a checkout of an earlier drivelab, e.g. ``git worktree add /tmp/base
  6b54828``): one compiled-core DriveEnv of that checkout and of this tree, each in a subprocess
  with the same code and actions, so that how much faster one world got is a same-run ratio.

Each ratio is the median of the per-repeat ratios. Writes ``benchmarks/results/circuit_speed.json``
and ``.md``.
"""

from __future__ import annotations

import json
import os
import platform
import statistics
import sys
import time
import timeit
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("NUMBA_NUM_THREADS", "1")
os.environ.setdefault("PYGAME_HIDE_SUPPORT_PROMPT", "1")

import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).parent))
from backend_speed import steps_per_second  # noqa: E402
from batch_speed import _commit, baseline_rate, vector_rate  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from provenance import Parser, command_line, cpu_isa, whole  # noqa: E402

RESULTS = Path(__file__).parent / "results"
CIRCUITS = ("follow-line", "follow-lane")


def simulator_rate(backend_class, name: str, steps: int) -> float:
    """Steps/s of one backend's ``step`` alone, 40 % throttle, straight wheel, reset off the road."""
    from drivelab.scenarios import SCENARIOS

    backend = backend_class(SCENARIOS[name], "empty", "continuous")
    backend.reset(0)
    control = np.array([0.4, 0.0], dtype=np.float32)
    for _ in range(10):
        backend.step(control)
    backend.reset(1)
    start = time.perf_counter()
    for step in range(steps):
        if backend.step(control).events.off_road:
            backend.reset(step)
    return steps / (time.perf_counter() - start)


PARTS = ("simulator", "rules", "reward", "metrics", "sensor", "infos")
PIPELINE_PARTS = PARTS[1:]


def part_costs(env, calls: int) -> dict[str, float]:
    """µs per call of each part of ``env``'s (a fast DriveEnv) step, timed on its current world
    after a few straight steps (the simulator keeps stepping; the others see the same batch)."""
    from drivelab.envs.vector import world_info

    vector, action = env.vector, np.array([[0.3, 0.0]], dtype=np.float32)
    env.reset(seed=0)
    for _ in range(5):
        env.step(action[0])
    batch, controls, keep = vector.batch, vector.adapter.controls_for(action, vector.batch), np.zeros(1, bool)
    rewards, terms = vector.reward_shaper(batch, batch, controls)

    def infos():
        events = batch.events
        arrays = (
            batch.ego.speed_mps.copy(),
            events.collided.copy(),
            events.off_road.copy(),
            events.arrived.copy(),
        )
        world_info(vector._step_infos(terms, *arrays, keep, keep), 0)

    fused_controls = vector.adapter.to_controls(action)
    parts = {
        "compiled": lambda: vector._fused.step(fused_controls),
        "simulator": lambda: vector.simulator.step(controls, keep, vector.episode_seeds),
        "rules": lambda: vector.rules.apply(batch),
        "reward": lambda: vector.reward_shaper(batch, batch, controls),
        "metrics": lambda: vector.metrics.update(batch, rewards),
        "sensor": lambda: vector._observe(batch),
        "infos": infos,
    }
    return {name: timeit.timeit(call, number=calls) / calls * 1e6 for name, call in parts.items()}


def main() -> None:
    parser = Parser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=whole(5), default=3000)
    parser.add_argument("--repeats", type=whole(), default=5)
    parser.add_argument("--worlds", type=whole(), default=64)
    parser.add_argument(
        "--baseline-repo", default=None, help="an earlier drivelab checkout to time one world of"
    )
    args = parser.parse_args()
    here = str(Path(__file__).resolve().parent.parent)
    fast_kwargs = "obs='kinematics', action='continuous', backend='fast'"
    from drivelab.envs.core import DriveEnv
    from drivelab.sim.core.backend import FastBackend
    from drivelab.sim.reference.highway import HighwayBackend

    rows = []
    for name in CIRCUITS:
        make = lambda backend: DriveEnv(name, obs="kinematics", action="continuous", backend=backend)  # noqa: B023, E731
        fast_env, slow_env = make("fast"), make("highway")
        steps_per_second(fast_env, 50, seed=0)  # compile before timing
        vector_rate(name, "kinematics", 2, 20, 0)
        keys = ["sim_fast", "sim_highway", "env_fast", "env_highway", "vector_fast"]
        keys += ["env_this_tree", "env_baseline"] if args.baseline_repo else []
        rates = {key: [] for key in keys}
        costs = {part: [] for part in ("compiled", *PARTS)}
        for repeat in range(args.repeats):
            rates["sim_fast"].append(simulator_rate(FastBackend, name, args.steps))
            rates["sim_highway"].append(simulator_rate(HighwayBackend, name, args.steps // 5))
            rates["env_fast"].append(steps_per_second(fast_env, args.steps, repeat))
            rates["env_highway"].append(steps_per_second(slow_env, args.steps // 5, repeat))
            rates["vector_fast"].append(vector_rate(name, "kinematics", args.worlds, args.steps * 2, repeat))
            if args.baseline_repo:
                for key, repo in (("env_baseline", args.baseline_repo), ("env_this_tree", here)):
                    rates[key].append(baseline_rate(repo, args.steps, repeat, name, fast_kwargs))
            for part, cost in part_costs(fast_env, args.steps // 3).items():
                costs[part].append(cost)
            print(name, repeat, {k: round(v[-1]) for k, v in rates.items()}, flush=True)
        ratio = lambda a, b, r=rates: statistics.median(x / y for x, y in zip(r[a], r[b], strict=True))  # noqa: E731
        rows.append(
            {
                "scenario": name,
                **{key: statistics.median(values) for key, values in rates.items()},
                "simulator_ratio": ratio("sim_fast", "sim_highway"),
                "one_env_ratio": ratio("env_fast", "env_highway"),
                "vector_vs_highway_env_ratio": ratio("vector_fast", "env_highway"),
                "part_us": {part: statistics.median(values) for part, values in costs.items()},
                **(
                    {"one_env_vs_baseline_ratio": ratio("env_this_tree", "env_baseline")}
                    if args.baseline_repo
                    else {}
                ),
            }
        )
    result = {
        "command": command_line(),
        "machine": f"{cpu_isa()}, {os.cpu_count()} cores, Python {platform.python_version()}",
        "date": time.strftime("%Y-%m-%d"),
        "repeats": args.repeats,
        "worlds": args.worlds,
        "baseline_repo_commit": _commit(args.baseline_repo) if args.baseline_repo else None,
        "rows": rows,
    }
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / "circuit_speed.json").write_text(json.dumps(result, indent=2))
    lines = [
        "# Circuit speed: follow-line and follow-lane, compiled core against highway-env",
        "",
        f"Command: `{result['command']}`  ",
        f"Machine: {result['machine']}; date {result['date']}; {args.repeats} interleaved repeats, "
        "one thread.",
        "",
        "Steps per second (medians) and the median of the per-repeat ratios.",
        "",
        "| circuit | what | highway-env | fast | ratio |",
        "|---|---|---|---|---|",
    ]
    for r in rows:
        lines += [
            f"| {r['scenario']} | simulator step alone | {r['sim_highway']:.0f} | {r['sim_fast']:.0f} | "
            f"{r['simulator_ratio']:.1f}x |",
            f"| {r['scenario']} | one DriveEnv (kinematics, default reward) | {r['env_highway']:.0f} | "
            f"{r['env_fast']:.0f} | {r['one_env_ratio']:.1f}x |",
            f"| {r['scenario']} | K = {args.worlds} VectorDriveEnv (fast) vs one highway-env DriveEnv | "
            f"{r['env_highway']:.0f} | {r['vector_fast']:.0f} | {r['vector_vs_highway_env_ratio']:.1f}x |",
        ]
    lines += [
        "",
        "One compiled-core DriveEnv step takes the circuits' compiled step (envs/fused.py): the",
        "simulator, rules, reward terms, metrics and kinematics sensor in one compiled call. Below, µs",
        "per call (medians): `compiled` is that call with its Python side (`CircuitStep.step`); the",
        "other columns are the parts of the pipeline it replaces, each called alone (P: all but the",
        "simulator), which every other configuration still runs. The whole step is 1 / the one-DriveEnv",
        "rate above, resets included.",
        "",
        "| circuit | compiled | " + " | ".join(PARTS) + " | P | whole step |",
        "|---|" + "---|" * (len(PARTS) + 3),
    ]
    for r in rows:
        cost, step_us = r["part_us"], 1e6 / r["env_fast"]
        pipeline = sum(cost[part] for part in PIPELINE_PARTS)
        lines.append(
            f"| {r['scenario']} | {cost['compiled']:.1f} | "
            + " | ".join(f"{cost[part]:.1f}" for part in PARTS)
            + f" | {pipeline:.1f} | {step_us:.1f} |"
        )
    if args.baseline_repo:
        lines += [
            "",
            f"One compiled-core DriveEnv, this tree against {result['baseline_repo_commit']} (each in a "
            "subprocess, the same actions):",
            "",
            "| circuit | baseline steps/s | this tree steps/s | ratio |",
            "|---|---|---|---|",
            *[
                f"| {r['scenario']} | {r['env_baseline']:.0f} | {r['env_this_tree']:.0f} | "
                f"{r['one_env_vs_baseline_ratio']:.2f}x |"
                for r in rows
            ],
        ]
    (RESULTS / "circuit_speed.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
