"""Shipped hyper-parameters: one YAML file per algorithm, keyed by scenario (RL Zoo's manner).

``drivelab/hyperparams/<algo>.yaml`` maps a scenario name (or ``default``) to keyword arguments
of the algorithm. Each file says where its values come from and whether they were tuned. A new
run starts from the file's entry for its scenario; ``--hyperparams key=value`` (or the run YAML's
``hyperparams``) overrides single keys, and the merged values are written into ``config.yaml``.
"""

from __future__ import annotations

import copy
from functools import cache
from importlib import resources

import yaml

from drivelab.errors import UsageError


@cache
def _load(algo: str) -> dict:
    file = resources.files(__package__) / f"{algo}.yaml"
    if not file.is_file():
        return {}
    data = yaml.safe_load(file.read_text())
    if not isinstance(data, dict):
        raise UsageError(f"hyper-parameter file {algo}.yaml must map scenarios to mappings")
    return data


def shipped_hyperparams(algo: str, scenario: str) -> dict:
    """The shipped values for ``algo`` on ``scenario`` (the file's ``default`` if the scenario has
    no entry; empty for an algorithm without a file)."""
    table = _load(algo)
    return copy.deepcopy(dict(table.get(scenario, table.get("default", {})) or {}))


def resolve_hyperparams(algo: str, scenario: str, overrides: dict | None = None) -> dict:
    """Shipped values for (``algo``, ``scenario``) with ``overrides`` on top, key by key."""
    return {**shipped_hyperparams(algo, scenario), **(overrides or {})}


def with_shipped_hyperparams(values: dict) -> dict:
    """Run-config values with ``hyperparams`` resolved against the shipped file of their algorithm
    and scenario (``env``, default ``highway``). Values without ``algo`` are returned unchanged."""
    if "algo" not in values or not isinstance(values.get("hyperparams", {}), dict):
        return dict(values)
    algo, scenario = str(values["algo"]), str(values.get("env", "highway"))
    return {**values, "hyperparams": resolve_hyperparams(algo, scenario, values.get("hyperparams"))}
