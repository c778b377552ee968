"""Episode set-up speed of the compiled core: one world's ``FastSimulator._episode`` per scenario.

    OMP_NUM_THREADS=1 NUMBA_NUM_THREADS=1 .venv/bin/python benchmarks/setup_speed.py [--seeds 300]
        [--repeats 3] [--against <another drivelab checkout>]

Regular traffic; meta-actions (continuous control on the racetrack, whose meta-action ego
highway-env cannot place). The town's set-up is its ``TownEpisode`` (vehicles, pedestrians,
lights, the ego's route). Each measurement is the mean over ``--seeds`` set-ups after one untimed
set-up (compilation), made in a fresh process; the table gives the median of ``--repeats``.

On a shared machine a single pass is noisy, so a change is measured as a ratio: ``--against DIR``
times another checkout's tree (its ``drivelab`` on ``PYTHONPATH``) in the same run, the two trees'
processes interleaved, and the table gives each tree's median and the speed-up of this tree over
it. The script uses only ``fast_simulator``, ``SCENARIOS`` and ``_episode``, which older trees
have too.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from provenance import Parser, command_line, provenance, stop, whole  # noqa: E402

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("NUMBA_NUM_THREADS", "1")

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "benchmarks" / "results"
CASES = (("highway", "meta"), ("merge", "meta"), ("roundabout", "meta"), ("intersection", "meta"))
CASES += (("racetrack", "continuous"), ("town", "meta"))


def setup_ms(scenario: str, control: str, seeds: int) -> float:
    """Mean milliseconds of one episode set-up of ``scenario`` (regular traffic)."""
    from drivelab.scenarios import SCENARIOS
    from drivelab.sim.core.backend import fast_simulator

    simulator = fast_simulator(SCENARIOS[scenario], "regular", control, 1)
    simulator._episode(0)
    start = time.perf_counter()
    for seed in range(seeds):
        simulator._episode(seed)
    return (time.perf_counter() - start) / seeds * 1e3


def measure(tree: Path, seeds: int) -> dict[str, float]:
    """One pass over every scenario in a fresh process that imports ``tree``'s ``drivelab``."""
    environment = {**os.environ, "PYTHONPATH": str(tree)}
    done = subprocess.run(
        [sys.executable, __file__, "--pass", str(seeds)],
        env=environment, cwd=tree, capture_output=True, text=True,
    )  # fmt: skip
    if done.returncode != 0:
        stop(f"a pass over {tree} failed: {(done.stderr.strip().splitlines() or ['no output'])[-1]}")
    return json.loads(done.stdout)


def one_pass(seeds: int) -> None:
    """The worker: print this process's ``drivelab`` set-up times as JSON (scenario → ms)."""
    import drivelab

    tree = Path(os.environ.get("PYTHONPATH", ROOT)).resolve()
    origin = getattr(drivelab, "__file__", None)  # None: a folder that is no package
    if origin is None or tree not in Path(origin).resolve().parents:
        stop(f"{tree} has no drivelab of its own: {origin or 'a folder without __init__.py'} was imported")
    print(json.dumps({name: setup_ms(name, control, seeds) for name, control in CASES}))


def reference_tree(text: str) -> Path:
    """A checkout holding a ``drivelab`` package other than this one."""
    tree = Path(text).resolve()
    if not (tree / "drivelab" / "__init__.py").is_file():
        stop(f"--against: {text} holds no drivelab package (drivelab/__init__.py)")
    if tree == ROOT:
        stop("--against: that is this checkout; give another one")
    return tree


def commit_of(tree: Path) -> str:
    """``tree``'s git commit (short), or ``"not a git checkout"``."""
    done = subprocess.run(
        ["git", "-C", str(tree), "rev-parse", "--short", "HEAD"], capture_output=True, text=True
    )
    return done.stdout.strip() if done.returncode == 0 else "not a git checkout"


def main() -> None:
    parser = Parser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=whole(), default=300, help="set-ups timed in each pass")
    parser.add_argument("--repeats", type=whole(), default=3, help="passes per tree (medians)")
    parser.add_argument("--against", type=reference_tree, help="another checkout to time in the same run")
    parser.add_argument("--no-save", action="store_true", help="print only")
    parser.add_argument("--pass", dest="one_pass", type=whole(), help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.one_pass:
        one_pass(args.one_pass)
        return
    command = command_line()
    trees = [ROOT] + ([args.against] if args.against else [])
    passes: dict[Path, list[dict[str, float]]] = {tree: [] for tree in trees}
    for repeat in range(args.repeats):
        for tree in trees if repeat % 2 == 0 else trees[::-1]:
            passes[tree].append(measure(tree, args.seeds))
            print(f"repeat {repeat + 1}/{args.repeats}: {tree} done", file=sys.stderr)
    rows = []
    for name, control in CASES:
        row = {"scenario": name, "control": control}
        row["ms_per_setup"] = statistics.median(p[name] for p in passes[ROOT])
        if args.against:
            row["reference_ms_per_setup"] = statistics.median(p[name] for p in passes[args.against])
            row["speedup"] = row["reference_ms_per_setup"] / row["ms_per_setup"]
        rows.append(row)
    for row in rows:
        against = (
            f"  reference {row['reference_ms_per_setup']:.3f}  ×{row['speedup']:.2f}" if args.against else ""
        )
        print(f"{row['scenario']:12s} {row['ms_per_setup']:.3f} ms per set-up{against}")
    if args.no_save:
        return
    head, this_commit = provenance(command), commit_of(ROOT)
    reference = None
    if args.against:
        reference = f"the drivelab tree at commit {commit_of(args.against)} (`--against`)"
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / "setup_speed.json").write_text(
        json.dumps({**head, "this_commit": this_commit, "reference": reference, "rows": rows}, indent=2)
        + "\n"
    )
    columns = "| scenario | control | ms per set-up |"
    rule = "|---|---|---|"
    if args.against:
        columns += " reference, ms per set-up | speed-up |"
        rule += "---|---|"
    lines = [
        "# Episode set-up speed (one world, regular traffic)",
        "",
        f"Command: `{head['command']}`  ",
        f"Machine: {head['machine']}; date {head['date']}; this tree: commit {this_commit}"
        + (f"; reference: {reference}" if reference else "")
        + ".",
        "",
        f"Each pass times {args.seeds} set-ups of every scenario after one untimed set-up, in a fresh "
        f"process; the table gives the median of {args.repeats} passes per tree"
        + (", the two trees' passes interleaved." if args.against else "."),
        "",
        columns,
        rule,
    ]
    for r in rows:
        line = f"| {r['scenario']} | {r['control']} | {r['ms_per_setup']:.3f} |"
        if args.against:
            line += f" {r['reference_ms_per_setup']:.3f} | {r['speedup']:.2f}× |"
        lines.append(line)
    (RESULTS / "setup_speed.md").write_text("\n".join([*lines, ""]))


if __name__ == "__main__":
    main()
