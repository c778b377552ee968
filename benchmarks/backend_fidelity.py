"""Statistical fidelity: traffic statistics of the fast backend against highway-env.

    .venv/bin/python benchmarks/backend_fidelity.py [--episodes 200] [--scenarios highway,merge,...]

Both backends run the same episodes (seeds 0..N-1, default traffic) with the same scripted ego:
on meta-action scenarios a fixed cycle (IDLE x4, LANE_LEFT, IDLE x4, LANE_RIGHT); on the racetrack
(continuous control) a proportional lane keeper at half throttle that reads only the WorldState.
Per episode: mean NPC speed, NPC lane changes per vehicle-km (a lane change: an NPC's lane id
changes while it stays on the same road; vehicle-km from the NPCs' speeds) and whether the ego
crashed. Agreement: means within 5 %
or 95 % confidence intervals overlapping.

The two backends agree bit for bit only where numpy's and OpenBLAS's kernels round like libm (no
AVX-512 dispatch); elsewhere positions drift by rounding (tests/sim/test_fast.py says how
much) while events stay identical, so the machine line records numpy's SIMD dispatch.
"""

from __future__ import annotations

import json
import os
import platform
import sys
import time
from pathlib import Path

os.environ.setdefault("PYGAME_HIDE_SUPPORT_PROMPT", "1")

import numpy as np  # noqa: E402

from drivelab.scenarios import FAST_SCENARIOS  # noqa: E402
from drivelab.sim.core import traffic as T  # noqa: E402
from drivelab.sim.core.backend import FastBackend  # noqa: E402
from drivelab.sim.reference.highway import HighwayBackend  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from provenance import Parser, cpu_isa, names, whole  # noqa: E402

# highway-env's traffic scenarios: the town has its own (benchmarks/town_fidelity.py), the circuits
# have no traffic, and the block maps no highway-env backend
SUPPORTED = ("highway", "merge", "roundabout", "intersection", "racetrack")
assert set(SUPPORTED) <= set(FAST_SCENARIOS)
from drivelab.scenarios import SCENARIOS  # noqa: E402
from drivelab.world.state import WorldState  # noqa: E402

RESULTS = Path(__file__).parent / "results"
EGO_CYCLE = (1, 1, 1, 1, 0, 1, 1, 1, 1, 2)  # IDLE x4, LANE_LEFT, IDLE x4, LANE_RIGHT


def scripted_action(world: WorldState, step: int, control: str):
    if control == "meta":
        return EGO_CYCLE[step % len(EGO_CYCLE)]
    ego = world.ego
    heading_error = np.angle(np.exp(1j * (ego.heading - ego.lane_heading)))
    steer = np.clip(-0.4 * ego.lateral_offset_m - 1.5 * heading_error, -1, 1)
    return np.array([0.3 if ego.speed_mps < 6 else -0.1, steer], dtype=np.float32)


def npc_lanes(backend) -> list[tuple]:
    """Lane index (from, to, id) of every NPC, in the vehicle order both backends share."""
    if isinstance(backend, FastBackend):
        rows = [r for k, r in enumerate(backend.vehicles) if k != backend.ego and r[T.KIND] != T.OBSTACLE]
        return [backend.table.indices[int(r[T.LANE])] for r in rows]
    return [v.lane_index for v in backend.env.road.vehicles if v is not backend.env.vehicle]


def episode_statistics(backend, seed: int) -> dict[str, float]:
    world = backend.reset(seed)
    speeds, distance_m, changes, step = [], 0.0, 0, 0
    lanes = npc_lanes(backend)
    while True:
        world = backend.step(scripted_action(world, step, backend.control))
        step += 1
        speeds.extend(world.vehicles[:, 3])
        distance_m += float(np.abs(world.vehicles[:, 3]).sum()) * world.dt_s  # vehicles come and go
        now = npc_lanes(backend)
        if len(now) == len(lanes):  # (the intersection's roads have one lane: nothing to count there)
            changes += sum(a[:2] == b[:2] and a[2] != b[2] for a, b in zip(lanes, now, strict=True))
        lanes = now
        events = world.events
        if events.collided or events.arrived or events.off_road or world.time_s >= backend.duration_s - 1e-9:
            break
    return {
        "npc_speed_mps": float(np.mean(speeds)) if speeds else float("nan"),
        "lane_changes_per_vehicle_km": changes / max(distance_m / 1000, 1e-9),
        "crashed": float(world.events.collided),
    }


