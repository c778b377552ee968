"""Measurements: the ego's own speed and steering (RLAD's V)."""

from __future__ import annotations

import numpy as np
from gymnasium import spaces

from drivelab.perception.base import Sensor
from drivelab.world.batch import WorldBatch

MAX_STEERING_RAD = np.pi / 3  # highway-env's largest steering angle (ControlledVehicle)


class Measurements(Sensor):
    """``[speed / max speed, steering / 60°]``, both clipped to [-1, 1]; ``stack=3`` gives RLAD's
    three frames (6 numbers). Batched: ``(K, 2)``."""

    name = "measurements"
    help = "[speed / max speed, steering / 60 deg]; stack=3 for RLAD's three frames"

    def __init__(self) -> None:
        self._space = spaces.Box(-1.0, 1.0, shape=(2,), dtype=np.float32)

    def _observe(self, batch: WorldBatch, out: np.ndarray) -> None:
        out[:, 0] = batch.ego.speed_mps / batch.max_speed_mps
        out[:, 1] = batch.ego.steering / MAX_STEERING_RAD
        np.clip(out, -1.0, 1.0, out=out)
