"""The command line a benchmark writes into its results: the thread settings in effect (the
environment's, so that the line is true whoever set them) and the arguments, quoted for a shell."""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import inspect
import os
import shlex
import sys
from pathlib import Path

THREAD_VARIABLES = ("OMP_NUM_THREADS", "NUMBA_NUM_THREADS")


def command_line(argv: list[str] | None = None) -> str:
    """``[OMP_NUM_THREADS=N] [NUMBA_NUM_THREADS=N] python SCRIPT ARGS…`` of this process."""
    settings = [f"{name}={os.environ[name]}" for name in THREAD_VARIABLES if name in os.environ]
    return " ".join([*settings, "python", shlex.join(sys.argv if argv is None else argv)])


def agent_defaults(algo: str) -> dict:
    """The keyword defaults of ``algo``'s agent class (SB3's own for the SB3 agents): {} when unknown."""
    from drivelab.agents.registry import ALGORITHMS

    spec = ALGORITHMS.get(algo)
    try:
        parameters = inspect.signature(spec.agent_class().__init__).parameters if spec else {}
    except (TypeError, ValueError, ImportError):
        parameters = {}
    return {k: p.default for k, p in parameters.items() if p.default is not inspect.Parameter.empty}


def _effective(config):
    """``config`` with the hyper-parameters that only restate the agent class's own defaults dropped
    (a recipe pinning SB3's ``clip_range=0.2`` trains the run that left it out)."""
    defaults = agent_defaults(config.algo)
    kept = {k: v for k, v in (config.hyperparams or {}).items() if k not in defaults or defaults[k] != v}
    return dataclasses.replace(config, hyperparams=kept)


def stop(message: str) -> None:
    """A benchmark's bad input: one ``error:`` line, exit 2, before anything is written."""
    print(f"error: {message}", file=sys.stderr)
    raise SystemExit(2)


class Parser(argparse.ArgumentParser):
    """A benchmark's argument parser: a bad argument is one ``error:`` line and exit 2, as in every
    drivelab command (argparse's own prints the usage block first; ``--help`` still shows it)."""

    def error(self, message: str) -> None:
        stop(message)


def check_reuse(run_dir: Path, arguments: list[str], root: Path) -> None:
    """Stop the benchmark (one ``error:`` line, exit 2) when the finished run it would reuse is not
    the run ``drivelab ARGUMENTS`` trains today (``arguments`` start with ``train``; paths in them
    from ``root``): a table must not list one command beside the numbers of another. Values equal
    to the agent's own defaults count as given or not alike."""
    from drivelab.cli import train_config
    from drivelab.errors import UsageError
    from drivelab.training.evaluate import load_run_config

    try:
        with contextlib.chdir(root):
            wanted = _effective(train_config(arguments[1:]))
        have = _effective(load_run_config(run_dir))
    except UsageError as exc:
        stop(f"{run_dir}: {exc}")
    if have != wanted:
        names = [field.name for field in dataclasses.fields(have)]
        differ = [name for name in names if getattr(have, name) != getattr(wanted, name)]
        stop(
            f"{run_dir} is not the run of `drivelab {shlex.join(arguments)}` ({', '.join(differ)} differ): "
            "remove it to train it again"
        )
