"""Whether an agent's replay buffer, rollout or training batch can fit in this machine's memory:
``check_buffer_memory`` refuses a size (``-H buffer_size=1e12``) whose estimated bytes exceed the
physical memory before the agent is built, rather than a MemoryError or the OOM killer later.
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
