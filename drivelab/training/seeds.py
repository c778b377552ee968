"""The seed protocol of evaluation and tuning.

Training episodes are drawn below ``TRAINING_SEED_LIMIT`` (``envs/vector.py``); the evaluation set
of every scenario is the episodes ``EVALUATION_SEED_BASE``, +1, +2, …, the same for every run and
never a training episode. Tuning selects on validation episodes, from ``VALIDATION_START`` on, so
that no test episode (the first ones: every report, the leaderboard) chooses a configuration."""

from __future__ import annotations

import numpy as np

EVALUATION_SEED_BASE = 2**31
VALIDATION_START = 1_000_000


def evaluation_seeds(count: int, start: int = 0) -> np.ndarray:
    """The episode seeds of evaluation episodes ``start`` … ``start + count − 1`` (int64)."""
    return EVALUATION_SEED_BASE + start + np.arange(count, dtype=np.int64)
