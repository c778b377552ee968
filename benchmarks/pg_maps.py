"""Procedural maps: generation time and the gallery of seeds 0-11 (5 blocks) plus "OSX".

    OMP_NUM_THREADS=1 .venv/bin/python benchmarks/pg_maps.py [--seeds 50]

Writes ``results/pg_maps.json`` / ``.md`` (median milliseconds to generate one 5-block map over
``--seeds`` seeds after one untimed map; the size of "OSX") and ``results/pg_maps_gallery.png``.
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

RESULTS = Path(__file__).parent / "results"


def main() -> None:
    from drivelab.scenarios.blocks.gallery import draw_gallery
    from drivelab.scenarios.blocks.pg_map import generate_map

    parser = Parser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=whole(), default=50)
    args = parser.parse_args()
    generate_map(5, 0)
    times = []
    for seed in range(args.seeds):
        start = time.perf_counter()
        generate_map(5, seed)
        times.append(time.perf_counter() - start)
    osx = {count: generate_map("OSX", 0, lane_count=count) for count in (2, 3)}
    row = {
        "median_ms_per_5_block_map": 1e3 * sorted(times)[len(times) // 2],
        "max_ms_per_5_block_map": 1e3 * max(times),
        "osx_lanes": {str(count): pg.description.lane_count for count, pg in osx.items()},
        "osx_junctions": osx[3].description.junction_count,
    }
    maps = [generate_map("OSX", 0)] + [generate_map(5, seed) for seed in range(12)]
    draw_gallery(maps, RESULTS / "pg_maps_gallery.png", columns=5, dpi=80)
    command = f"OMP_NUM_THREADS=1 python benchmarks/pg_maps.py --seeds {args.seeds}"
    machine = f"{cpu_isa()}, {os.cpu_count()} cores, Python {platform.python_version()}"
    (RESULTS / "pg_maps.json").write_text(
        json.dumps({"command": command, "machine": machine, **row}, indent=2) + "\n"
    )
    (RESULTS / "pg_maps.md").write_text(
        f"# Procedural maps\n\n`{command}` ({machine})\n\n"
        f"- one 5-block map: median {row['median_ms_per_5_block_map']:.1f} ms over {args.seeds} seeds "
        f"(max {row['max_ms_per_5_block_map']:.1f} ms)\n"
        f'- "OSX": {row["osx_lanes"]["3"]} lanes with 3 lanes per direction, {row["osx_lanes"]["2"]} with 2\n'
        '- gallery: `pg_maps_gallery.png` ("OSX" seed 0, then 5 random blocks, seeds 0-11)\n'
    )
    print(json.dumps(row, indent=2))


if __name__ == "__main__":
    main()
