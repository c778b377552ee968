"""RLAD's cost on a CPU: time per update and per environment step at 84×84 and 256×256, and the
replay memory of 100 k transitions at 84×84.

    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/rlad_cost.py [--steps 40] [--repeats 3]

- environment step: ``DriveEnv("town", obs="camera:width=S:height=S:stack=3,waypoints,
  measurements:stack=3", action="target_speed", reward="roach", traffic="regular")`` stepped with
  random actions; the same town with ``--obs waypoints,measurements:stack=3`` is the reference
  (the ratio is the camera's share);
- policy: one ``RLAD.act`` on a batch of one (encoder in evaluation mode, stochastic action);
- update: one ``RLAD.train_step`` with Table II's networks (1024-wide SAC, batch 256, A-LIX, DrQ
  shifts, auxiliary loss) on a replay filled from the town;
- replay: an actually allocated ``FrameReplayBuffer`` of 100 k transitions at 84×84 filled with
  100 k steps of 150-step episodes (frames from a pool of recorded town frames), measured by its own
  accounting (``nbytes``, ``unique_frame_bytes``) and by the process's resident memory.

Figures are medians over ``--repeats`` of the mean per call, as wall and process CPU time (the
machine is shared: CPU time is the steadier one), one torch thread.
"""

from __future__ import annotations

import json
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np
import torch

from drivelab.agents.rlad.replay import FrameReplayBuffer
from drivelab.agents.rlad.sac import REPLAY_FRAMES, RLAD
from drivelab.envs.core import DriveEnv

sys.path.insert(0, str(Path(__file__).resolve().parent))
from provenance import Parser, command_line, cpu_isa, device, whole  # noqa: E402

RESULTS = Path(__file__).parent / "results"
SIZES = (84, 256)


def camera_obs(size: int) -> str:
    return f"camera:width={size}:height={size}:stack=3,waypoints,measurements:stack=3"


def timed(function, calls: int, repeats: int) -> tuple[float, float]:
    """(wall, CPU) milliseconds per call: medians over repeats of the mean over ``calls`` (a GPU
    is synchronised before the clocks are read)."""
    sync = torch.cuda.synchronize if torch.cuda.is_available() else (lambda: None)
    function()  # warm-up
    wall, cpu = [], []
    for _ in range(repeats):
        sync()
        start, start_cpu = time.perf_counter(), time.process_time()
        for _ in range(calls):
            function()
        sync()
        wall.append((time.perf_counter() - start) / calls * 1e3)
        cpu.append((time.process_time() - start_cpu) / calls * 1e3)
    return float(np.median(wall)), float(np.median(cpu))


def stepper(env: DriveEnv, seed: int = 0):
    """A call that takes one random-action step of ``env`` (resetting at episode ends)."""
    rng = np.random.default_rng(seed)
    env.reset(seed=seed)
    low, high = env.action_space.low, env.action_space.high

    def step() -> None:
        _, _, terminated, truncated, _ = env.step(rng.uniform(low, high).astype(np.float32))
        if terminated or truncated:
            env.reset()

    return step


def resident_mib() -> float:
    with open("/proc/self/status") as status:
        line = next(row for row in status if row.startswith("VmRSS"))
    return int(line.split()[1]) / 1024


def replay_memory(frames: list[np.ndarray], transitions: int = 100_000, episode: int = 150) -> dict:
    """Allocate and fill a 100 k replay at 84×84; its accounting and the resident memory it took."""
    before = resident_mib()
    replay = FrameReplayBuffer(transitions, (3, 84, 84), 3, (10, 2), 6, 2)
    waypoints, measurements, action = np.zeros((10, 2)), np.zeros(6), np.zeros(2)
    replay.start_episode(frames[0], waypoints, measurements, 0)
    for step in range(transitions):
        end = (step + 1) % episode == 0
        replay.add(action, 0.0, end, frames[step % len(frames)], waypoints, measurements, 0)
        if end:
            replay.start_episode(frames[(step + 7) % len(frames)], waypoints, measurements, 0)
    unique = replay.unique_frame_bytes()
    naive = replay.size * 2 * 3 * replay.frames[0].nbytes  # obs + next_obs stacks of 3 frames each
    return {
        "transitions": transitions, "episode_length": episode, "sampleable": replay.size,
        "nbytes_mib": replay.nbytes / 2**20, "unique_frame_mib": unique / 2**20,
        "ratio_to_unique_frames": replay.nbytes / unique, "naive_obs_next_obs_mib": naive / 2**20,
        "resident_increase_mib": resident_mib() - before,
    }  # fmt: skip


def row_markdown(row: dict) -> str:
    image = f"{row['size']}x{row['size']}" if row["size"] else "-"
    return f"| {row['what']} | {image} | {row['wall_ms']:.1f} | {row['cpu_ms']:.1f} |"


