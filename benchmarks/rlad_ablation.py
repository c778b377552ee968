"""RLAD, DrQ and RLAD's three ablations × 3 seeds in the training town, then NoCrash on the test town.

    .venv/bin/python benchmarks/rlad_ablation.py [--steps N] [--episodes 25] [--workers 1]

1. the runs of ``benchmarks/sweeps/rlad-ablation.yaml`` (as ``drivelab sweep``), RLAD and DrQ
   first: re-running the command skips finished runs and resumes unfinished ones from their last
   checkpoint (``drivelab.training.sweep``), exactly (``drivelab.training.resume_state``);
2. ``drivelab benchmark nocrash RUN`` for every run (success per traffic level, infractions);
3. ``drivelab compare`` of the runs (learning curves with 90 % bands, bootstrap intervals) into
   ``benchmarks/results/rlad-ablation/`` plus ``nocrash.md``: NoCrash success per variant and level,
   mean and 90 % bootstrap interval over seeds.

``--report-only`` rewrites ``nocrash.md`` from the runs' ``nocrash.json`` files (e.g. after the runs
were made on another machine and only their small files were brought back).

``--steps`` (and ``--eval-every``) shrink the budget for a check of the pipeline; such runs go
to their own runs directory and report directory so they never mix with the real ones
(``--runs-dir`` and ``--out`` put them elsewhere).

Slices. A command may be stopped (the GPU machine ends each command after 10 minutes and each
session after 30): ``--time-limit-s T`` stops every run T seconds after the command started, at
its next safe point, with a checkpoint (replay included), and ``--stop-after-steps N`` after N
more steps of each run; runs not started by then wait. The command then exits with status 3 and
says how far the runs got; the same command run again continues them (and, once every run is
finished, evaluates and reports). ``--variants`` restricts a slice to some variants (RLAD and
DrQ first, as the issue's priorities).

The experiment on a GPU machine (H100, 16 cores; camera 84x84, Table II's batch 256 and replay
100 k, >= 100 k steps). Nothing on that machine outlives a session, and the run directories, whose
replays take 2.2 GB each at 100 k x 84x84, cannot be brought back (64 MiB), so runs continue across
the <= 10-minute commands of one session, not across sessions. First the checks and the update
(``benchmarks/gpu_checks.sh``), then, in the same session, the same command until it exits with 0,
each within 30 s of the last (a slice stops itself after 8 minutes, leaving time for the
checkpoints)::

    OMP_NUM_THREADS=1 python benchmarks/rlad_ablation.py --variants rlad drq --workers 6 \
        --time-limit-s 480 --checkpoint-every 10000 \
        --hyperparams '{"device": "cuda", "fast_update": true, "compile": "reduce-overhead"}'

(the ablations: ``--variants no-alix no-aux mlp-waypoints --workers 9``; NoCrash and the report:
the same command without ``--variants``). Six processes share the GPU; ``replay_frames=auto``
puts the frames of as many of them on the GPU as fit in half its free memory
(``drivelab.agents.rlad.memory``), the others keep theirs on the host. Every checkpoint writes the
run's replay (2.2 GB, twice while it is replaced): a slice's own stop writes one, so periodic
checkpoints are rare; 15 runs' replays (33 GB) fit the 64 GB disk. Budget, measured
(``benchmarks/results/rlad_gpu_training.md``, H100): six such runs at once train at 23.4 steps/s
each once updating (the GPU busy ~100 %), so 100 k steps each take about 71 minutes of one machine.
A session lent 15 minutes of GPU time reaches about 15 k steps per run: pass ``--steps`` to what the
session allows (with ``--eval-every`` a tenth of it, for the learning curves) so that the runs
finish, and state the budget reached.
"""

from __future__ import annotations

import json
import multiprocessing
import os
import signal
import sys
import threading
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from pathlib import Path

import torch

