"""Clock: how far the episode is into its time, for tasks where beating the clock is the task."""

from __future__ import annotations

import numpy as np
from gymnasium import spaces

from drivelab.perception.base import Sensor
from drivelab.world.batch import WorldBatch


class Clock(Sensor):
    """``[elapsed episode time / horizon_s]``, clipped to [0, 1]. Batched: ``(K, 1)``.

    A policy that must arrive before a time limit (the intersection's 13 s) cannot tell a late
    moment from an early one without it (Pardo et al. 2018, "Time Limits in Reinforcement
    Learning"); set ``horizon_s`` to the limit, so that 1 means time is up.

    :param horizon_s: the elapsed time that reads 1.
    """

    name = "clock"
    help = "elapsed episode time / horizon_s (default 60 s), clipped to [0, 1]"

    def __init__(self, *, horizon_s: float = 60.0) -> None:
        if not horizon_s > 0:
            raise ValueError("clock needs horizon_s > 0")
        self.horizon_s = float(horizon_s)
        self._space = spaces.Box(0.0, 1.0, shape=(1,), dtype=np.float32)

    def _observe(self, batch: WorldBatch, out: np.ndarray) -> None:
        np.clip(batch.time_s / self.horizon_s, 0.0, 1.0, out=out[:, 0])
