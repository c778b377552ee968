"""One instruction set for numbers that must agree across x86-64 machines.

numpy, OpenBLAS, oneDNN, torch and numba pick AVX-512 or AVX2 code at run time, which round
differently: an agent's check episodes give numbers a few float32 ulps apart on the two kinds of
CPU. ``PINNED_ISA`` caps every one of them at AVX2 (and one thread each), so a number recorded and
checked under it is the same on both. The variables are read when each library loads, so
``call_pinned`` runs a function in a fresh process and returns its JSON result.

    python -m drivelab.isa MODULE:FUNCTION [ARG ...]   # prints the function's result as JSON
"""

from __future__ import annotations

import importlib
import json
import os
import subprocess
import sys
import tempfile
from typing import Any

PINNED_ISA = {
    # numpy's SIMD dispatch (features this CPU lacks are ignored by numpy)
    "NPY_DISABLE_CPU_FEATURES": "X86_V4 AVX512_ICL AVX512_SPR",
    "OPENBLAS_CORETYPE": "Haswell",  # numpy's OpenBLAS
    "ATEN_CPU_CAPABILITY": "avx2",  # torch's own vectorised kernels
    "ONEDNN_MAX_CPU_ISA": "AVX2",  # torch's convolutions (oneDNN)
    "MKL_ENABLE_INSTRUCTIONS": "AVX2",  # torch's matrix products (MKL)
    "NUMBA_CPU_NAME": "haswell",  # drivelab's compiled kernels
    # torch.compile's kernels in a cache of their own: inductor's cache key misses these pins, and
    # a native process that loads kernels compiled under them aborts (RLAD's fast update did)
    "TORCHINDUCTOR_CACHE_DIR": os.path.join(tempfile.gettempdir(), f"torchinductor_{os.getuid()}_avx2"),
    "OMP_NUM_THREADS": "1",
    "MKL_NUM_THREADS": "1",
    "NUMBA_NUM_THREADS": "1",
}


def code_paths() -> dict[str, str]:
    """The vector code each library of this process runs: numpy's widest enabled feature, torch's
    kernels' capability, numba's target CPU."""
    import llvmlite.binding
    import torch
    from numba.core import config
    from numpy._core._multiarray_umath import __cpu_dispatch__, __cpu_features__

    enabled = [feature for feature in __cpu_dispatch__ if __cpu_features__.get(feature)]
    return {
        "numpy": enabled[-1] if enabled else "baseline",
        "torch": torch.backends.cpu.get_cpu_capability(),
        "numba": config.CPU_NAME or llvmlite.binding.get_host_cpu_name(),
    }


def call_pinned(target: str, *args: str, timeout_s: float | None = None) -> Any:
    """``MODULE:FUNCTION(*args)`` in a fresh Python under ``PINNED_ISA``; its JSON result.

    :param target: e.g. ``"drivelab.training.zoo:check_metrics"``; the function takes strings and
        returns something ``json.dumps`` writes.
    :raises RuntimeError: the child failed (its last lines of stderr in the message).
    """
    child = subprocess.run(
        [sys.executable, "-m", "drivelab.isa", target, *args],
        env={**os.environ, **PINNED_ISA},
        capture_output=True,
        text=True,
        timeout=timeout_s,
        check=False,
    )
    lines = child.stdout.strip().splitlines()
    if child.returncode != 0 or not lines:
        tail = "\n".join(child.stderr.strip().splitlines()[-15:])
        raise RuntimeError(f"{target}{args} under the pinned ISA exited {child.returncode}:\n{tail}")
    return json.loads(lines[-1])


def main(argv: list[str]) -> None:
    module, _, function = argv[0].partition(":")
    result = getattr(importlib.import_module(module), function)(*argv[1:])
    print(json.dumps(result))


if __name__ == "__main__":
    main(sys.argv[1:])
