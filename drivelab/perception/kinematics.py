"""Kinematics: the nearest vehicles' state in the ego frame, like highway-env's, numpy only."""

from __future__ import annotations

import numpy as np
from gymnasium import spaces

from drivelab.envs.world import WorldState
from drivelab.perception.base import Sensor, ego_frame

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

    def observe(self, world: WorldState) -> np.ndarray:
        ego = world.ego
        rows = np.zeros((self.vehicles_count, len(FEATURES)))
        relative_heading = ego.heading - ego.lane_heading
        rows[0] = [1.0, 0.0, 0.0, ego.speed_mps / self.speed_scale_mps, 0.0,
                   np.cos(relative_heading), np.sin(relative_heading)]  # fmt: skip
        others = world.vehicles
        if len(others) and self.vehicles_count > 1:
            position = ego_frame(others[:, :2], ego.position, ego.heading)
            distance = np.hypot(position[:, 0], position[:, 1])
            seen = np.flatnonzero(distance <= self.perception_distance_m)
            nearest = seen[np.argsort(distance[seen], kind="stable")][: self.vehicles_count - 1]
            if len(nearest):
                heading = others[nearest, 2] - ego.heading
                speed = others[nearest, 3]
                # velocity of the other relative to the ego, in the ego frame
                vx = speed * np.cos(heading) - ego.speed_mps
                vy = speed * np.sin(heading)
                count = len(nearest)
                rows[1 : 1 + count, 0] = 1.0
                rows[1 : 1 + count, 1:3] = position[nearest] / self.perception_distance_m
                rows[1 : 1 + count, 3] = vx / self.speed_scale_mps
                rows[1 : 1 + count, 4] = vy / self.speed_scale_mps
                rows[1 : 1 + count, 5] = np.cos(heading)
                rows[1 : 1 + count, 6] = np.sin(heading)
        return np.clip(rows, -1.0, 1.0).astype(np.float32).reshape(-1)
