"""Freed memory kept for reuse while training (``drivelab/training/allocator.py``)."""

import platform
import subprocess
import sys

import pytest

from drivelab.training import run
from drivelab.training.allocator import keep_freed_memory
from tests.training.tiny_runs import tiny_config

GLIBC = platform.system() == "Linux" and platform.libc_ver()[0] == "glibc"

# 30 blocks of 64 MiB (above glibc's largest automatic mmap threshold, 32 MiB), each written
# through and freed; prints the page faults the loop took
FAULTS = """
import ctypes, resource, sys
from drivelab.training.allocator import keep_freed_memory
if sys.argv[1] == "keep":
    assert keep_freed_memory()
libc = ctypes.CDLL(None)
libc.malloc.restype = ctypes.c_void_p
libc.free.argtypes = [ctypes.c_void_p]
size = 64 << 20
before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
for _ in range(30):
    block = libc.malloc(size)
    ctypes.memset(block, 1, size)
    libc.free(block)
print(resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before)
"""


def _faults(mode: str) -> int:
    done = subprocess.run([sys.executable, "-c", FAULTS, mode], capture_output=True, text=True, check=True)
    return int(done.stdout)


@pytest.mark.skipif(not GLIBC, reason="the thresholds are glibc's")
def test_a_freed_large_block_is_reused_not_mapped_again():
    # unmapped on free, each block is faulted in page by page again; kept, only the first one is
    kept, default = _faults("keep"), _faults("default")
    assert kept * 4 < default, (kept, default)


@pytest.mark.skipif(GLIBC, reason="on glibc the thresholds are taken")
def test_other_c_libraries_are_left_alone():
    assert keep_freed_memory() is False


def test_training_keeps_freed_memory(tmp_path, monkeypatch):
    calls = []
    monkeypatch.setattr(run, "keep_freed_memory", lambda: calls.append(True))
    run.train(tiny_config(steps=64, eval_every=0), tmp_path)
    assert calls == [True]
