"""The command line a benchmark writes into its results: the thread settings in effect (the
environment's, so that the line is true whoever set them) and the arguments, quoted for a shell."""

from __future__ import annotations

import os
import shlex
import sys

THREAD_VARIABLES = ("OMP_NUM_THREADS", "NUMBA_NUM_THREADS")


def command_line(argv: list[str] | None = None) -> str:
    """``[OMP_NUM_THREADS=N] [NUMBA_NUM_THREADS=N] python SCRIPT ARGS…`` of this process."""
    settings = [f"{name}={os.environ[name]}" for name in THREAD_VARIABLES if name in os.environ]
    return " ".join([*settings, "python", shlex.join(sys.argv if argv is None else argv)])
