"""RLAD and DrQ training on one GPU, several runs at once: steps per second per run once the updates
begin, and how busy the GPU is, the numbers that size ``rlad_ablation.py``'s >= 100 k-step runs.

    python benchmarks/rlad_gpu_training.py [--seconds 160] [--seeds 0 1 2] [--algos rlad drq]

Starts one ``drivelab train`` process per algorithm and seed at once on the training town (regular
traffic, RLAD's observation at 84x84, Roach's reward, Table II's settings, ``-H device=cuda
fast_update=true compile=reduce-overhead``: the fast update with CUDA graphs, frames in GPU memory),
samples ``nvidia-smi`` every 5 s, and stops the processes after ``--seconds``. A run's rate is read
from its ``monitor.csv``: the steps between the first episode end at or after ``learning_starts``
and the last, over the time between them, so the warm-up of random actions and the compiles (numba's,
inductor's) are left out. Writes ``results/<out>.json`` and ``.md`` (default ``rlad_gpu_training``).
"""

from __future__ import annotations

import csv
import json
import os
import platform
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from provenance import Parser, command_line, cpu_isa, positive, stop, whole  # noqa: E402

RESULTS = Path(__file__).parent / "results"
LEARNING_STARTS = 1000  # RLAD's default (Table II)
OBS = "camera:stack=3,waypoints,measurements:stack=3"


def train_command(algo: str, seed: int, steps: int, runs: Path) -> list[str]:
    return [
        sys.executable, "-m", "drivelab.cli", "train", "--algo", algo, "--env", "town", "--obs", OBS,
        "--action", "target_speed", "--reward", "roach", "--traffic", "regular", "--steps", str(steps),
        "--eval-every", str(steps), "--seed", str(seed), "--name", f"{algo}-{seed}",
        "--runs-dir", str(runs),
        "-H", "device=cuda", "-H", "fast_update=true", "-H", "compile=reduce-overhead",
    ]  # fmt: skip


def run_rate(monitor: Path, learning_starts: int = LEARNING_STARTS) -> dict:
    """Episodes, steps and seconds of one run's ``monitor.csv``, and its steps per second once updating
    (None with fewer than two episode ends after ``learning_starts``)."""
    lines = monitor.read_text().splitlines()[1:]  # the first line is the monitor's JSON header
    steps, points = 0, []
    for episode in csv.DictReader(lines):
        steps += int(episode["l"])
        points.append((steps, float(episode["t"])))
    learning = [p for p in points if p[0] >= learning_starts]
    rate = None
    if len(learning) > 1 and learning[-1][1] > learning[0][1]:
        rate = (learning[-1][0] - learning[0][0]) / (learning[-1][1] - learning[0][1])
    return {
        "run": monitor.parent.name, "episodes": len(points), "steps": steps,
        "seconds": points[-1][1] if points else None, "steps_per_s_updating": rate,
    }  # fmt: skip


def gpu_samples(text: str) -> list[dict]:
    """``nvidia-smi --query-gpu=timestamp,utilization.gpu,memory.used --format=csv`` rows."""
    rows = []
    for row in csv.reader(text.splitlines()[1:]):
        if len(row) == 3:
            rows.append({"utilisation": int(row[1].split()[0]), "memory_mib": int(row[2].split()[0])})
    return rows


def markdown(result: dict) -> str:
    rows, util = result["runs"], result["gpu_utilisation_percent_once_updating"]
    rated = [r for r in rows if r["steps_per_s_updating"]]
    lines = [
        "# RLAD and DrQ training on one GPU: several runs at once",
        "",
        f"Command: `{result['command']}`  ",
        f"Machine: {result['machine']}; {result['date']}.",
        "",
        f"{len(rows)} `drivelab train` processes at once ({', '.join(r['run'] for r in rows)}) on the",
        "training town with regular traffic, RLAD's observation (`camera:stack=3,waypoints,",
        "measurements:stack=3`, 84×84), Roach's reward, Table II's settings (batch 256, replay 100 k,",
        "learning starts at 1,000 steps), `-H device=cuda fast_update=true compile=reduce-overhead` (the",
        f"fast update with CUDA graphs, frames in GPU memory), stopped after {result['seconds']:.0f} s.",
        "Steps per second once updating: from each run's `monitor.csv`, the steps between the first",
        "episode end at or after step 1,000 and the last, over the time between them (the random warm-up",
        "and numba's and inductor's compiles are left out).",
        "",
        "| run | episodes | steps reached | seconds (monitor) | steps/s once updating |",
        "|---|---|---|---|---|",
    ]
    for r in rows:
        rate = f"{r['steps_per_s_updating']:.1f}" if r["steps_per_s_updating"] else "-"
        seconds = f"{r['seconds']:.0f}" if r["seconds"] is not None else "-"
        lines.append(f"| {r['run']} | {r['episodes']} | {r['steps']} | {seconds} | {rate} |")
    lines.append("")
    if rated:
        mean = statistics.mean(r["steps_per_s_updating"] for r in rated)
        total = sum(r["steps_per_s_updating"] for r in rated)
        per_algo = {}
        for r in rated:
            per_algo.setdefault(r["run"].rsplit("-", 1)[0], []).append(r["steps_per_s_updating"])
        lines.append(
            f"Together: {total:.0f} training steps (and updates) per second; per run "
            + ", ".join(f"{a} {statistics.mean(v):.1f}" for a, v in per_algo.items())
            + " (means over seeds)."
        )
        if util:
            lines.append(
                "GPU utilisation (nvidia-smi's share of time a kernel runs, every 5 s) once the updates "
                f"began: median {statistics.median(util):.0f} %, {len(util)} samples from {min(util)} to "
                f"{max(util)} %; memory used at most {result['gpu_memory_used_mib_max']} MiB."
            )
        lines += [
            "",
            f"At {mean:.1f} steps/s a run, {len(rows)} runs of 100 k steps at once take about "
            f"{100_000 / mean / 60:.0f} minutes of this machine, all on it (each run's replay is 2.2 GB).",
        ]
    return "\n".join(lines) + "\n"


