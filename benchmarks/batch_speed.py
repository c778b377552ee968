"""Batch speed: K worlds in one VectorDriveEnv against one DriveEnv, in one run.

    OMP_NUM_THREADS=1 NUMBA_NUM_THREADS=1 .venv/bin/python benchmarks/batch_speed.py \
        [--steps 3000] [--repeats 5] [--baseline-repo PATH]

Random actions, resets included (NEXT_STEP autoreset in the vector env; the single env resets
when an episode ends). Every number is env steps per second of all worlds together; each row's
ratio is the median over interleaved repeats of (vector rate / single rate) measured back to back.

- Sensors on highway, regular traffic: kinematics, LiDAR 240, topdown 84×84 (K = 64 vs one world).
- Every scenario the compiled core runs, kinematics (K = 64 vs one world).
- Threads: K = 256 on highway kinematics with ``NUMBA_NUM_THREADS=2`` against 1, each in its own
  subprocess (numba reads the variable at import).
- ``--baseline-repo``: a checkout of an earlier drivelab (e.g. ``git worktree add /tmp/base
  57c1874``) whose single highway DriveEnv is timed in a subprocess in the same repeats, so that
  "the single world did not get slower" is a same-run comparison; and K town worlds of it and of
  this tree, each in a subprocess.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import subprocess
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from provenance import Parser, command_line, cpu_isa, whole  # noqa: E402

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("NUMBA_NUM_THREADS", "1")
os.environ.setdefault("PYGAME_HIDE_SUPPORT_PROMPT", "1")


RESULTS = Path(__file__).parent / "results"
SENSORS = {"kinematics": "kinematics", "lidar 240": "lidar:beams=240", "topdown 84x84": "topdown"}


def single_rate(scenario: str, obs: str, steps: int, seed: int) -> float:
    """Steps/s of one DriveEnv, random actions, reset at every episode end."""
    from drivelab.envs.core import DriveEnv

    env = DriveEnv(scenario, obs=obs)
    env.action_space.seed(seed)
    actions = [env.action_space.sample() for _ in range(steps)]
    env.reset(seed=seed)
    for action in actions[:20]:  # compile and warm up outside the clock
        if any(env.step(action)[2:4]):
            env.reset()
    start = time.perf_counter()
    for action in actions:
        _, _, terminated, truncated, _ = env.step(action)
        if terminated or truncated:
            env.reset()
    return steps / (time.perf_counter() - start)


def vector_rate(scenario: str, obs: str, worlds: int, steps: int, seed: int) -> float:
    """Env steps/s of all ``worlds`` of one VectorDriveEnv together."""
    from drivelab.envs.vector import VectorDriveEnv

    vector = VectorDriveEnv(worlds, scenario=scenario, obs=obs)
    vector.action_space.seed(seed)
    batches = [vector.action_space.sample() for _ in range(max(steps // worlds, 5))]
    vector.reset(seed=seed)
    for actions in batches[:3]:
        vector.step(actions)
    start = time.perf_counter()
    for actions in batches:
        vector.step(actions)
    return len(batches) * worlds / (time.perf_counter() - start)


def _subprocess_rate(argv: list[str], env_vars: dict[str, str], cwd: str | None = None) -> float:
    env = {**os.environ, **env_vars}
    out = subprocess.run(argv, capture_output=True, text=True, env=env, cwd=cwd, check=True).stdout
    return float(out.strip().splitlines()[-1])


def threaded_rate(threads: int, worlds: int, steps: int, seed: int) -> float:
    argv = [sys.executable, __file__, "--worker", "vector", "--worlds", str(worlds), "--steps", str(steps),
            "--seed", str(seed)]  # fmt: skip
    return _subprocess_rate(argv, {"NUMBA_NUM_THREADS": str(threads), "OMP_NUM_THREADS": "1"})


def baseline_rate(
    repo: str, steps: int, seed: int, scenario: str = "highway", env_kwargs: str = "obs='kinematics'"
) -> float:
    """One DriveEnv (highway, kinematics by default; ``env_kwargs`` as Python keyword arguments) of
    the drivelab checked out at ``repo``, random actions, in a subprocess."""
    code = (
        "import sys, time; from drivelab.envs.core import DriveEnv\n"
        f"env = DriveEnv({scenario!r}, {env_kwargs}); env.action_space.seed({seed})\n"
        f"acts = [env.action_space.sample() for _ in range({steps})]; env.reset(seed={seed})\n"
        "for a in acts[:20]:\n    r = env.step(a)\n    (r[2] or r[3]) and env.reset()\n"
        "t = time.perf_counter()\n"
        "for a in acts:\n    r = env.step(a)\n    (r[2] or r[3]) and env.reset()\n"
        f"print({steps} / (time.perf_counter() - t))\n"
    )
    return _subprocess_rate([sys.executable, "-c", code], {"PYTHONPATH": repo}, cwd=repo)


def repo_vector_rate(repo: str, scenario: str, worlds: int, steps: int, seed: int) -> float:
    """:func:`vector_rate` (kinematics) of the drivelab checked out at ``repo``, in a subprocess."""
    code = (
        "import time; from drivelab.envs.vector import VectorDriveEnv\n"
        f"env = VectorDriveEnv({worlds}, scenario={scenario!r}, obs='kinematics')\n"
        f"env.action_space.seed({seed})\n"
        f"acts = [env.action_space.sample() for _ in range({max(steps // worlds, 5)})]\n"
        f"env.reset(seed={seed})\n"
        "for a in acts[:3]:\n    env.step(a)\n"
        "t = time.perf_counter()\n"
        "for a in acts:\n    env.step(a)\n"
        f"print(len(acts) * {worlds} / (time.perf_counter() - t))\n"
    )
    return _subprocess_rate([sys.executable, "-c", code], {"PYTHONPATH": repo}, cwd=repo)


def _median_ratio(pairs: list[tuple[float, float]]) -> dict:
    return {
        "reference_steps_per_s": statistics.median(a for a, _ in pairs),
        "steps_per_s": statistics.median(b for _, b in pairs),
        "ratio_median": statistics.median(b / a for a, b in pairs),
    }


def main() -> None:
    parser = Parser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=whole(4), default=3000, help="env steps per measurement")
    parser.add_argument("--repeats", type=whole(), default=5)
    parser.add_argument("--worlds", type=whole(), default=64)
    parser.add_argument("--baseline-repo", default=None)
    parser.add_argument("--seed", type=whole(0), default=0)
    parser.add_argument("--worker", choices=["vector"], default=None, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.worker:
        print(vector_rate("highway", "kinematics", args.worlds, args.steps, args.seed))
        return

    from drivelab.scenarios import FAST_SCENARIOS as SUPPORTED

    cases = [("highway", name, spec) for name, spec in SENSORS.items()]
    cases += [(scenario, "kinematics", "kinematics") for scenario in SUPPORTED if scenario != "highway"]
    pairs: dict[tuple[str, str], list[tuple[float, float]]] = {(s, n): [] for s, n, _ in cases}
    threads, baseline, town_baseline = [], [], []
    here = str(Path(__file__).resolve().parent.parent)
    for repeat in range(args.repeats):
        for scenario, name, spec in cases:
            steps = args.steps if name != "topdown 84x84" else args.steps // 4
            one = single_rate(scenario, spec, steps, repeat)
            many = vector_rate(scenario, spec, args.worlds, steps * 2, repeat)
            pairs[(scenario, name)].append((one, many))
            print(
                f"repeat {repeat} {scenario:12s} {name:14s} one {one:8.0f}/s  K={args.worlds} {many:8.0f}/s"
            )
        threads.append(
            (threaded_rate(1, 256, 4 * args.steps, repeat), threaded_rate(2, 256, 4 * args.steps, repeat))
        )
        print(f"repeat {repeat} K=256 1 thread {threads[-1][0]:.0f}/s, 2 threads {threads[-1][1]:.0f}/s")
        if args.baseline_repo:
            current = single_rate("highway", "kinematics", args.steps, repeat)
            baseline.append((baseline_rate(args.baseline_repo, args.steps, repeat), current))
            print(f"repeat {repeat} single highway: baseline {baseline[-1][0]:.0f}/s, now {current:.0f}/s")
            town_baseline.append(
                tuple(
                    repo_vector_rate(repo, "town", args.worlds, args.steps * 2, repeat)
                    for repo in (args.baseline_repo, here)
                )
            )
            print(f"repeat {repeat} town K={args.worlds}: baseline {town_baseline[-1][0]:.0f}/s, now "
                  f"{town_baseline[-1][1]:.0f}/s")  # fmt: skip
    rows = [{"scenario": s, "sensor": n, **_median_ratio(pairs[(s, n)])} for s, n, _ in cases]
    result = {
        "command": command_line(),
        "machine": f"{cpu_isa()}, {os.cpu_count()} cores, "
        f"Python {platform.python_version()}",
        "date": time.strftime("%Y-%m-%d"),
        "repeats": args.repeats,
        "worlds": args.worlds,
        "rows": rows,
        "threads_k256": _median_ratio(threads),
        "single_vs_baseline": _median_ratio(baseline) if baseline else None,
        "town_vector_vs_baseline": _median_ratio(town_baseline) if town_baseline else None,
        "baseline_repo_commit": _commit(args.baseline_repo) if args.baseline_repo else None,
    }
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / "batch_speed.json").write_text(json.dumps(result, indent=2))
    lines = [
        f"# Batch speed: {args.worlds} worlds in one VectorDriveEnv against one DriveEnv",
        "",
        f"Command: `{result['command']}`  ",
        f"Machine: {result['machine']}; date {result['date']}; {args.repeats} interleaved repeats, "
        "one thread.",
        "",
        "Random actions, resets included, regular traffic. Rates are env steps/s of all worlds together;",
        "the ratio is the median of the per-repeat ratios (vector / single, measured back to back).",
        "",
        f"| scenario | sensor | one DriveEnv steps/s | K = {args.worlds} steps/s | ratio |",
        "|---|---|---|---|---|",
        *[
            f"| {r['scenario']} | {r['sensor']} | {r['reference_steps_per_s']:.0f} | "
            f"{r['steps_per_s']:.0f} | {r['ratio_median']:.2f}x |"
            for r in rows
        ],
        "",
        "Threads (numba `prange` over worlds), highway kinematics, K = 256:",
        "",
        "| 1 thread steps/s | 2 threads steps/s | ratio |",
        "|---|---|---|",
        "| {reference_steps_per_s:.0f} | {steps_per_s:.0f} | {ratio_median:.2f}x |".format(
            **result["threads_k256"]
        ),
        "",
    ]
    if baseline:
        b = result["single_vs_baseline"]
        lines += [
            f"One highway DriveEnv (kinematics), this tree against {result['baseline_repo_commit']}: "
            f"{b['steps_per_s']:.0f} vs {b['reference_steps_per_s']:.0f} steps/s ({b['ratio_median']:.2f}x).",
            "",
        ]
        t = result["town_vector_vs_baseline"]
        lines += [
            f"The town, K = {args.worlds} worlds (kinematics), this tree against "
            f"{result['baseline_repo_commit']}, each in a subprocess: {t['steps_per_s']:.0f} vs "
            f"{t['reference_steps_per_s']:.0f} steps/s ({t['ratio_median']:.2f}x).",
            "",
        ]
    (RESULTS / "batch_speed.md").write_text("\n".join(lines))
    print("\n".join(lines))


def _commit(repo: str) -> str:
    out = subprocess.run(["git", "-C", repo, "rev-parse", "--short", "HEAD"], capture_output=True, text=True)
    return out.stdout.strip() or repo


if __name__ == "__main__":
    main()
