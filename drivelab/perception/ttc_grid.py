"""A discrete time-to-collision grid: highway driving as a small tabular state for Q-learning.

After highway-env's ``TimeToCollision`` observation (lanes × time bins), reduced to one integer:
for the left, current and right lane, the time to reach the nearest vehicle ahead at the current
closing speed falls in one of ``len(TTC_EDGES_S) + 1`` bins (the last: no vehicle closing in), and
a lane that does not exist counts as the most urgent bin; the ego's speed adds 3 bins. With the
default edges: 4³ · 3 = 192 states.
"""

from __future__ import annotations

import numpy as np
from gymnasium import spaces

from drivelab.perception.base import Sensor, ego_frame
from drivelab.world.state import WorldState

TTC_EDGES_S = np.array([2.0, 4.0, 8.0])  # bins [0, 2), [2, 4), [4, 8), ≥ 8 s or never
SPEED_EDGES_MPS = np.array([22.0, 27.0])  # highway-env's target speeds 20 / 25 / 30 m/s, binned


def lane_ttc_s(world: WorldState) -> np.ndarray:
    """Time to collision (s) with the nearest closing vehicle ahead in the lanes −1, 0, +1 (left, own,
    right; inf where none closes in, 0 where the lane does not exist)."""
    ego = world.ego
    ttc = np.full(3, np.inf)
    lane_exists = np.array([ego.lane_id > 0, True, ego.lane_id < ego.lane_count - 1])
    if len(world.vehicles):
        local = ego_frame(world.vehicles[:, :2], ego.position, ego.heading)
        relative_lane = np.round((local[:, 1] + ego.lateral_offset_m) / max(ego.lane_width_m, 1e-6)).astype(
            int
        )
        gap = local[:, 0] - (world.vehicles[:, 4] + ego.length_m) / 2
        closing = ego.speed_mps - world.vehicles[:, 3] * np.cos(world.vehicles[:, 2] - ego.heading)
        with np.errstate(divide="ignore", invalid="ignore"):
            time_s = np.where((gap > -ego.length_m) & (closing > 0), np.maximum(gap, 0.0) / closing, np.inf)
        for offset in (-1, 0, 1):
            in_lane = relative_lane == offset
            if in_lane.any():
                ttc[offset + 1] = time_s[in_lane].min()
    return np.where(lane_exists, ttc, 0.0)


class TTCGrid(Sensor):
    """Discrete highway state: time-to-collision bins of 3 lanes and a speed bin (``Discrete(192)``)."""

    name = "ttc_grid"

    def __init__(self) -> None:
        self.bins = len(TTC_EDGES_S) + 1
        self._space = spaces.Discrete(self.bins**3 * (len(SPEED_EDGES_MPS) + 1))

    @property
    def space(self) -> spaces.Discrete:
        return self._space

    def observe(self, world: WorldState) -> np.int64:
        lanes = np.searchsorted(TTC_EDGES_S, lane_ttc_s(world), side="right")
        speed = int(np.searchsorted(SPEED_EDGES_MPS, world.ego.speed_mps, side="right"))
        return np.int64(int(lanes[0] + self.bins * lanes[1] + self.bins**2 * lanes[2]) + self.bins**3 * speed)
