"""Reward terms on one world: the worlds stacked into K = 1 batches, the value read back."""

import numpy as np

from drivelab.world.batch import WorldBatch


def one(term, prev, now, control=None) -> float:
    """``term`` for the step ``prev`` → ``now`` (WorldStates; ``prev`` None: ``now``) as a float."""
    prev = now if prev is None else prev
    batched_control = None if control is None else np.asarray(control)[None]
    values = term(WorldBatch.stack([prev]), WorldBatch.stack([now]), batched_control)
    assert values.shape == (1,)
    return float(values[0])