def main() -> None:
    parser = Parser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--steps", type=whole(), default=40, help="environment steps / policy calls per repeat"
    )
    parser.add_argument("--updates", type=whole(), default=2, help="updates per repeat")
    parser.add_argument("--repeats", type=whole(), default=3)
    parser.add_argument("--batch-size", type=whole(), default=256)
    parser.add_argument(
        "--device", type=device, default="cpu", help="cpu or cuda: where the agent's networks run"
    )
    parser.add_argument(
        "--replay-frames", default="auto", choices=REPLAY_FRAMES, help="where the replay keeps its frames "
        "(RLAD's replay_frames: auto is the device's memory on CUDA, the host's otherwise)",
    )  # fmt: skip
    parser.add_argument("--out", default="rlad_cost", help="result file name (JSON and md) in results/")
    args = parser.parse_args()
    torch.set_num_threads(1)
    load_before = os.getloadavg()
    rows, frames_84 = [], []

    def add(what: str, size: int | None, wall: float, cpu: float) -> None:
        rows.append({"what": what, "size": size, "wall_ms": wall, "cpu_ms": cpu})
        print(rows[-1], flush=True)

    reference = DriveEnv("town", obs="waypoints,measurements:stack=3", action="target_speed",
                         reward="roach", traffic="regular")  # fmt: skip
    add(
        "environment step, no camera (reference)",
        None,
        *timed(stepper(reference), args.steps, args.repeats),
    )
    for size in SIZES:
        env = DriveEnv("town", obs=camera_obs(size), action="target_speed", reward="roach", traffic="regular")
        add("environment step", size, *timed(stepper(env), args.steps, args.repeats))
        agent = RLAD(env.observation_space, env.action_space, 0, {"batch_size": args.batch_size,
                     "buffer_size": 4 * args.batch_size, "device": args.device,
                     "replay_frames": args.replay_frames}, env)  # fmt: skip
        agent.learn(2 * args.batch_size)  # warm-up steps only (learning_starts 1000): fills the replay
        obs, _ = env.reset(seed=1)
        add(
            "policy action (batch of one)",
            size,
            *timed(lambda a=agent, o=obs: a.act(o, False), args.steps, args.repeats),
        )
        add(f"update (batch {args.batch_size})", size, *timed(agent.train_step, args.updates, args.repeats))
        if size == 84:
            frames = agent.replay_buffer.frames[: min(64, agent.replay_buffer.written)]
            frames_84 = list(frames.cpu().numpy() if isinstance(frames, torch.Tensor) else frames.copy())
        del agent
    memory = replay_memory(frames_84)
    print(memory, flush=True)
    by = {(r["what"], r["size"]): r for r in rows}
    where = "GPU" if args.device.startswith("cuda") else "CPU"  # where the networks run
    update = f"update (batch {args.batch_size})"
    clock = "wall_ms" if where == "GPU" else "cpu_ms"  # a GPU's work is not the process's CPU time
    ratios = {
        "environment step 256 / 84 (CPU)": by[("environment step", 256)]["cpu_ms"]
        / by[("environment step", 84)]["cpu_ms"],
        "environment step 84 / no camera (CPU)": by[("environment step", 84)]["cpu_ms"]
        / by[("environment step, no camera (reference)", None)]["cpu_ms"],
        f"update 256 / 84 ({where}, batch {args.batch_size})": by[(update, 256)][clock]
        / by[(update, 84)][clock],
    }
    parts = ("environment step", "policy action (batch of one)", f"update (batch {args.batch_size})")
    for size in SIZES:  # one training step = env step + policy + one update
        total = sum(by[(what, size)]["wall_ms"] for what in parts)
        ratios[f"training steps per second at {size} (wall)"] = 1e3 / total
        ratios[f"days for the paper's 10^6 steps at {size} (wall)"] = total * 1e6 / 1e3 / 86400
    result = {
        "command": command_line(),
        "machine": f"{cpu_isa()}, {os.cpu_count()} cores, "
        f"Python {platform.python_version()}, torch {torch.__version__}, 1 torch thread, "
        + (torch.cuda.get_device_name() if args.device.startswith("cuda") else "networks on the CPU"),
        "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
        "load_average_1min_before_after": [load_before[0], os.getloadavg()[0]],
        "repeats": args.repeats, "steps_per_repeat": args.steps, "updates_per_repeat": args.updates,
        "rows": rows, "ratios": ratios, "replay_100k_84": memory,
    }  # fmt: skip
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / f"{args.out}.json").write_text(json.dumps(result, indent=2))
    load = result["load_average_1min_before_after"]
    lines = [
        f"# RLAD cost ({where})",
        "",
        f"Command: `{result['command']}`  ",
        f"Machine: {result['machine']}; {result['date']}. Median over {args.repeats} repeats of the mean "
        f"per call ({args.steps} steps or policy calls, {args.updates} updates per repeat). Load average "
        f"(1 min) {load[0]:.1f} before, {load[1]:.1f} after, on {os.cpu_count()} cores. Town, regular "
        "traffic, random actions; Table II's networks.",
        "",
        "| what | image | wall ms | CPU ms |",
        "|---|---|---|---|",
        *[row_markdown(r) for r in rows],
        "",
        "| ratio | value |",
        "|---|---|",
        *[f"| {key} | {value:.2f} |" for key, value in ratios.items()],
        "",
        f"Replay of {memory['transitions']:,} transitions at 84x84 (stack 3), allocated and filled with "
        f"{memory['episode_length']}-step episodes: {memory['nbytes_mib']:.0f} MiB by its accounting, "
        f"{memory['unique_frame_mib']:.0f} MiB of unique frames (ratio "
        f"{memory['ratio_to_unique_frames']:.3f}), {memory['sampleable']:,} sampleable; resident memory "
        f"grew by {memory['resident_increase_mib']:.0f} MiB. Storing obs and next_obs stacks would take "
        f"{memory['naive_obs_next_obs_mib']:.0f} MiB.",
        "",
    ]
    (RESULTS / f"{args.out}.md").write_text("\n".join(lines))
    print("\n".join(lines))


if __name__ == "__main__":
    main()
