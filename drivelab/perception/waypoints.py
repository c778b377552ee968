"""Waypoints: the next points of the planned route, in the ego frame (RLAD's W)."""

from __future__ import annotations

import numpy as np
from gymnasium import spaces

from drivelab.perception.base import Sensor, ego_frame
from drivelab.world.batch import WorldBatch


class Waypoints(Sensor):
    """The route ``count`` points ahead, ``spacing_m`` apart from the ego's projection on it, as
    (x forward, y right) metres in the ego frame; past the route's end the last point repeats.
    RLAD feeds N = 10 planner waypoints; the 2 m spacing is our choice (the paper states none).

    :param count: number of waypoints N.
    :param spacing_m: arc length between consecutive waypoints along the route.
    """

    name = "waypoints"
    help = "next 10 route points, 2 m apart, in the ego frame (m), the last repeated past the end"

    def __init__(self, *, count: int = 10, spacing_m: float = 2.0) -> None:
        if count < 1 or spacing_m <= 0:
            raise ValueError("waypoints needs count >= 1 and spacing_m > 0")
        self.count, self.spacing_m = int(count), float(spacing_m)
        self.range_m = self.count * self.spacing_m + 20.0  # a far-off ego still fits the space
        self._space = spaces.Box(-self.range_m, self.range_m, shape=(self.count, 2), dtype=np.float32)

    def _observe(self, batch: WorldBatch, out: np.ndarray) -> None:
        route, ego = batch.route, batch.ego
        distances = route.progress_m[:, None] + self.spacing_m * np.arange(1, self.count + 1)  # (K, count)
        points, _ = route.poses_at(distances)  # (K, count, 2)
        local = ego_frame(points, ego.position[:, None], ego.heading[:, None])
        out[...] = np.clip(local, -self.range_m, self.range_m)
