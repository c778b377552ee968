"""Episode set-up speed of the compiled core: one world's ``FastSimulator._episode`` per scenario.

    OMP_NUM_THREADS=1 NUMBA_NUM_THREADS=1 .venv/bin/python benchmarks/setup_speed.py [--seeds 100]
    PYTHONPATH=<an older checkout> .venv/bin/python benchmarks/setup_speed.py --no-save  # compare

Regular traffic; meta-actions (continuous control on the racetrack, whose meta-action ego
highway-env cannot place). Each row is the mean over ``--seeds`` set-ups after one untimed
set-up (compilation). Run against an older checkout with ``PYTHONPATH`` (the script uses only
``fast_simulator``, ``SCENARIOS`` and ``_episode``, which older trees have too) to compare. The
town's set-up is its ``TownEpisode`` (vehicles, pedestrians, lights, the ego's route).
"""

from __future__ import annotations

import json
import os
import platform
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from provenance import Parser, cpu_isa, whole  # noqa: E402

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("NUMBA_NUM_THREADS", "1")

RESULTS = Path(__file__).parent / "results"
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


def main() -> None:
    parser = Parser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=whole(), default=100)
    parser.add_argument("--no-save", action="store_true", help="print only (e.g. for an older checkout)")
    args = parser.parse_args()
    rows = [
        {"scenario": name, "control": control, "ms_per_setup": setup_ms(name, control, args.seeds)}
        for name, control in CASES
    ]
    for row in rows:
        print(f"{row['scenario']:12s} {row['ms_per_setup']:.3f} ms per set-up")
    if args.no_save:
        return
    command = f"OMP_NUM_THREADS=1 NUMBA_NUM_THREADS=1 python benchmarks/setup_speed.py --seeds {args.seeds}"
    machine = f"{cpu_isa()}, {os.cpu_count()} cores, Python {platform.python_version()}"
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / "setup_speed.json").write_text(
        json.dumps({"command": command, "machine": machine, "rows": rows}, indent=2) + "\n"
    )
    lines = [
        "# Episode set-up speed (one world, regular traffic)",
        "",
        f"Command: `{command}`  ",
        f"Machine: {machine}; mean over {args.seeds} seeds after one untimed set-up.",
        "",
        "| scenario | control | ms per set-up |",
        "|---|---|---|",
        *(f"| {r['scenario']} | {r['control']} | {r['ms_per_setup']:.3f} |" for r in rows),
        "",
    ]
    (RESULTS / "setup_speed.md").write_text("\n".join(lines))


if __name__ == "__main__":
    main()