def main() -> None:
    parser = Parser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=positive, default=160, help="stop the runs after this long")
    parser.add_argument("--seeds", type=whole(0), nargs="+", default=[0, 1, 2])
    parser.add_argument("--algos", nargs="+", choices=["rlad", "drq"], default=["rlad", "drq"])
    parser.add_argument("--steps", type=whole(), default=100_000, help="each run's budget (rarely reached)")
    parser.add_argument("--out", default="rlad_gpu_training", help="result file name in results/ (no suffix)")
    args = parser.parse_args()
    if len(set(args.seeds)) != len(args.seeds):
        stop("--seeds names a seed twice")
    smi = shutil.which("nvidia-smi")
    if smi is None:
        stop("this benchmark needs an NVIDIA GPU: nvidia-smi was not found")
    import torch

    if not torch.cuda.is_available():
        stop("this benchmark needs a CUDA GPU, and torch sees none here")
    runs = Path(tempfile.mkdtemp(prefix="rlad-gpu-training-"))
    sampler = subprocess.Popen(
        [smi, "--query-gpu=timestamp,utilization.gpu,memory.used", "--format=csv", "-l", "5"],
        stdout=subprocess.PIPE, text=True,
    )  # fmt: skip
    processes = {}
    for seed in args.seeds:
        for algo in args.algos:
            log = open(runs / f"{algo}-{seed}.log", "w")  # noqa: SIM115 - closed below
            command = train_command(algo, seed, args.steps, runs)
            process = subprocess.Popen(command, stdout=log, stderr=subprocess.STDOUT)
            processes[f"{algo}-{seed}"] = (process, log)
    start = time.monotonic()
    try:
        while time.monotonic() - start < args.seconds and any(
            p.poll() is None for p, _ in processes.values()
        ):
            time.sleep(1)
    finally:
        for process, log in processes.values():
            process.kill()
            process.wait()
            log.close()
        sampler.terminate()
    samples = gpu_samples(sampler.communicate()[0])
    rows = [run_rate(m) for m in sorted(runs.glob("*/monitor.csv"))]
    busy = next((i for i, s in enumerate(samples) if s["utilisation"] > 50), len(samples))
    result = {
        "command": command_line(),
        "machine": f"{cpu_isa()}, {os.cpu_count()} cores, Python {platform.python_version()}, "
        f"torch {torch.__version__}, {torch.cuda.get_device_name()}",
        "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
        "seconds": args.seconds,
        "runs": rows,
        "gpu_utilisation_percent_once_updating": [s["utilisation"] for s in samples[busy:]],
        "gpu_memory_used_mib_max": max((s["memory_mib"] for s in samples), default=None),
    }
    for name in processes:  # a run that never reached its updates: the end of what it printed
        if not any(r["run"] == name and r["steps_per_s_updating"] for r in rows):
            tail = (runs / f"{name}.log").read_text(errors="replace").splitlines()[-5:]
            print(f"{name} has no rate; the end of its output:", *tail, sep="\n  ")
    shutil.rmtree(runs, ignore_errors=True)
    write_results(result, args.out)


def write_results(result: dict, out: str) -> None:
    """``results/<out>.json`` and ``.md``; none when no run reached its updates (a rate-less table
    would replace the committed one): an ``error:`` line and exit 1."""
    if not any(r["steps_per_s_updating"] for r in result["runs"]):
        print(
            f"error: no run reached its updates in {result['seconds']:g} s; no results written",
            file=sys.stderr,
        )
        raise SystemExit(1)
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / f"{out}.json").write_text(json.dumps(result, indent=2) + "\n")
    text = markdown(result)
    (RESULTS / f"{out}.md").write_text(text)
    print(text)


if __name__ == "__main__":
    main()
