"""Shipped hyper-parameters: ``drivelab/hyperparams/<algo>.yaml``, one rl-baselines3-zoo file per
algorithm. Top-level keys are gymnasium env ids (``drivelab/Highway-v0``) or ``default``; each
entry holds RL Zoo's run settings and the algorithm's keyword arguments. drivelab reads the same
entries without the run settings (its run config gives them). ``build_sb3`` starts every model
from ``default``; a new run starts from its scenario's entry, ``--hyperparams key=value``
overriding single keys. A file of an algorithm RL Zoo does not have may key entries by scenario.
"""

from __future__ import annotations

import copy
from functools import cache
from importlib import resources

import yaml

from drivelab.errors import UsageError

# RL Zoo's run settings that drivelab takes from its run config instead
ZOO_RUN_KEYS = ("n_timesteps", "policy", "env_kwargs")
# RL Zoo's other run settings (ExperimentManager._preprocess_hyperparams): drivelab has no
# equivalent of them, so a file that sets one would train differently under RL Zoo; refused.
ZOO_UNSUPPORTED = ("n_envs", "normalize", "frame_stack", "env_wrapper", "vec_env_wrapper", "callback",
                   "monitor_kwargs")  # fmt: skip


@cache
def _load(algo: str) -> dict:
    file = resources.files(__package__) / f"{algo}.yaml"
    if not file.is_file():
        return {}
    return parse_zoo_file(file.read_text(), f"{algo}.yaml")


def parse_zoo_file(text: str, name: str) -> dict:
    """The entries of an RL Zoo hyper-parameter file's ``text``, read as RL Zoo reads it
    (``yaml.safe_load``: YAML 1.1, where 5.0e-4 is a number and 5e-4 a string). A UsageError when
    it is not a mapping of mappings, or an entry sets a run setting drivelab cannot honour."""
    data = yaml.safe_load(text)
    if not isinstance(data, dict) or not all(isinstance(v, dict) for v in data.values()):
        raise UsageError(f"hyper-parameter file {name} must map env ids to mappings")
    for key, entry in data.items():
        unsupported = sorted(set(entry) & set(ZOO_UNSUPPORTED))
        if unsupported:
            raise UsageError(f"hyper-parameter file {name}: {key!r} sets RL Zoo's "
                             f"{unsupported[0]!r}, which drivelab runs cannot honour")  # fmt: skip
    return data


def zoo_entry(algo: str, scenario: str) -> dict:
    """The whole entry of ``algo``'s file for ``scenario`` (a scenario name or its env id), run
    settings included: the env id's entry, else the scenario name's, else ``default``, else empty."""
    from drivelab.envs import gym_id

    table = _load(algo)
    for key in (scenario, gym_id(scenario), "default"):
        if key in table:
            return copy.deepcopy(table[key])
    return {}


def shipped_hyperparams(algo: str, scenario: str) -> dict:
    """The shipped keyword arguments of ``algo`` on ``scenario`` (a scenario name or its env id):
    its file's entry (``default`` if the scenario has none) without RL Zoo's run settings; empty for
    an algorithm without a file."""
    return {k: v for k, v in zoo_entry(algo, scenario).items() if k not in ZOO_RUN_KEYS}


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


class _PlainDumper(yaml.SafeDumper):
    """SafeDumper without anchors: every entry written out in full."""

    def ignore_aliases(self, data) -> bool:
        return True


def zoo_yaml(entries: dict[str, dict], header: str = "") -> str:
    """``entries`` (env id or ``default`` → entry) as an RL Zoo hyper-parameter file's text, with
    ``header`` as ``#`` comment lines above. Floats are written so that YAML 1.1 reads them back
    as numbers (PyYAML's ``1.0e-05`` form)."""
    comments = "".join(f"# {line}".rstrip() + "\n" for line in header.splitlines())
    return comments + yaml.dump(entries, Dumper=_PlainDumper, sort_keys=False, default_flow_style=None)
