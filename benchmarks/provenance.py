"""The command line a benchmark writes into its results: the thread settings in effect (the
environment's, so that the line is true whoever set them) and the arguments, quoted for a shell."""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import inspect
import json
import math
import os
import platform
import re
import shlex
import sys
from collections.abc import Callable, Iterable
from pathlib import Path

THREAD_VARIABLES = ("OMP_NUM_THREADS", "NUMBA_NUM_THREADS")


def cpu_isa() -> str:
    """The architecture and the vector code this process runs (``drivelab.isa.code_paths``), for
    a results file's machine line: numpy, torch and numba round differently on AVX-512 and AVX2."""
    from drivelab.isa import code_paths

    paths = code_paths()
    return f"{platform.machine()} (numpy {paths['numpy']}, torch {paths['torch']}, numba {paths['numba']})"


def provenance(command: str) -> dict[str, str]:
    """The head of a results file: the command that made it, the machine and the date."""
    import time

    machine = f"{cpu_isa()}, {os.cpu_count()} cores, Python {platform.python_version()}"
    return {"command": command, "machine": machine, "date": time.strftime("%Y-%m-%d")}


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


# --- argument types: a bad value is argparse's one line, "argument --steps: 0 is below 1" ------------
def whole(minimum: int = 1) -> Callable[[str], int]:
    """A whole number of at least ``minimum``."""

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r} is not a whole number") from None
        if value < minimum:
            raise argparse.ArgumentTypeError(f"{value} is below {minimum}")
        return value

    return parse


def wholes(minimum: int = 0) -> Callable[[str], list[int]]:
    """Comma-separated whole numbers of at least ``minimum``, none twice (seeds, map counts)."""

    def parse(text: str) -> list[int]:
        values = [whole(minimum)(part) for part in text.split(",")]
        if len(set(values)) != len(values):
            raise argparse.ArgumentTypeError(f"{text!r} names a value twice")
        return values

    return parse


def positive(text: str) -> float:
    """A finite number above zero (seconds, durations)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not math.isfinite(value) or value <= 0:
        raise argparse.ArgumentTypeError(f"{text!r} is not a finite number above 0")
    return value


def names(choices: Iterable[str]) -> Callable[[str], list[str]]:
    """Comma-separated names out of ``choices``, none twice."""
    known = list(choices)

    def parse(text: str) -> list[str]:
        chosen = text.split(",")
        unknown = [name for name in chosen if name not in known]
        if unknown:
            raise argparse.ArgumentTypeError(f"unknown {unknown[0]!r} (known: {', '.join(known)})")
        if len(set(chosen)) != len(chosen):
            raise argparse.ArgumentTypeError(f"{text!r} names one twice")
        return chosen

    return parse


def step_overrides(choices: Iterable[str]) -> Callable[[str], dict[str, int]]:
    """``NAME=STEPS,…`` with each NAME out of ``choices`` and STEPS a whole number above 0."""
    known = list(choices)

    def parse(text: str) -> dict[str, int]:
        steps = {}
        for item in filter(None, text.split(",")):
            name, equals, value = item.partition("=")
            if not equals or name not in known:
                raise argparse.ArgumentTypeError(
                    f"{item!r} is not NAME=STEPS, NAME one of {', '.join(known)}"
                )
            steps[name] = whole(1)(value)
        return steps

    return parse


def mapping(text: str) -> dict:
    """A JSON object (extra hyper-parameters)."""
    try:
        value = json.loads(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(f"not JSON ({exc.msg} at character {exc.pos})") from None
    if not isinstance(value, dict):
        raise argparse.ArgumentTypeError(f"{text!r} is not a JSON object")
    return value


def readable(text: str) -> str:
    """The text of a readable UTF-8 file (notes appended to a report)."""
    try:
        return Path(text).read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise argparse.ArgumentTypeError(
            f"cannot read {text!r} ({getattr(exc, 'strerror', None) or exc})"
        ) from None


def device(text: str) -> str:
    """``cpu`` or ``cuda[:N]``, the latter only where torch sees a CUDA device."""
    if text != "cpu" and not re.fullmatch(r"cuda(:\d+)?", text):
        raise argparse.ArgumentTypeError(f"{text!r} is not cpu or cuda[:N]")
    if text != "cpu":
        import torch

        if not torch.cuda.is_available():
            raise argparse.ArgumentTypeError(f"{text!r}: torch sees no CUDA device here")
    return text


def training_command(run_dir: Path, arguments: list[str], root: Path) -> tuple[list[str], bool]:
    """The ``drivelab`` command that brings the run in ``run_dir`` (no final model yet) to its end,
    and whether it continues one: ``arguments``, its ``train`` command, for a run not started;
    ``train --resume RUN`` for one a killed benchmark left (its config matched by ``check_reuse``
    first), so that the benchmark loses only the work since the run's last checkpoint. A resumed
    run's training time is that of its last part only: the benchmarks record none for it."""
    if (run_dir / "config.yaml").is_file():
        return ["train", "--resume", os.path.relpath(run_dir, root)], True
    return arguments, False


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
