"""The seed protocol of evaluation and tuning.

Training episodes are drawn by each world below ``TRAINING_SEED_LIMIT`` (``envs/vector.py``). The
evaluation set of every scenario is the episodes ``EVALUATION_SEED_BASE``, +1, +2, … given directly
(``reset(options={"episode_seeds": …})``), so no training episode is ever an evaluation episode,
and every run, seed and algorithm is evaluated on the same episodes. Tuning selects
hyper-parameters on validation episodes, the evaluation range from ``VALIDATION_START`` on, so that
no test episode (the first ones: every report, the leaderboard) chooses a configuration.
"""

from __future__ import annotations

import numpy as np

EVALUATION_SEED_BASE = 2**31
VALIDATION_START = 1_000_000


def evaluation_seeds(count: int, start: int = 0) -> np.ndarray:
    """The episode seeds of evaluation episodes ``start`` … ``start + count − 1`` (int64)."""
    return EVALUATION_SEED_BASE + start + np.arange(count, dtype=np.int64)
