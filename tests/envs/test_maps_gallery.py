"""The map gallery (``scenarios/blocks/gallery.py``) draws procedural maps to a PNG; the roads package
it draws from does not need matplotlib."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

from drivelab.scenarios.blocks.gallery import draw_gallery, draw_map
from drivelab.scenarios.blocks.pg_map import generate_map

PACKAGE = Path(__file__).resolve().parents[2] / "drivelab"


def test_the_gallery_writes_a_png_of_every_map(tmp_path):
    maps = [generate_map("OSX", 0), generate_map(3, 1), generate_map("rRyY", 2)]
    path = draw_gallery(maps, tmp_path / "maps" / "gallery.png", columns=2, dpi=40)
    data = path.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 5000


def test_a_drawn_map_shows_its_letters_and_spans_its_lanes():
    pg = generate_map("OSX", 0)
    ax = Figure().add_subplot()
    draw_map(ax, pg)
    assert [text.get_text() for text in ax.texts] == list("IOSX")
    x_low, x_high = ax.get_xlim()
    starts = pg.description.start[np.isfinite(pg.description.start[:, 0])]
    assert x_low <= starts[:, 0].min() and starts[:, 0].max() <= x_high
    assert ax.get_ylim()[0] > ax.get_ylim()[1]  # y grows downwards, as on the simulators' screens


def test_the_simulator_and_the_scenarios_do_not_import_matplotlib():
    """Only the gallery draws: the roads, the maps and the simulators never load matplotlib."""
    paths = [*(PACKAGE / "sim").rglob("*.py"), *(PACKAGE / "scenarios").rglob("*.py")]
    assert len(paths) > 30
    for path in paths:
        if path.name != "gallery.py":
            assert "matplotlib" not in path.read_text(encoding="utf-8"), path