from drivelab.training.checkpoints import file_sha256
from drivelab.training.compare import group_runs, load_run, write_report
from drivelab.training.nocrash import INFRACTIONS, LEVELS, NOCRASH_SEED, nocrash
from drivelab.training.resume_state import StopRequest
from drivelab.training.stats import summarize
from drivelab.training.sweep import Sweep, expand_sweep, plan, run_cell, run_dirs
from drivelab.yaml_io import load_yaml

sys.path.insert(0, str(Path(__file__).resolve().parent))
from provenance import Parser, command_line, mapping, positive, whole  # noqa: E402

HERE = Path(__file__).parent
SWEEP = HERE / "sweeps" / "rlad-ablation.yaml"
UNFINISHED = 3  # exit status of a slice that left runs to continue
VARIANTS = {  # --variants names → the paper's names (``variant``)
    "rlad": "RLAD", "drq": "DrQ", "no-alix": "no A-LIX", "no-aux": "no traffic-light loss",
    "mlp-waypoints": "MLP waypoints",
}  # fmt: skip


def variant(record) -> str:
    """The paper's name of a run's variant, from the switches in its hyper-parameters (DrQ: RLAD
    without A-LIX and the traffic-light loss, with MLP waypoints, as ``DrQConfig``)."""
    hyperparams = record.config.hyperparams or {}
    if record.config.algo == "drq" or (
        hyperparams.get("alix") is False
        and hyperparams.get("aux") is False
        and hyperparams.get("waypoint_encoder") == "mlp"
    ):
        return "DrQ" + (" (no augmentation)" if hyperparams.get("augment") is False else "")
    off = [
        name
        for name, is_off in (
            ("no A-LIX", hyperparams.get("alix") is False),
            ("no traffic-light loss", hyperparams.get("aux") is False),
            ("MLP waypoints", hyperparams.get("waypoint_encoder") == "mlp"),
            ("no augmentation", hyperparams.get("augment") is False),
        )
        if is_off
    ]
    return ", ".join(off) or "RLAD"


def interval(values: list[float], digits: int = 0) -> str:
    """``mean [90 % bootstrap interval]`` over seeds (the mean alone for one seed)."""
    s = summarize(values)
    if s.n < 2:
        return f"{s.mean:.{digits}f}"
    return f"{s.mean:.{digits}f} [{s.ci_low:.{digits}f}, {s.ci_high:.{digits}f}]"


