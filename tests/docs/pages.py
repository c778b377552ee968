"""The documentation's sources for the docs tests: the pages, their code blocks, their headings, and
docs/hooks.py (the site's build hook, which holds the docs' one import of the scenario registry)."""

from __future__ import annotations

import importlib.util
import re
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
DOCS = REPO / "docs"
FENCE = re.compile(r"^```(?P<lang>[\w-]*)[^\n]*\n(?P<body>.*?)^```$", re.MULTILINE | re.DOTALL)
MARKER = re.compile(r"^<!-- drivelab: .*? -->$", re.MULTILINE)


def hooks():
    """docs/hooks.py as a module (it is loaded by mkdocs, not imported from a package)."""
    spec = importlib.util.spec_from_file_location("drivelab_docs_hooks", DOCS / "hooks.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def pages() -> list[Path]:
    """Every Markdown page of the site, and the README (its examples must run too)."""
    return [*sorted(DOCS.rglob("*.md")), REPO / "README.md"]


def python_blocks(path: Path) -> list[str]:
    """The ```python blocks of a page, in order."""
    return [match["body"] for match in FENCE.finditer(path.read_text()) if match["lang"] == "python"]


def prose(path: Path) -> str:
    """A page without its code blocks and its generated tables' markers: what a person wrote."""
    return MARKER.sub("", FENCE.sub("", path.read_text()))


def headings(path: Path) -> list[str]:
    """The page's headings' text (outside code blocks), without the #'s."""
    return [line.lstrip("#").strip() for line in prose(path).splitlines() if line.startswith("#")]
