"""A gallery of procedural maps (``roads.pg_map.PGMap``) drawn with matplotlib to a PNG: every
lane filled in its block's colour with its edges, each block's entry socket as a bar across the
road and its letter, the route, the spawn road (green) and the destination (red)."""

from __future__ import annotations

import contextlib
import os
from collections.abc import Sequence
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

from drivelab.errors import UsageError
from drivelab.scenarios.blocks.pg_map import PGMap, lane_samples
from drivelab.scenarios.blocks.pg_roads import right_normal

BLOCK_COLOURS = ("#c6dbef", "#fdd0a2", "#c7e9c0", "#dadaeb", "#fcbba1", "#d9d9d9", "#fee391", "#ccebc5")


def draw_map(ax, pg_map: PGMap, title: str | None = None) -> None:
    """Draw ``pg_map`` on a matplotlib axes (y grows downwards, as on the simulators' screens)."""
    desc = pg_map.description
    for row in range(desc.lane_count):
        lane = desc.lane(row)
        left = lane_samples(lane, 2.0, -lane.width / 2)[1]
        right = lane_samples(lane, 2.0, lane.width / 2)[1]
        outline = np.concatenate([left, right[::-1]])
        colour = BLOCK_COLOURS[int(pg_map.lane_block[row]) % len(BLOCK_COLOURS)]
        ax.fill(outline[:, 0], outline[:, 1], color=colour, linewidth=0)
        for side, edge in ((0, left), (1, right)):
            if lane.lines[side]:
                ax.plot(edge[:, 0], edge[:, 1], color="0.35", linewidth=0.3)
    for block in pg_map.blocks:
        points = np.concatenate([lane_samples(lane, 5.0)[1] for lane in block.lanes])
        middle = points.mean(axis=0)
        ax.text(*middle, block.letter, fontsize=9, weight="bold", ha="center", va="center", color="0.1")
        entry = block.entry
        half = entry.lane_count * entry.lane_width
        bar = np.array(entry.position) + np.outer([-half, half], right_normal(entry.heading))
        ax.plot(bar[:, 0], bar[:, 1], color="black", linewidth=1.2)
    route = np.concatenate([lane_samples(desc.lane(int(row)), 2.0)[1] for row in pg_map.route_rows])
    ax.plot(route[:, 0], route[:, 1], color="tab:blue", linewidth=0.8, alpha=0.8)
    spawn = desc.lane(int(pg_map.spawn_lanes[0]))
    goal = desc.lane(int(pg_map.destination_lanes[0]))
    ax.plot(*spawn.position(5.0, 0.0), marker="o", color="tab:green", markersize=5)
    ax.plot(*goal.position(goal.length, 0.0), marker="*", color="tab:red", markersize=9)
    ax.set_aspect("equal")
    ax.invert_yaxis()
    ax.set_xticks([])
    ax.set_yticks([])
    ax.set_title(title or f"{pg_map.letters} · seed {pg_map.seed}", fontsize=8)


def draw_gallery(
    maps: Sequence[PGMap],
    path: str | Path,
    columns: int = 4,
    titles: Sequence[str] | None = None,
    dpi: int = 80,
) -> Path:
    """Draw ``maps`` in a grid of ``columns`` to the PNG ``path`` (its missing folders created);
    returns the path. A path that cannot be written is a one-line UsageError, and leaves neither
    the file nor the folders made for it."""
    rows = int(np.ceil(len(maps) / columns))
    figure = Figure(figsize=(3.2 * columns, 3.2 * rows))
    for k, pg_map in enumerate(maps):
        ax = figure.add_subplot(rows, columns, k + 1)
        draw_map(ax, pg_map, titles[k] if titles else None)
    figure.tight_layout()
    path = Path(path)
    missing = [folder for folder in path.parents if not folder.exists()]
    partial = path.with_name(path.name + ".tmp")
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        figure.savefig(partial, dpi=dpi, format="png")
        os.replace(partial, path)
    except OSError as exc:
        with contextlib.suppress(OSError):  # absent, or its folder is not one
            partial.unlink()
        for folder in missing:  # innermost first
            if folder.is_dir():
                folder.rmdir()
        raise UsageError(f"cannot write {str(path)!r}: {exc.strerror or exc}") from None
    return path
