"""Freed memory kept for reuse while training, instead of handed back to the system each time.

glibc's ``malloc`` serves every block above a threshold (32 MiB at most, adjusted as the program
runs) with a fresh ``mmap`` and returns it on ``free``; it also trims the top of its heap back to
the system. A PPO update allocates the same large activations and gradients for every minibatch
(a CNN's, for 1,024 images: blocks of tens of megabytes), so each one is mapped, zeroed page by
page by the kernel and unmapped again, many times a rollout. On the town's bird's-eye recipe that
was a third of the training time, spent in the kernel (``benchmarks/results/trainer_allocator.md``);
with both thresholds raised the process reuses its blocks.

The numbers an agent computes do not depend on where its memory lies: a run trains to the same
bytes either way. The cost is memory: the heap keeps its largest size until the process ends.
Other C libraries (macOS, musl) are left as they are.
"""

from __future__ import annotations

import ctypes
import platform

M_TRIM_THRESHOLD = -1  # glibc's <malloc.h>: free memory kept at the heap's top before trimming
M_MMAP_THRESHOLD = -3  # glibc's <malloc.h>: the size from which a block gets an mmap of its own
KEEP_BYTES = 1 << 30  # blocks up to 1 GiB come from the heap, and up to 1 GiB free stays there


def keep_freed_memory() -> bool:
    """Raise glibc's mmap and trim thresholds to ``KEEP_BYTES`` for this process (a fixed
    threshold also stops glibc adjusting it); whether this process runs on glibc and took them."""
    if platform.system() != "Linux" or platform.libc_ver()[0] != "glibc":
        return False
    libc = ctypes.CDLL(None)
    return bool(libc.mallopt(M_MMAP_THRESHOLD, KEEP_BYTES)) and bool(
        libc.mallopt(M_TRIM_THRESHOLD, KEEP_BYTES)
    )
