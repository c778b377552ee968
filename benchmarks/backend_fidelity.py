"""Statistical fidelity: traffic statistics of the fast backend against highway-env.

    .venv/bin/python benchmarks/backend_fidelity.py [--episodes 200]

Both backends run the same episodes (seeds 0..N-1) with the same scripted ego policy (a fixed
cycle of meta-actions). Per episode: mean NPC speed, NPC lane changes per vehicle-km (a lane
change is a change of the lane an NPC's centre is in, lanes being 4 m wide from y = -2 m), and
whether the ego crashed. Agreement: means within 5 % or 95 % confidence intervals overlapping.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time
from pathlib import Path

os.environ.setdefault("PYGAME_HIDE_SUPPORT_PROMPT", "1")

import numpy as np  # noqa: E402

from drivelab.envs.backends.fast.backend import SUPPORTED, FastBackend  # noqa: E402
from drivelab.envs.backends.highway import HighwayBackend  # noqa: E402
from drivelab.envs.scenarios import SCENARIOS  # noqa: E402

RESULTS = Path(__file__).parent / "results"
EGO_POLICY = (1, 3, 1, 2, 1, 4, 0)  # IDLE, FASTER, IDLE, LANE_RIGHT, IDLE, SLOWER, LANE_LEFT


def episode_statistics(backend, seed: int) -> dict[str, float]:
    world = backend.reset(seed)
    duration = backend.duration_s
    speeds, distance_m, changes = [], 0.0, 0
    lanes = np.floor((world.vehicles[:, 1] + 2.0) / 4.0)
    step = 0
    while True:
        previous = world.vehicles
        world = backend.step(EGO_POLICY[step % len(EGO_POLICY)])
        step += 1
        vehicles = world.vehicles
        speeds.extend(vehicles[:, 3])
        distance_m += float(np.linalg.norm(vehicles[:, :2] - previous[:, :2], axis=1).sum())
        now = np.floor((vehicles[:, 1] + 2.0) / 4.0)
        changes += int(np.sum(now != lanes))
        lanes = now
        if world.events.collided or world.time_s >= duration - 1e-9:
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


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=200)
    args = parser.parse_args()
    rows = []
    for name in SUPPORTED:
        scenario = SCENARIOS[name]
        results = {}
        for label, backend in (("highway", HighwayBackend(scenario)), ("fast", FastBackend(scenario))):
            start = time.perf_counter()
            stats = [episode_statistics(backend, seed) for seed in range(args.episodes)]
            results[label] = (stats, time.perf_counter() - start)
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
        "machine": f"{platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}",
        "date": time.strftime("%Y-%m-%d"),
        "episodes": args.episodes,
        "rows": rows,
    }
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / "backend_fidelity.json").write_text(json.dumps(result, indent=2))
    show = lambda t: f"{t[0]:.3f} [{t[1]:.3f}, {t[2]:.3f}]"  # noqa: E731
    lines = [
        "# Statistical fidelity of the fast backend",
        "",
        f"Command: `{result['command']}`  ",
        f"Machine: {result['machine']}; date {result['date']}; {args.episodes} episodes per backend,",
        "seeds 0..N-1, scripted ego cycling IDLE, FASTER, IDLE, LANE_RIGHT, IDLE, SLOWER, LANE_LEFT.",
        "",
        "| scenario | metric | highway-env mean [95 % CI] | fast mean [95 % CI] | agree |",
        "|---|---|---|---|---|",
        *[
            f"| {r['scenario']} | {r['metric']} | {show(r['highway'])} | {show(r['fast'])} | {r['agree']} |"
            for r in rows
        ],
        "",
        "Scenarios other than those listed are not run by the fast backend yet.",
        "",
    ]
    (RESULTS / "backend_fidelity.md").write_text("\n".join(lines))
    print("\n".join(lines))


if __name__ == "__main__":
    main()
