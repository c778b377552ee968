"""Kinematics: the nearest vehicles' state in the ego frame, like highway-env's, numpy only."""

from __future__ import annotations

import numpy as np
from gymnasium import spaces

from drivelab.perception.base import Sensor, ego_frame
from drivelab.world.batch import WorldBatch

FEATURES = ("presence", "x", "y", "vx", "vy", "cos_h", "sin_h")


class Kinematics(Sensor):
    """A flat vector of ``vehicles_count`` rows × 7 features, all in [-1, 1].

    Features per row: ``presence, x, y, vx, vy, cos_h, sin_h`` (``FEATURES``). Row 0 is the
    ego: presence 1, position (0, 0), its velocity (speed, 0) in its own frame, and its heading
    relative to its lane (so a drifting ego sees sin_h ≠ 0). Rows 1… are the nearest other
    vehicles within ``perception_distance_m`` (centre to centre), nearest first: position and
    velocity relative to the ego, in the ego frame (x forward, y right), and heading relative
    to the ego. Positions are divided by the perception distance, velocities by
    ``speed_scale_mps``, then everything is clipped to [-1, 1]; absent rows are all zero.

    :param vehicles_count: rows, the ego included.
    :param perception_distance_m: vehicles farther than this are not seen.
    :param speed_scale_mps: velocity normalisation; highway-env's 2 × its 40 m/s maximum speed.
    """

    name = "kinematics"

    def __init__(
        self, *, vehicles_count: int = 5, perception_distance_m: float = 100.0, speed_scale_mps: float = 80.0
    ) -> None:
        if vehicles_count < 1 or perception_distance_m <= 0 or speed_scale_mps <= 0:
            raise ValueError("kinematics needs vehicles_count >= 1 and positive distance and speed scales")
        self.vehicles_count = int(vehicles_count)
        self.perception_distance_m = float(perception_distance_m)
        self.speed_scale_mps = float(speed_scale_mps)
        size = self.vehicles_count * len(FEATURES)
        self._space = spaces.Box(-1.0, 1.0, shape=(size,), dtype=np.float32)

    @property
    def space(self) -> spaces.Box:
        return self._space

    def _observe(self, batch: WorldBatch, out: np.ndarray) -> None:
        ego, count = batch.ego, self.vehicles_count
        rows = np.zeros((batch.num_worlds, count, len(FEATURES)))  # (K, rows, 7)
        relative_heading = ego.heading - ego.lane_heading
        rows[:, 0, 0] = 1.0
        rows[:, 0, 3] = ego.speed_mps / self.speed_scale_mps
        rows[:, 0, 5], rows[:, 0, 6] = np.cos(relative_heading), np.sin(relative_heading)
        others = batch.vehicles  # (K, N, 6)
        if others.shape[1] and count > 1:
            position = ego_frame(others[..., :2], ego.position[:, None], ego.heading[:, None])
            distance = np.hypot(position[..., 0], position[..., 1])
            seen = batch.vehicle_valid & (distance <= self.perception_distance_m)
            # nearest first; unseen slots sort last (a stable sort keeps highway-env's order on ties)
            order = np.argsort(np.where(seen, distance, np.inf), axis=1, kind="stable")[:, : count - 1]
            worlds = np.arange(batch.num_worlds)[:, None]
            present = seen[worlds, order]  # (K, count - 1)
            nearest = others[worlds, order]
            heading = nearest[..., 2] - ego.heading[:, None]
            speed = nearest[..., 3]
            # velocity of the other relative to the ego, in the ego frame
            vx = speed * np.cos(heading) - ego.speed_mps[:, None]
            vy = speed * np.sin(heading)
            block = rows[:, 1 : 1 + order.shape[1]]
            block[..., 0] = 1.0
            block[..., 1:3] = position[worlds, order] / self.perception_distance_m
            block[..., 3] = vx / self.speed_scale_mps
            block[..., 4] = vy / self.speed_scale_mps
            block[..., 5] = np.cos(heading)
            block[..., 6] = np.sin(heading)
            block *= present[..., None]
        out[...] = np.clip(rows, -1.0, 1.0).reshape(batch.num_worlds, -1)
