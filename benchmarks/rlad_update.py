"""One RLAD update (Table II's networks, batch 256) with and without the fast update (fast.py), per
camera size and torch thread count, and torch.profiler's top operators.

    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/rlad_update.py [--device cpu] [--size 84] \\
        [--threads 1 2] [--variants plain fast compiled]
    python benchmarks/rlad_update.py --device cuda --size 84 256 \\
        --variants plain fast compiled cuda-graphs cuda-graphs-bf16 --profile

Variants (``-H`` hyper-parameters of RLAD):

- ``plain``: ``RLAD.train_step`` as it has always been;
- ``fast``: ``fast_update=true`` (eager: randomness drawn up front, A-LIX on the device, fused
  Adam, foreach EMA, no host synchronisation);
- ``fast-nhwc``: ``fast`` with ``channels_last=true``;
- ``compiled``: ``fast`` with ``compile=default`` (inductor);
- ``cuda-graphs``: ``fast`` with ``compile=reduce-overhead`` (CUDA graphs on a GPU);
- ``cuda-graphs-bf16``: ``cuda-graphs`` with ``bf16=true`` (bfloat16 autocast: changes the result
  at ~1e-2 relative, fast.py).

The agent's replay is filled with random frames (the update's cost does not depend on what the
pixels show) and keeps them where ``replay_frames=auto`` puts them (the GPU when it has room).
Each measured call is a whole update as ``learn`` runs it: replay sample, copy, DrQ shifts, the
update (the fast update without reading its metrics back). Warm-up: one update (plain, fast) or
three (compiled: the first compiles; its time is reported). Repeats are interleaved across
variants so that a shared machine's load falls on all of them alike; the figure is the median
over repeats of the mean wall time per update (the GPU synchronised before each clock read).
``--profile`` runs ``--profile-updates`` more updates of each variant under torch.profiler and
writes the top operators by self time into the results.

Writes ``results/<out>.json`` and ``.md`` (``--out``, default ``rlad_update_<cpu|gpu>``).
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
from gymnasium import spaces
from torch.profiler import ProfilerActivity, profile

from drivelab.agents.rlad.sac import RLAD

sys.path.insert(0, str(Path(__file__).resolve().parent))
from provenance import Parser, command_line, cpu_isa, device, whole  # noqa: E402

RESULTS = Path(__file__).parent / "results"
VARIANTS = {
    "plain": {},
    "fast": {"fast_update": True},
    "fast-nhwc": {"fast_update": True, "channels_last": True},
    "compiled": {"fast_update": True, "compile": "default"},
    "cuda-graphs": {"fast_update": True, "compile": "reduce-overhead"},
    "cuda-graphs-bf16": {"fast_update": True, "compile": "reduce-overhead", "bf16": True},
}


def make_agent(size: int, batch: int, device: str, hyperparams: dict, seed: int = 0) -> RLAD:
    """An RLAD agent (Table II, 84 or 256 px, stack 3) with a replay of 2·``batch`` random transitions."""
    space = spaces.Dict(
        {
            "camera": spaces.Box(0, 255, (size, size, 9), np.uint8),
            "waypoints": spaces.Box(-50.0, 50.0, (10, 2), np.float32),
            "measurements": spaces.Box(-1.0, 1.0, (6,), np.float32),
        }
    )
    actions = spaces.Box(np.array([0.0, -1.0], np.float32), np.array([1.0, 1.0], np.float32))
    config = {"batch_size": batch, "buffer_size": 2 * batch, "device": device, **hyperparams}
    agent = RLAD(space, actions, seed, config)
    rng = np.random.default_rng(seed)
    replay = agent.replay_buffer

    def record():
        frame = rng.integers(0, 256, (3, size, size), dtype=np.uint8)
        return frame, rng.normal(size=(10, 2)), rng.uniform(-1, 1, 6), int(rng.integers(0, 3))

    replay.start_episode(*record())
    for step in range(2 * batch):
        replay.add(rng.uniform(-1, 1, 2), float(rng.normal()), (step + 1) % 100 == 0, *record())
    return agent


def updater(agent: RLAD):
    """One update as ``learn`` runs it (the fast update's metrics stay on the device)."""
    return agent._fast_update if agent.config.fast_update else agent.train_step


def timed_ms(update, calls: int, sync) -> float:
    sync()
    start = time.perf_counter()
    for _ in range(calls):
        update()
    sync()
    return (time.perf_counter() - start) / calls * 1e3


def profile_table(update, calls: int, cuda: bool, sync, top: int) -> dict[str, str]:
    activities = [ProfilerActivity.CPU] + ([ProfilerActivity.CUDA] if cuda else [])
    with profile(activities=activities) as prof:
        for _ in range(calls):
            update()
        sync()
    averages = prof.key_averages()
    tables = {"self CPU time": averages.table(sort_by="self_cpu_time_total", row_limit=top)}
    if cuda:
        tables["self CUDA time"] = averages.table(sort_by="self_cuda_time_total", row_limit=top)
    return tables


def main() -> None:
    parser = Parser(description=__doc__.splitlines()[0])
    parser.add_argument("--device", type=device, default="cpu", help="cpu or cuda")
    parser.add_argument("--size", type=whole(), nargs="+", default=[84], help="camera sizes (px)")
    parser.add_argument("--batch-size", type=whole(), default=256)
    parser.add_argument("--threads", type=whole(), nargs="+", default=[1], help="torch thread counts")
    parser.add_argument(
        "--variants", nargs="+", choices=list(VARIANTS), default=["plain", "fast", "compiled"]
    )
    parser.add_argument("--updates", type=whole(), default=1, help="updates per repeat")
    parser.add_argument("--repeats", type=whole(), default=3)
    parser.add_argument("--profile", action="store_true", help="torch.profiler tables of each variant")
    parser.add_argument("--profile-updates", type=whole(), default=3)
    parser.add_argument("--top", type=whole(), default=15, help="operators per profiler table")
    parser.add_argument("--out", default=None, help="result file name in results/ (no suffix)")
    args = parser.parse_args()
    cuda = args.device.startswith("cuda")
    sync = torch.cuda.synchronize if cuda else (lambda: None)
    load_before = os.getloadavg()
    rows, profiles = [], {}
    failures: list[dict] = []  # a variant that fails is reported and the others go on

    def failed(size: int, name: str, exc: Exception) -> None:
        message = f"{type(exc).__name__}: {str(exc).strip().splitlines()[0] if str(exc).strip() else ''}"
        failures.append({"size": size, "variant": name, "error": message})
        print(f"{size} px {name}: failed: {message}", flush=True)

    for size in args.size:
        agents, first = {}, {}
        for name in args.variants:
            torch.set_num_threads(args.threads[0])
            try:
                agent = make_agent(size, args.batch_size, args.device, VARIANTS[name])
                update = updater(agent)
                sync()
                start = time.perf_counter()
                update()
                sync()
                first[name] = time.perf_counter() - start
                for _ in range(2 if agent.config.compile != "none" else 0):  # CUDA graphs record, then replay
                    update()
            except Exception as exc:  # noqa: BLE001 - reported in the results
                failed(size, name, exc)
                continue
            agents[name] = agent
            print(f"{size} px {name}: first update {first[name]:.1f} s", flush=True)
        for threads in args.threads:
            torch.set_num_threads(threads)
            samples: dict[str, list[float]] = {name: [] for name in agents}
            for _ in range(args.repeats):
                for name in list(agents):  # interleaved
                    try:
                        samples[name].append(timed_ms(updater(agents[name]), args.updates, sync))
                    except Exception as exc:  # noqa: BLE001 - reported in the results
                        failed(size, name, exc)
                        del agents[name], samples[name]
            for name in samples:
                row = {
                    "size": size, "threads": threads, "variant": name, "hyperparams": VARIANTS[name],
                    "median_ms": float(np.median(samples[name])), "samples_ms": samples[name],
                    "first_update_s": first[name],
                }  # fmt: skip
                rows.append(row)
                print(f"{size} px, {threads} threads, {name}: {row['median_ms']:.1f} ms", flush=True)
            if args.profile:
                for name in agents:
                    key = f"{name}, {size} px, {threads} threads"
                    try:
                        profiles[key] = profile_table(
                            updater(agents[name]), args.profile_updates, cuda, sync, args.top
                        )
                    except Exception as exc:  # noqa: BLE001 - reported in the results
                        failed(size, f"{name} (profiler)", exc)
        del agents
        if rows:  # each size as soon as it is done; never a results file without a timing
            write_results(args, rows, profiles, failures, load_before, cuda)
    if not rows:
        print(f"error: every variant failed ({len(failures)}); no results written", file=sys.stderr)
        raise SystemExit(1)


def write_results(
    args, rows: list[dict], profiles: dict, failures: list[dict], load_before, cuda: bool
) -> None:
    """``results/<out>.json`` and ``.md`` of the rows measured so far."""
    plain = {(r["size"], r["threads"]): r["median_ms"] for r in rows if r["variant"] == "plain"}
    for row in rows:
        base = plain.get((row["size"], row["threads"]))
        row["speedup_vs_plain"] = base / row["median_ms"] if base else None
    where = "gpu" if cuda else "cpu"
    device_name = torch.cuda.get_device_name() if cuda else "networks on the CPU"
    result = {
        "command": command_line(),
        "machine": f"{cpu_isa()}, {os.cpu_count()} cores, Python {platform.python_version()}, "
        f"torch {torch.__version__}, {device_name}",
        "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
        "load_average_1min_before_after": [load_before[0], os.getloadavg()[0]],
        "batch_size": args.batch_size, "repeats": args.repeats, "updates_per_repeat": args.updates,
        "rows": rows, "failures": failures, "profiles": profiles,
    }  # fmt: skip
    RESULTS.mkdir(exist_ok=True)
    name = args.out or f"rlad_update_{where}"
    (RESULTS / f"{name}.json").write_text(json.dumps(result, indent=2))
    load = result["load_average_1min_before_after"]
    lines = [
        f"# One RLAD update, plain and fast ({where.upper()})",
        "",
        f"Command: `{result['command']}`  ",
        f"Machine: {result['machine']}; {result['date']}. Load average (1 min) {load[0]:.1f} before, "
        f"{load[1]:.1f} after. Table II's networks, batch {args.batch_size}, stack 3; a whole update "
        f"(sample, copy, shifts, update); median over {args.repeats} interleaved repeats of the mean "
        f"over {args.updates} update(s), wall time.",
        "",
        "| camera | threads | variant | ms per update | speed-up vs plain | first update (s) |",
        "|---|---|---|---|---|---|",
        *[
            f"| {r['size']}x{r['size']} | {r['threads']} | {r['variant']} | {r['median_ms']:.1f} | "
            f"{r['speedup_vs_plain']:.2f} | {r['first_update_s']:.1f} |"
            if r["speedup_vs_plain"]
            else f"| {r['size']}x{r['size']} | {r['threads']} | {r['variant']} | {r['median_ms']:.1f} | - | "
            f"{r['first_update_s']:.1f} |"
            for r in rows
        ],
        "",
    ]
    if failures:
        lines += ["Variants that failed (not timed):", "", "| camera | variant | error |", "|---|---|---|"]
        lines += [f"| {f['size']}x{f['size']} | {f['variant']} | {f['error']} |" for f in failures] + [""]
    for key, tables in profiles.items():
        for title, table in tables.items():
            lines += [f"torch.profiler, {key}, {args.profile_updates} updates, by {title}:", "", "```", table,
                      "```", ""]  # fmt: skip
    (RESULTS / f"{name}.md").write_text("\n".join(lines))
    print("\n".join(lines))


if __name__ == "__main__":
    main()
