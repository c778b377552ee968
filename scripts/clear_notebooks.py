"""Strip outputs and execution counts from the teaching notebooks (they are stored without them).

Usage: ``.venv/bin/python scripts/clear_notebooks.py [NOTEBOOK ...]`` (default: notebooks/*.ipynb).
"""

from __future__ import annotations

import sys
from pathlib import Path

import nbformat


def clear(path: Path) -> bool:
    """Remove every code cell's outputs and execution count; True when the file changed."""
    notebook = nbformat.read(path, as_version=4)
    changed = False
    for cell in notebook.cells:
        if cell.cell_type == "code" and (cell.outputs or cell.execution_count is not None):
            cell.outputs, cell.execution_count = [], None
            changed = True
    if changed:
        nbformat.write(notebook, path)
    return changed


if __name__ == "__main__":
    default = sorted((Path(__file__).parents[1] / "notebooks").glob("*.ipynb"))
    paths = [Path(p) for p in sys.argv[1:]] or default
    for path in paths:
        print(f"{path}: {'cleared' if clear(path) else 'already clean'}")
