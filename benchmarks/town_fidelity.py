"""Town fidelity: the compiled core against the highway-env reference, in distribution.

    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/town_fidelity.py [--episodes 25]

The rule-based expert drives NoCrash on the test town (the 25 fixed routes, every traffic level,
the same episode seeds as ``drivelab benchmark nocrash``) on both backends. Reported per backend:

- success and every column of RLAD's Table IV (at each level), with a 90 % bootstrap interval
  over episodes (2000 resamples; per-km rates as ratios of summed counts to summed distance);
- the traffic's own behaviour over the same episodes: the NPCs' mean speed, their stops at a red
  or yellow light (a vehicle coming to rest, under 0.5 m/s, within 15 m before a stop line of its
  lane facing its way) and the pedestrians' crossings (a pedestrian starting to walk), both per
  km the NPCs drove. These should agree within 5 %.

Writes ``benchmarks/results/town_fidelity.json`` and ``.md``.
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

from drivelab.agents.expert import RuleBasedExpert  # noqa: E402
from drivelab.envs.core import DriveEnv  # noqa: E402
from drivelab.training.evaluate import aggregate  # noqa: E402
from drivelab.training.nocrash import INFRACTIONS, LEVELS, NOCRASH_SEED  # noqa: E402
from drivelab.world.state import LIGHT_GREEN  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from provenance import Parser, cpu_isa, whole  # noqa: E402

RESULTS = Path(__file__).parent / "results"
BACKENDS = ("highway", "fast")
STOPPED_MPS, STOP_LINE_M, BESIDE_M = 0.5, 15.0, 2.5
TRAFFIC_TOLERANCE = 0.05


def _stopping_at_lights(vehicles: np.ndarray, lights: np.ndarray) -> np.ndarray:
    """(N,) whether each vehicle has a red or yellow stop line within STOP_LINE_M ahead, facing
    its way (approach heading within 45°) and within BESIDE_M of its axis."""
    if len(lights) == 0 or len(vehicles) == 0:
        return np.zeros(len(vehicles), dtype=bool)
    cos_h, sin_h = np.cos(vehicles[:, 2])[:, None], np.sin(vehicles[:, 2])[:, None]
    delta = lights[None, :, :2] - vehicles[:, None, :2]
    ahead = delta[..., 0] * cos_h + delta[..., 1] * sin_h
    beside = -delta[..., 0] * sin_h + delta[..., 1] * cos_h
    turn = np.angle(np.exp(1j * (lights[None, :, 2] - vehicles[:, None, 2])))
    facing = (np.abs(turn) < np.pi / 4) & (lights[None, :, 3] != LIGHT_GREEN)
    return (facing & (ahead > 0) & (ahead < STOP_LINE_M) & (np.abs(beside) < BESIDE_M)).any(axis=1)


class TrafficLog:
    """The NPCs' and pedestrians' behaviour over the steps of many episodes."""

    def __init__(self) -> None:
        self.speed_sum = self.speed_samples = self.npc_m = 0.0
        self.red_stops = self.crossings = 0
        self.previous = None

    def start(self, world) -> None:
        self.previous = world

    def step(self, world) -> None:
        before, vehicles = self.previous, world.vehicles
        self.speed_sum += float(vehicles[:, 3].sum())
        self.speed_samples += len(vehicles)
        self.npc_m += float(vehicles[:, 3].sum()) * world.dt_s
        if len(before.vehicles) == len(vehicles):  # rows keep their vehicle unless a wreck was towed
            came_to_rest = (before.vehicles[:, 3] >= STOPPED_MPS) & (vehicles[:, 3] < STOPPED_MPS)
            self.red_stops += int((came_to_rest & _stopping_at_lights(vehicles, world.traffic_lights)).sum())
        if len(before.pedestrians) == len(world.pedestrians):  # unless one was hit
            self.crossings += int(((before.pedestrians[:, 3] == 0) & (world.pedestrians[:, 3] > 0)).sum())
        self.previous = world

    def summary(self) -> dict:
        km = self.npc_m / 1000
        return {
            "npc_mean_speed_mps": self.speed_sum / max(self.speed_samples, 1),
            "npc_km": km,
            "red_stops_per_npc_km": self.red_stops / km if km else None,
            "crossings_per_npc_km": self.crossings / km if km else None,
        }


def nocrash_episodes(backend: str, level: str, episodes: int, log: TrafficLog) -> list[dict]:
    """The expert's NoCrash episodes of one level on one backend (drivelab's NoCrash set-up)."""
    env = DriveEnv(
        "town",
        obs="waypoints,affordances",
        action="target_speed",
        traffic=level,
        backend=backend,
        backend_options={"layout": "test", "fixed_routes": True, "retarget": False},
    )
    expert = RuleBasedExpert(env.observation_space, env.action_space, env=env)
    results = []
    for episode in range(episodes):
        obs, _ = env.reset(seed=NOCRASH_SEED + episode)
        log.start(env.world)
        while True:
            obs, _, terminated, truncated, info = env.step(expert.predict(obs)[0])
            log.step(env.world)
            if terminated or truncated:
                results.append(info["episode_metrics"])
                break
    return results


def interval(results: list[dict], key: str, rng: np.random.Generator, resamples: int = 2000) -> list:
    """90 % bootstrap interval of ``aggregate(results)[key]`` over episodes."""
    values = []
    for _ in range(resamples):
        sample = [results[i] for i in rng.integers(len(results), size=len(results))]
        value = aggregate(sample)[key]
        if value is not None:
            values.append(value)
    return [float(np.percentile(values, 5)), float(np.percentile(values, 95))] if values else [None, None]


def main() -> None:
    parser = Parser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=whole(), default=25)
    args = parser.parse_args()
    rows, traffic, seconds = {}, {}, {}
    for backend in BACKENDS:
        log, start = TrafficLog(), time.perf_counter()
        for level in LEVELS:
            results = nocrash_episodes(backend, level, args.episodes, log)
            values = aggregate(results)
            rng = np.random.default_rng(0)
            rows[(backend, level)] = {
                key: {"value": values[key], "interval90": interval(results, key, rng)}
                for _, key in INFRACTIONS
            }
            print(backend, level, {key: values[key] for _, key in INFRACTIONS}, flush=True)
        seconds[backend] = time.perf_counter() - start
        traffic[backend] = log.summary()
        print(backend, traffic[backend], f"{seconds[backend]:.0f} s", flush=True)

    def overlap(level: str, key: str) -> bool:
        a, b = rows[("highway", level)][key], rows[("fast", level)][key]
        if a["value"] is None or b["value"] is None:
            return a["value"] is None and b["value"] is None
        inside = lambda x, iv: iv[0] - 1e-12 <= x <= iv[1] + 1e-12  # noqa: E731
        return inside(b["value"], a["interval90"]) and inside(a["value"], b["interval90"])

    agreement = {f"{level}/{key}": overlap(level, key) for level in LEVELS for _, key in INFRACTIONS}
    relative = {
        key: abs(traffic["fast"][key] - traffic["highway"][key]) / abs(traffic["highway"][key])
        for key in ("npc_mean_speed_mps", "red_stops_per_npc_km", "crossings_per_npc_km")
        if traffic["highway"][key]
    }
    result = {
        "command": "python " + " ".join(sys.argv),
        "machine": f"{cpu_isa()}, {os.cpu_count()} cores, Python {platform.python_version()}",
        "date": time.strftime("%Y-%m-%d"),
        "episodes_per_level": args.episodes,
        "rows": {f"{b}/{lv}": v for (b, lv), v in rows.items()},
        "traffic": traffic,
        "seconds": seconds,
        "each_value_inside_the_other_backends_interval": agreement,
        "traffic_relative_difference": relative,
    }
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / "town_fidelity.json").write_text(json.dumps(result, indent=2))
    fmt = lambda x, pct: "n/a" if x is None else (f"{100 * x:.1f}" if pct else f"{x:.2f}")  # noqa: E731

    def cell(backend: str, level: str, key: str) -> str:
        entry, pct = rows[(backend, level)][key], key in ("success_rate", "route_completion")
        low, high = entry["interval90"]
        return f"{fmt(entry['value'], pct)} [{fmt(low, pct)}, {fmt(high, pct)}]"

    lines = [
        "# Town fidelity: compiled core against the highway-env reference",
        "",
        f"Command: `{result['command']}`  ",
        f"Machine: {result['machine']}; date {result['date']}.",
        "",
        f"The rule-based expert on NoCrash, test town, {args.episodes} episodes per level (the fixed",
        "routes, NoCrash's seeds). Each cell: value [90 % bootstrap interval over episodes].",
        "",
    ]
    for level in LEVELS:
        lines += [
            f"## {level} traffic",
            "",
            "| column | highway-env | fast | each inside the other's interval |",
        ]
        lines += ["|---|---|---|---|"]
        for label, key in INFRACTIONS:
            ok = "yes" if agreement[f"{level}/{key}"] else "**no**"
            lines.append(f"| {label} | {cell('highway', level, key)} | {cell('fast', level, key)} | {ok} |")
        lines.append("")
    lines += [
        "## The traffic itself (all levels together)",
        "",
        "| quantity | highway-env | fast | relative difference |",
        "|---|---|---|---|",
    ]
    for key, label in (
        ("npc_mean_speed_mps", "NPC mean speed (m/s)"),
        ("red_stops_per_npc_km", "NPC stops at red or yellow / NPC km"),
        ("crossings_per_npc_km", "pedestrian crossings / NPC km"),
    ):
        diff = relative.get(key)
        shown = "n/a" if diff is None else f"{100 * diff:.2f} %"
        lines.append(
            f"| {label} | {fmt(traffic['highway'][key], False)} | {fmt(traffic['fast'][key], False)} "
            f"| {shown} |"
        )
    lines += [
        "",
        f"Wall time: highway-env {seconds['highway']:.0f} s, fast {seconds['fast']:.0f} s.",
        "",
    ]
    (RESULTS / "town_fidelity.md").write_text("\n".join(lines))
    print("\n".join(lines))


if __name__ == "__main__":
    main()