def interval(values: np.ndarray, binary: bool) -> tuple[float, float, float]:
    """Mean and 95 % interval (Wilson for rates, normal approximation for means)."""
    n, mean = len(values), float(np.mean(values))
    if binary:
        z = 1.96
        centre = (mean + z * z / (2 * n)) / (1 + z * z / n)
        half = z * np.sqrt(mean * (1 - mean) / n + z * z / (4 * n * n)) / (1 + z * z / n)
        return mean, centre - half, centre + half
    half = 1.96 * float(np.std(values, ddof=1)) / np.sqrt(n)
    return mean, mean - half, mean + half


def simd_dispatch() -> str:
    """numpy's SIMD targets in use on this CPU (AVX-512 ones change its rounding, see above)."""
    from numpy._core._multiarray_umath import __cpu_dispatch__, __cpu_features__

    return " ".join(t for t in __cpu_dispatch__ if __cpu_features__.get(t)) or "baseline only"


def main() -> None:
    parser = Parser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=whole(), default=200)
    parser.add_argument("--scenarios", type=names(SUPPORTED), default=",".join(SUPPORTED))
    args = parser.parse_args()
    rows, timings = [], {}
    for name in args.scenarios:
        scenario = SCENARIOS[name]
        control = "meta" if "meta" in scenario.action_kinds else "continuous"
        results = {}
        for label, backend_class in (("highway", HighwayBackend), ("fast", FastBackend)):
            backend = backend_class(scenario, control=control)
            start = time.perf_counter()
            stats = [episode_statistics(backend, seed) for seed in range(args.episodes)]
            results[label] = (stats, time.perf_counter() - start)
        timings[name] = {label: seconds for label, (_, seconds) in results.items()}
        for metric in ("npc_speed_mps", "lane_changes_per_vehicle_km", "crashed"):
            binary = metric == "crashed"
            reference = interval(np.array([s[metric] for s in results["highway"][0]]), binary)
            fast = interval(np.array([s[metric] for s in results["fast"][0]]), binary)
            within_5 = abs(fast[0] - reference[0]) <= 0.05 * abs(reference[0])
            overlap = fast[1] <= reference[2] and reference[1] <= fast[2]
            rows.append(
                {
                    "scenario": name,
                    "metric": metric,
                    "highway": reference,
                    "fast": fast,
                    "agree": within_5 or overlap,
                }
            )
            print(rows[-1], flush=True)
    result = {
        "command": "python " + " ".join(sys.argv),
        "machine": f"{cpu_isa()}, {os.cpu_count()} cores, Python {platform.python_version()},"
        f" numpy SIMD dispatch {simd_dispatch()}",
        "date": time.strftime("%Y-%m-%d"),
        "episodes": args.episodes,
        "rows": rows,
        "wall_s": timings,
    }
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / "backend_fidelity.json").write_text(json.dumps(result, indent=2))
    show = lambda t: f"{t[0]:.3f} [{t[1]:.3f}, {t[2]:.3f}]"  # noqa: E731
    lines = [
        "# Statistical fidelity of the fast backend",
        "",
        f"Command: `{result['command']}`  ",
        f"Machine: {result['machine']}; date {result['date']}; {args.episodes} episodes per backend,",
        "seeds 0..N-1, default traffic; scripted ego cycling IDLE x4, LANE_LEFT, IDLE x4, LANE_RIGHT",
        "(racetrack: a proportional lane keeper). The fast backend does highway-env's arithmetic step",
        "for step: bit for bit where numpy and OpenBLAS round like libm (no AVX-512 kernels), else up to",
        "rounding (1e-3 m within 30 steps, identical events; tests/sim/test_fast.py), so equal",
        "statistics are the expected result.",
        "",
        "| scenario | metric | highway-env mean [95 % CI] | fast mean [95 % CI] | agree |",
        "|---|---|---|---|---|",
        *[
            f"| {r['scenario']} | {r['metric']} | {show(r['highway'])} | {show(r['fast'])} | {r['agree']} |"
            for r in rows
        ],
        "",
        "Wall time per backend and scenario (all episodes, scripted ego, no learning):",
        "",
        *[
            f"- {name}: highway-env {t['highway']:.0f} s, fast {t['fast']:.0f} s"
            for name, t in timings.items()
        ],
        "",
    ]
    (RESULTS / "backend_fidelity.md").write_text("\n".join(lines))
    print("\n".join(lines))


if __name__ == "__main__":
    main()
