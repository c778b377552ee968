"""Where one RLAD update spends its time: replay sampling, the host-to-device copy with the DrQ
shifts, the whole update, and torch.profiler's top operators.

    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/rlad_profile.py [--device cuda] [--size 84]

The agent (Table II's networks, batch ``--batch-size``) fills its replay from the town with
random actions, then each part is timed on its own (median over ``--repeats`` of the mean over
``--updates`` calls, the GPU synchronised before every clock read) and ``--updates`` updates run
under torch.profiler. Writes ``results/rlad_profile_<gpu|cpu>_<size>_<host|device>.{json,md}``
(where the replay kept its frames).
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
from torch.profiler import ProfilerActivity, profile

from drivelab.agents.rlad.sac import RLAD
from drivelab.envs.core import DriveEnv

sys.path.insert(0, str(Path(__file__).resolve().parent))
from provenance import Parser, command_line, cpu_isa, device, mapping, whole  # noqa: E402

RESULTS = Path(__file__).parent / "results"


def timed_ms(function, calls: int, repeats: int, sync) -> float:
    """Median over ``repeats`` of the mean wall milliseconds per call (after one warm-up call)."""
    function()
    means = []
    for _ in range(repeats):
        sync()
        start = time.perf_counter()
        for _ in range(calls):
            function()
        sync()
        means.append((time.perf_counter() - start) / calls * 1e3)
    return float(np.median(means))


def main() -> None:
    parser = Parser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--device", type=device, default="cpu", help="cpu or cuda: where the agent's networks run"
    )
    parser.add_argument("--size", type=whole(), default=84, help="camera width and height")
    parser.add_argument("--batch-size", type=whole(), default=256)
    parser.add_argument("--updates", type=whole(), default=10, help="calls per repeat, and updates profiled")
    parser.add_argument("--repeats", type=whole(), default=3)
    parser.add_argument("--top", type=whole(), default=15, help="operators listed per table")
    parser.add_argument(
        "--replay-frames",
        choices=("auto", "host", "device"),
        default="auto",
        help="auto, host or device (RLAD's replay_frames)",
    )
    parser.add_argument(
        "--hyperparams",
        type=mapping,
        default="{}",
        help='JSON of more RLAD hyper-parameters, e.g. {"fast_update": true}',
    )
    args = parser.parse_args()
    torch.set_num_threads(1)
    cuda = args.device.startswith("cuda")
    sync = torch.cuda.synchronize if cuda else (lambda: None)
    env = DriveEnv(
        "town",
        obs=f"camera:width={args.size}:height={args.size}:stack=3,waypoints,measurements:stack=3",
        action="target_speed",
        reward="roach",
        traffic="regular",
    )
    agent = RLAD(
        env.observation_space,
        env.action_space,
        0,
        {
            "batch_size": args.batch_size,
            "buffer_size": 4 * args.batch_size,
            "device": args.device,
            "replay_frames": args.replay_frames,
            **args.hyperparams,
        },
        env,
    )
    frames_on = "device" if agent.replay_buffer.frame_device is not None else "host"
    agent.learn(2 * args.batch_size)  # warm-up steps only (learning_starts 1000): fills the replay
    batch = agent.replay_buffer.sample(args.batch_size, agent.rng)
    parts = {
        "replay sample (frame gather)": lambda: agent.replay_buffer.sample(args.batch_size, agent.rng),
        "to device + DrQ shifts": lambda: agent._batch_tensors(batch),
        "update on a fixed batch (no sampling)": lambda: agent.train_step(batch),
        "update (sample + copy + update)": agent.train_step,
    }
    rows = {name: timed_ms(fn, args.updates, args.repeats, sync) for name, fn in parts.items()}
    for name, value in rows.items():
        print(f"{name}: {value:.1f} ms", flush=True)
    activities = [ProfilerActivity.CPU] + ([ProfilerActivity.CUDA] if cuda else [])
    with profile(activities=activities) as prof:
        for _ in range(args.updates):
            agent.train_step()
        sync()
    averages = prof.key_averages()
    tables = {"self CPU time": averages.table(sort_by="self_cpu_time_total", row_limit=args.top)}
    if cuda:
        tables["self CUDA time"] = averages.table(sort_by="self_cuda_time_total", row_limit=args.top)
    result = {
        "command": command_line(),
        "machine": f"{cpu_isa()}, {os.cpu_count()} cores, Python {platform.python_version()}, "
        f"torch {torch.__version__}, 1 torch thread, "
        + (torch.cuda.get_device_name() if cuda else "networks on the CPU"),
        "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
        "size": args.size,
        "batch_size": args.batch_size,
        "replay_frames": frames_on,
        "hyperparams": args.hyperparams,
        "ms": rows,
    }
    RESULTS.mkdir(exist_ok=True)
    fast = "_fast" if agent.config.fast_update else ""
    name = f"rlad_profile_{'gpu' if cuda else 'cpu'}_{args.size}_{frames_on}{fast}"
    (RESULTS / f"{name}.json").write_text(json.dumps(result, indent=2))
    lines = [
        f"# Where an RLAD update spends its time ({'GPU' if cuda else 'CPU'})",
        "",
        f"Command: `{result['command']}`  ",
        f"Machine: {result['machine']}; {result['date']}. Camera {args.size}x{args.size}, stack 3, batch "
        f"{args.batch_size}, Table II's networks, replay frames on the {frames_on}. Median over "
        f"{args.repeats} repeats of the mean over "
        f"{args.updates} calls, wall time.",
        "",
        "| part | ms |",
        "|---|---|",
        *[f"| {part} | {value:.1f} |" for part, value in rows.items()],
        "",
    ]
    for title, table in tables.items():
        lines += [f"torch.profiler, {args.updates} updates, by {title}:", "", "```", table, "```", ""]
    (RESULTS / f"{name}.md").write_text("\n".join(lines))
    print("\n".join(lines))


if __name__ == "__main__":
    main()
