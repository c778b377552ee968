"""Whether an agent's replay buffer, rollout or training batch can fit in this machine's memory.

Buffers are arrays of (size, *observation shape): a size no machine can hold (``-H
buffer_size=1e12``) ends in a MemoryError traceback when they are allocated, or, allocated lazily
(numpy's zeros), in the out-of-memory killer once they fill. ``check_buffer_memory`` refuses such
a size before the agent is built, from an estimate of its bytes: the observation's bytes times the
copies the buffer keeps, plus a few bytes of action, reward and flags per entry. The bound is the
machine's physical memory, the most any buffer could ever use; sensible sizes (SB3's 1 M
transitions of vectors, 100 k of 84 × 84 images) stay far below it.
"""

from __future__ import annotations

import math
import os

from gymnasium import spaces

from drivelab.errors import UsageError

ENTRY_OVERHEAD_BYTES = 64  # action, reward, done, timeout, value, log-prob … of one entry, generously
GIB = 2**30


def observation_bytes(space: spaces.Space, itemsize: int | None = None) -> int:
    """Bytes of one observation of ``space`` (Dict and Tuple: their parts summed), each value
    ``itemsize`` bytes when given (buffers that store float32 whatever the space's dtype), else the
    space's own."""
    if isinstance(space, spaces.Dict):
        return sum(observation_bytes(part, itemsize) for part in space.spaces.values())
    if isinstance(space, spaces.Tuple):
        return sum(observation_bytes(part, itemsize) for part in space.spaces)
    size = itemsize if itemsize is not None else (space.dtype.itemsize if space.dtype is not None else 8)
    return math.prod(space.shape or ()) * size


def physical_memory_bytes() -> int | None:
    """This machine's physical memory in bytes (None where the system does not say)."""
    try:
        return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (AttributeError, ValueError, OSError):
        return None


def check_buffer_memory(algo: str, key: str, entries: int, entry_bytes: int, what: str = "buffer") -> None:
    """Refuse ``key`` (its buffer of ``entries`` entries of ``entry_bytes`` each) when the buffer
    would take more than this machine's physical memory."""
    memory = physical_memory_bytes()
    needed = int(entries) * (int(entry_bytes) + ENTRY_OVERHEAD_BYTES)
    if memory is not None and needed > memory:
        raise UsageError(
            f"hyperparameter {key!r} of {algo!r} asks for a {what} of {entries} entries, about "
            f"{needed / GIB:.3g} GiB, more than this machine's {memory / GIB:.3g} GiB of memory"
        )
