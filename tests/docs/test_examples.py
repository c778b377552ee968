"""Every ```python block of the documentation pages and the README runs: a page's blocks in order,
in one fresh interpreter, in an empty folder (the examples keep their budgets tiny)."""

import os
import subprocess
import sys

import pytest

from tests.docs.pages import REPO, pages, python_blocks

PAGES = [page for page in pages() if python_blocks(page)]


def test_the_docs_have_python_examples():
    assert len(PAGES) >= 6


@pytest.mark.parametrize("page", PAGES, ids=[str(page.relative_to(REPO)) for page in PAGES])
def test_the_python_examples_run(page, tmp_path):
    script = "\n\n".join(python_blocks(page))
    environment = {**os.environ, "OMP_NUM_THREADS": "1", "MPLBACKEND": "Agg"}
    result = subprocess.run(
        [sys.executable, "-c", script], cwd=tmp_path, env=environment, capture_output=True, text=True,
        timeout=300,
    )  # fmt: skip
    assert result.returncode == 0, f"{page.relative_to(REPO)}:\n{result.stderr[-4000:]}"