def nocrash_tables(reports: dict[Path, dict], records: list) -> str:
    """Markdown: NoCrash success (%) per variant and traffic level, then the infractions in regular
    traffic; each cell the mean [90 % CI] over seeds."""
    groups = group_runs(records)
    lines = ["| variant | seeds | " + " | ".join(LEVELS) + " |", "|---|---|" + "---|" * len(LEVELS)]
    for runs in groups.values():
        cells = [
            interval([100 * reports[r.run_dir]["levels"][lv]["success_rate"] for r in runs]) for lv in LEVELS
        ]
        lines.append(f"| {variant(runs[0])} | {len(runs)} | " + " | ".join(cells) + " |")
    lines += [
        "",
        "Regular traffic:",
        "",
        "| variant | " + " | ".join(label for label, _ in INFRACTIONS) + " |",
    ]
    lines.append("|---|" + "---|" * len(INFRACTIONS))
    for runs in groups.values():
        cells = []
        for label, key in INFRACTIONS:
            scale, digits = (100, 0) if label.endswith("%") else (1, 1)
            values = [reports[r.run_dir]["levels"]["regular"][key] for r in runs]
            cells.append("n/a" if None in values else interval([scale * v for v in values], digits))
        lines.append(f"| {variant(runs[0])} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def saved_nocrash(run_dir: Path) -> dict:
    """The run's nocrash.json on the test town (``--report-only``)."""
    path = run_dir / "nocrash.json"
    if not path.exists():
        sys.exit(f"{path} is missing: run without --report-only to evaluate")
    report = json.loads(path.read_text())
    if report.get("town") != "test":
        sys.exit(f"{path} evaluated the {report.get('town')!r} town, not the test town")
    return report


def nocrash_once(run_dir: Path, episodes: int) -> dict:
    """NoCrash on the test town, or the run's nocrash.json when it already holds that evaluation
    (same episodes and seed) of this very final model (its SHA-256), so a re-run after an
    interruption only evaluates what is missing."""
    saved, final = run_dir / "nocrash.json", run_dir / "model.zip"
    if saved.exists() and final.is_file():
        report = json.loads(saved.read_text())
        wanted = {"town": "test", "episodes_per_level": episodes, "seed": NOCRASH_SEED}
        wanted["model_sha256"] = file_sha256(final)
        if all(report.get(key) == value for key, value in wanted.items()):
            return report
    return nocrash(run_dir, town="test", episodes=episodes)


def _one_thread() -> None:
    torch.set_num_threads(1)  # one evaluation per core: no oversubscription


def _nocrash_before(run_dir: Path, episodes: int, deadline: float | None) -> dict | None:
    """``nocrash_once``, or None when ``deadline`` (``time.time()``) passed before it started."""
    if deadline is not None and time.time() >= deadline:
        return None
    return nocrash_once(run_dir, episodes)


def nocrash_all(
    directories: list[Path], episodes: int, workers: int, deadline: float | None = None
) -> dict[Path, dict | None]:
    """``nocrash_once`` for every run, ``workers`` runs at a time (fresh interpreters); None for
    the runs not started before ``deadline``."""
    if workers <= 1:
        return {d: _nocrash_before(d, episodes, deadline) for d in directories}
    context = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(max_workers=workers, mp_context=context, initializer=_one_thread) as pool:
        futures = {d: pool.submit(_nocrash_before, d, episodes, deadline) for d in directories}
        return {d: future.result() for d, future in futures.items()}


# --- slices: runs that stop at a deadline or after some steps, and continue when re-run ----------
def _stop_at(deadline: float, finished: threading.Event) -> None:
    """From ``deadline`` on, wait until training is under way (its SIGTERM handler, a
    ``StopRequest``'s, is installed), then send this process one SIGTERM: training stops at its
    next safe point with a checkpoint (``drivelab.training.run``). Nothing is sent once the job is
    done, or while it is not training (building, evaluating): a signal there would be lost or
    would stop an evaluation half-way."""
    if finished.wait(max(deadline - time.time(), 0.0)):
        return
    while not finished.is_set():
        handler = signal.getsignal(signal.SIGTERM)
        if isinstance(getattr(handler, "__self__", None), StopRequest):
            os.kill(os.getpid(), signal.SIGTERM)
            return
        finished.wait(0.2)


def run_cell_until(job: dict, deadline: float | None) -> dict:
    """``sweep.run_cell`` for one job, stopped at ``deadline`` (``time.time()``) by ``_stop_at``;
    a job not started by then is left for the next slice (``"action": "wait"``)."""
    if deadline is not None and time.time() >= deadline:
        return {"name": build_name(job), "action": "wait", "ok": False, "error": "deadline", "seconds": 0.0}
    finished = threading.Event()
    previous = signal.signal(signal.SIGTERM, lambda signum, frame: None)  # a late timer: ignored
    if deadline is not None:
        threading.Thread(target=_stop_at, args=(deadline, finished), daemon=True).start()
    try:
        return run_cell(**job)
    finally:
        finished.set()
        signal.signal(signal.SIGTERM, previous)


def build_name(job: dict) -> str:
    return job["config_values"]["name"]


def slice_jobs(sweep: Sweep, stop_after_steps: int | None) -> tuple[list[dict], list[str]]:
    """The sweep's unfinished cells as ``run_cell`` jobs (and the finished ones' names). With
    ``stop_after_steps``, a job trains at most that many more steps (its config's ``steps``
    lowered, the final evaluation left for the slice that reaches the full budget)."""
    jobs, finished = [], []
    for cell, action in plan(sweep):
        if action == "skip":
            finished.append(cell.config.name)
            continue
        values, eval_episodes = cell.config.to_dict(), sweep.eval_episodes
        if stop_after_steps is not None and action in ("train", "restart", "resume"):
            done = checkpoint_steps(sweep.runs_dir / cell.config.name) if action == "resume" else 0
            if done + stop_after_steps < cell.config.steps:
                values["steps"], eval_episodes = done + stop_after_steps, 0
        jobs.append({"config_values": values, "runs_dir": str(sweep.runs_dir.resolve()), "action": action,
                     "eval_episodes": eval_episodes})  # fmt: skip
    return jobs, finished


def checkpoint_steps(run_dir: Path) -> int:
    """Steps of a run's latest checkpoint (0 without one)."""
    manifest = run_dir / "checkpoints" / "latest.json"
    return int(json.loads(manifest.read_text())["steps"]) if manifest.is_file() else 0


def run_slice(
    sweep: Sweep, workers: int, deadline: float | None = None, stop_after_steps: int | None = None
) -> dict[str, list[str]]:
    """Run the sweep's unfinished cells until ``deadline`` or for ``stop_after_steps`` more steps
    each; the names of the runs ``finished``, ``stopped`` (to continue), ``failed``."""
    sweep.runs_dir.mkdir(parents=True, exist_ok=True)
    jobs, finished = slice_jobs(sweep, stop_after_steps)
    if workers <= 1:
        outcomes = [run_cell_until(job, deadline) for job in jobs]
    else:
        context = multiprocessing.get_context("spawn")
        with ProcessPoolExecutor(max_workers=workers, mp_context=context) as pool:
            futures = [pool.submit(run_cell_until, job, deadline) for job in jobs]
            outcomes = [future.result() for future in as_completed(futures)]
    status: dict[str, list[str]] = {"finished": list(finished), "stopped": [], "failed": []}
    full = {cell.config.name: cell.config.steps for cell in sweep.cells}
    for outcome in outcomes:
        name = outcome["name"]
        interrupted = outcome["action"] == "wait" or str(outcome["error"]).startswith("TrainingInterrupted")
        if not outcome["ok"] and not interrupted:
            status["failed"].append(f"{name}: {outcome['error']}")
        elif checkpoint_steps(sweep.runs_dir / name) < full[name] or interrupted:
            status["stopped"].append(name)
        else:
            status["finished"].append(name)
    return status


def main() -> None:
    parser = Parser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--steps", type=whole(), default=None, help="training steps per run (default: the file's)"
    )
    parser.add_argument("--eval-every", type=whole(), default=None, help="steps between periodic evaluations")
    parser.add_argument("--episodes", type=whole(), default=25, help="NoCrash episodes per traffic level")
    parser.add_argument(
        "--workers",
        type=whole(),
        default=1,
        help="parallel runs and NoCrash evaluations (one per core at most)",
    )
    parser.add_argument(
        "--hyperparams", type=mapping, default=None, help="JSON of extra hyper-parameters for every run"
    )
    parser.add_argument(
        "--duration-s", type=positive, default=None, help="episode time limit (default: the town's)"
    )
    parser.add_argument("--out", type=Path, default=None, help="report directory")
    parser.add_argument(
        "--report-only",
        action="store_true",
        help="rewrite nocrash.md from the runs' nocrash.json (no training, no evaluation)",
    )
    parser.add_argument("--runs-dir", type=Path, default=None, help="where the run directories go")
    parser.add_argument(
        "--seeds", type=whole(), default=None, help="seeds per variant (default: the file's 3)"
    )
    parser.add_argument("--checkpoint-every", type=whole(), default=None, help="steps between checkpoints")
    parser.add_argument(
        "--time-limit-s", type=positive, default=None,
        help="stop every run this many seconds after the start, with a checkpoint; exit 3 if unfinished",
    )  # fmt: skip
    parser.add_argument(
        "--stop-after-steps", type=whole(), default=None,
        help="train each unfinished run at most this many more steps; exit 3 if unfinished",
    )  # fmt: skip
    parser.add_argument(
        "--variants", nargs="+", choices=list(VARIANTS), default=None,
        help="only these variants' runs (all: NoCrash and the report need every run finished)",
    )  # fmt: skip
    args = parser.parse_args()
    start = time.time()
    deadline = None if args.time_limit_s is None else start + args.time_limit_s
    spec = load_yaml(SWEEP)
    tiny = args.steps is not None
    if tiny:
        spec["base"] = {**spec["base"], "steps": args.steps, "eval_every": args.eval_every or args.steps}
        spec["runs_dir"] = spec["runs_dir"] + f"-{args.steps}steps"
    if args.runs_dir is not None:
        spec["runs_dir"] = str(args.runs_dir)
    if args.seeds is not None:
        spec["grid"] = {**spec["grid"], "seed": args.seeds}
    if args.checkpoint_every is not None:
        spec["base"] = {**spec["base"], "checkpoint_every": args.checkpoint_every}
    if args.hyperparams:
        spec["base"] = {**spec["base"], "hyperparams": args.hyperparams}
    if args.duration_s is not None:
        spec["base"] = {**spec["base"], "env_options": {"duration_s": args.duration_s}}
    out = args.out or HERE / "results" / ("rlad-ablation" + (f"-{args.steps}steps" if tiny else ""))
    sweep = expand_sweep(spec)
    if args.variants:
        wanted = {VARIANTS[name] for name in args.variants}
        cells = tuple(c for c in sweep.cells if variant(c) in wanted)
        sweep = Sweep(cells, sweep.runs_dir, sweep.eval_episodes)
    directories = run_dirs(sweep)
    command = command_line()
    if args.report_only:
        reports = {d: saved_nocrash(d) for d in directories}
        records = [load_run(d) for d in directories]
        report = out
        report.mkdir(parents=True, exist_ok=True)
        made = "runs, evaluations and their machine: report.md"
    else:
        status = run_slice(sweep, args.workers, deadline, args.stop_after_steps)
        if status["failed"]:
            sys.exit(f"runs failed: {'; '.join(status['failed'])} (logs in {sweep.runs_dir / '.sweep-logs'})")
        if status["stopped"]:
            steps = {name: checkpoint_steps(sweep.runs_dir / name) for name in status["stopped"]}
            print(f"{len(status['finished'])} runs finished; unfinished (checkpointed steps): "
                  + ", ".join(f"{name} {n:,}" for name, n in steps.items())
                  + f". Run the same command again to continue ({time.time() - start:.0f} s).")  # fmt: skip
            sys.exit(UNFINISHED)
        if args.variants:
            print(f"{len(directories)} runs of {', '.join(args.variants)} finished; NoCrash and the "
                  "report run without --variants")  # fmt: skip
            return
        evaluated = nocrash_all(directories, args.episodes, args.workers, deadline)
        if any(report is None for report in evaluated.values()):
            print("NoCrash unfinished at the time limit: run the same command again to continue")
            sys.exit(UNFINISHED)
        reports = {d: report for d, report in evaluated.items() if report is not None}
        records = [load_run(d) for d in directories]
        report = write_report(records, out, title="RLAD ablation in the town", command=command)
        made = "machine: report.md"
    episodes = {r["episodes_per_level"] for r in reports.values()}
    text = [
        "# NoCrash (test town): RLAD, DrQ and RLAD's ablations",
        "",
        f"Command: `{command}` ({made})  ",
        f"{', '.join(map(str, sorted(episodes)))} episodes per traffic level and run, on the test town's "
        "fixed routes; mean [90 % bootstrap interval] over seeds. "
        f"Training budget: {sweep.cells[0].config.steps:,} steps per run (the paper trains 10^6).",
        "",
        "Success %:",
        "",
        nocrash_tables(reports, records),
        "",
    ]
    (report / "nocrash.md").write_text("\n".join(text))
    print("\n".join(text))
    print(f"report: {report / 'report.md'}")


if __name__ == "__main__":
    main()
