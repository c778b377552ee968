"""The teaching notebooks in notebooks/: stored without outputs, and each runs top to bottom.

Each notebook is executed in a fresh kernel with nbclient, in a temporary directory (its runs
and reports go under TMPDIR, which points there); a cell that raises fails the test. A notebook
whose defaults are a real budget (10) reads DRIVELAB_NOTEBOOK_QUICK=1, set here, and runs a tiny
one. One test per notebook, so that pytest-xdist spreads them over the workers.
"""

from pathlib import Path

import nbformat
import pytest

NOTEBOOKS = sorted((Path(__file__).parents[1] / "notebooks").glob("*.ipynb"))
CELL_TIMEOUT_S = 600


def test_the_series_is_there():
    numbers = [path.name[:2] for path in NOTEBOOKS]
    assert {"01", "02", "03", "04", "05", "06", "07", "08", "09", "10"} <= set(numbers), numbers


@pytest.mark.parametrize("path", NOTEBOOKS, ids=lambda path: path.stem)
def test_stored_without_outputs(path):
    notebook = nbformat.read(path, as_version=4)
    nbformat.validate(notebook)
    dirty = [i for i, cell in enumerate(notebook.cells)
             if cell.cell_type == "code" and (cell.outputs or cell.execution_count is not None)]  # fmt: skip
    assert not dirty, f"cells {dirty} of {path.name} hold outputs: run scripts/clear_notebooks.py"


@pytest.mark.parametrize("path", NOTEBOOKS, ids=lambda path: path.stem)
def test_runs_top_to_bottom(path, tmp_path, monkeypatch):
    from nbclient import NotebookClient

    monkeypatch.setenv("TMPDIR", str(tmp_path))  # the kernel inherits it: tempfile writes there
    monkeypatch.setenv("OMP_NUM_THREADS", "1")
    monkeypatch.setenv("DRIVELAB_NOTEBOOK_QUICK", "1")  # notebooks whose defaults are real budgets run tiny
    before = sorted(p.name for p in path.parent.iterdir())
    notebook = nbformat.read(path, as_version=4)
    resources = {"metadata": {"path": str(tmp_path)}}  # the kernel's working directory
    client = NotebookClient(notebook, timeout=CELL_TIMEOUT_S, kernel_name="python3", resources=resources)
    client.execute()  # raises CellExecutionError, with the cell and its traceback, on an error
    assert sorted(p.name for p in path.parent.iterdir()) == before, "the notebook wrote into notebooks/"
