"""Cost per frame of the camera (and its masks, and the line/lane perception built on it).

    .venv/bin/python benchmarks/camera_cost.py [--states 60] [--repeats 5]

WorldStates are recorded first (random actions on follow-line, follow-lane and highway with regular
traffic, so the camera draws vehicles too); then each renderer runs over all of them, ``--repeats``
times; the figures are the median over repeats of the mean wall time and of the mean process CPU
time per frame (CPU time is less disturbed by other jobs on a shared machine; the load average is
recorded). One thread (torch too).
Targets (issue 4): 84 x 84 ≤ 1 ms, 256 x 256 ≤ 4 ms.
"""

from __future__ import annotations

import json
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np

os.environ.setdefault("PYGAME_HIDE_SUPPORT_PROMPT", "1")

import torch  # noqa: E402

from drivelab.envs.core import DriveEnv  # noqa: E402
from drivelab.perception.camera import PinholeModel, render_camera, render_masks  # noqa: E402
from drivelab.perception.lane import LANE_CAMERA, LaneState, classical_lane_masks  # noqa: E402
from drivelab.perception.line import LineState  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from provenance import Parser, cpu_isa, whole  # noqa: E402

RESULTS = Path(__file__).parent / "results"
SCENES = {
    "follow-line": {"action": "seed_line", "traffic": "empty"},
    "follow-lane": {"action": "seed_lane", "traffic": "empty"},
    "highway": {"action": "meta", "traffic": "regular"},
}


def record(scenario: str, count: int, seed: int = 0) -> list:
    env = DriveEnv(
        scenario, obs="kinematics", reward="metadrive_course", backend="highway", **SCENES[scenario]
    )
    rng = np.random.default_rng(seed)
    env.reset(seed=seed)
    worlds = []
    while len(worlds) < count:
        _, _, terminated, truncated, _ = env.step(int(rng.integers(env.action_space.n)))
        worlds.append(env.world)
        if terminated or truncated:
            env.reset()
    return worlds


def per_frame_ms(function, inputs: list, repeats: int) -> tuple[float, float]:
    """(wall, CPU) milliseconds per call: medians over repeats of the mean over ``inputs``."""
    function(inputs[0])  # warm caches (per-road geometry)
    wall, cpu = [], []
    for _ in range(repeats):
        start, start_cpu = time.perf_counter(), time.process_time()
        for item in inputs:
            function(item)
        wall.append((time.perf_counter() - start) / len(inputs) * 1e3)
        cpu.append((time.process_time() - start_cpu) / len(inputs) * 1e3)
    return float(np.median(wall)), float(np.median(cpu))


def main() -> None:
    parser = Parser(description=__doc__.splitlines()[0])
    parser.add_argument("--states", type=whole(), default=60)
    parser.add_argument("--repeats", type=whole(), default=5)
    args = parser.parse_args()
    torch.set_num_threads(1)
    rows = []
    load_before = os.getloadavg()

    def add(scene: str, what: str, function, inputs: list) -> None:
        wall, cpu = per_frame_ms(function, inputs, args.repeats)
        rows.append({"scene": scene, "what": what, "wall_ms": wall, "cpu_ms": cpu})
        print(rows[-1], flush=True)

    for scenario in SCENES:
        worlds = record(scenario, args.states)
        for size in (84, 256):
            model = PinholeModel(width=size, height=size)
            add(scenario, f"camera {size}x{size}", lambda w, m=model: render_camera(w, m), worlds)
        if scenario == "follow-line":
            add(scenario, "masks 160x120", lambda w: render_masks(w, LANE_CAMERA), worlds)
            add(scenario, "line state (160x120 camera + HSV + opening)", LineState().observe, worlds)
        if scenario == "follow-lane":
            frames = [render_camera(w, LANE_CAMERA) for w in worlds]
            add(scenario, "classical lane detector on a 160x120 frame", classical_lane_masks, frames)
            add(scenario, "lane CNN on a 160x120 frame", LaneState(detector="cnn").network.segment, frames)
            add(
                scenario,
                "lane state (160x120 camera + CNN + centres)",
                LaneState(detector="cnn").observe,
                worlds,
            )
    result = {
        "command": "python " + " ".join(sys.argv),
        "machine": f"{cpu_isa()}, {os.cpu_count()} cores (shared with other jobs), "
        f"Python {platform.python_version()}",
        "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
        "load_average_1min_before_after": [load_before[0], os.getloadavg()[0]],
        "states_per_scene": args.states,
        "repeats": args.repeats,
        "rows": rows,
    }
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / "camera_cost.json").write_text(json.dumps(result, indent=2))
    lines = [
        "# Camera cost per frame",
        "",
        f"Command: `{result['command']}`  ",
        f"Machine: {result['machine']}; {result['date']}. {args.states} recorded WorldStates per scene; "
        f"median over {args.repeats} repeats of the mean time per frame, one thread. Load average (1 min) "
        f"{result['load_average_1min_before_after'][0]:.1f} before, "
        f"{result['load_average_1min_before_after'][1]:.1f} after, on {os.cpu_count()} cores.",
        "",
        "| scene | what | wall ms per frame | CPU ms per frame |",
        "|---|---|---|---|",
        *[f"| {r['scene']} | {r['what']} | {r['wall_ms']:.2f} | {r['cpu_ms']:.2f} |" for r in rows],
        "",
    ]
    (RESULTS / "camera_cost.md").write_text("\n".join(lines))
    print("\n".join(lines))


if __name__ == "__main__":
    main()
