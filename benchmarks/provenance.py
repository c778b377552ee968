"""The command line a benchmark writes into its results: the thread settings in effect (the
environment's, so that the line is true whoever set them) and the arguments, quoted for a shell."""

from __future__ import annotations

import contextlib
import dataclasses
import os
import shlex
import sys
from pathlib import Path

THREAD_VARIABLES = ("OMP_NUM_THREADS", "NUMBA_NUM_THREADS")


def command_line(argv: list[str] | None = None) -> str:
    """``[OMP_NUM_THREADS=N] [NUMBA_NUM_THREADS=N] python SCRIPT ARGS…`` of this process."""
    settings = [f"{name}={os.environ[name]}" for name in THREAD_VARIABLES if name in os.environ]
    return " ".join([*settings, "python", shlex.join(sys.argv if argv is None else argv)])


def check_reuse(run_dir: Path, arguments: list[str], root: Path) -> None:
    """Stop the benchmark (one ``error:`` line, exit 2) when the finished run it would reuse is not
    the run ``drivelab ARGUMENTS`` trains today (``arguments`` start with ``train``; paths in them
    from ``root``): a table must not list one command beside the numbers of another."""
    from drivelab.cli import train_config
    from drivelab.training.evaluate import load_run_config

    with contextlib.chdir(root):
        wanted = train_config(arguments[1:])
    have = load_run_config(run_dir)
    if have != wanted:
        names = [field.name for field in dataclasses.fields(have)]
        differ = [name for name in names if getattr(have, name) != getattr(wanted, name)]
        print(
            f"error: {run_dir} is not the run of `drivelab {shlex.join(arguments)}` ({', '.join(differ)} "
            "differ): remove it to train it again",
            file=sys.stderr,
        )
        raise SystemExit(2)
