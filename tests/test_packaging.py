"""pyproject.toml's dependencies install beside other packages: floors, not exact pins."""

import re
import tomllib
from pathlib import Path

PYPROJECT = Path(__file__).resolve().parents[1] / "pyproject.toml"


def _requirements() -> dict[str, str]:
    dependencies = tomllib.loads(PYPROJECT.read_text())["project"]["dependencies"]
    return dict(re.match(r"([A-Za-z0-9_.-]+)\s*(.*)", d).groups() for d in dependencies)


def test_torch_is_a_range_not_a_pin():
    """An exact torch pin would make drivelab uninstallable beside any other torch; scripts/setup.sh
    pins the CPU build instead."""
    torch = _requirements()["torch"]
    assert "==" not in torch and ">=" in torch


def test_every_dependency_but_highway_env_has_a_floor():
    """scripts/check_min_versions.sh installs these floors; highway-env stays pinned because the fast
    backend reproduces that release's arithmetic."""
    requirements = _requirements()
    assert requirements.pop("highway-env") == "==1.12.1"
    assert {name: spec for name, spec in requirements.items() if ">=" not in spec or "==" in spec} == {}


def test_the_metadata_names_the_licence_and_the_audience():
    project = tomllib.loads(PYPROJECT.read_text())["project"]
    assert project["license"] == "MIT" and project["license-files"] == ["LICENSE"]
    assert (PYPROJECT.parent / "LICENSE").read_text().startswith("MIT License")
    classifiers = project["classifiers"]
    assert "Programming Language :: Python :: 3.11" in classifiers
    assert not [c for c in classifiers if c.startswith("License ::")]  # PEP 639: the expression only
