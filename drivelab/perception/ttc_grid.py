"""A discrete time-to-collision grid: highway driving as a small tabular state for Q-learning.

After highway-env's ``TimeToCollision`` observation: for the left, current and right lane, the
time to the nearest closing vehicle ahead falls in one of ``len(TTC_EDGES_S) + 1`` bins (a lane
that does not exist counts as the most urgent), times 3 speed bins: 4³ · 3 = 192 states.
"""

from __future__ import annotations

import numpy as np
from gymnasium import spaces

from drivelab.perception.base import Sensor, ego_frame
from drivelab.world.batch import WorldBatch
from drivelab.world.state import WorldState

TTC_EDGES_S = np.array([2.0, 4.0, 8.0])  # bins [0, 2), [2, 4), [4, 8), ≥ 8 s or never
SPEED_EDGES_MPS = np.array([22.0, 27.0])  # highway-env's target speeds 20 / 25 / 30 m/s, binned


def lane_ttc_s(batch: WorldBatch | WorldState) -> np.ndarray:
    """Time to collision (s) with the nearest closing vehicle ahead in the lanes −1, 0, +1 (left, own,
    right; inf where none closes in, 0 where the lane does not exist): (K, 3), or (3,) for a
    WorldState."""
    if isinstance(batch, WorldState):
        return lane_ttc_s(WorldBatch.stack([batch]))[0]
    ego, vehicles = batch.ego, batch.vehicles  # vehicles (K, N, 6)
    lane_exists = np.stack(
        [ego.lane_id > 0, np.ones(batch.num_worlds, dtype=bool), ego.lane_id < ego.lane_count - 1], axis=1
    )
    local = ego_frame(vehicles[..., :2], ego.position[:, None], ego.heading[:, None])  # (K, N, 2)
    lane_width = np.maximum(ego.lane_width_m, 1e-6)[:, None]
    relative_lane = np.round((local[..., 1] + ego.lateral_offset_m[:, None]) / lane_width).astype(int)
    length = ego.length_m[:, None]
    gap = local[..., 0] - (vehicles[..., 4] + length) / 2
    closing = ego.speed_mps[:, None] - vehicles[..., 3] * np.cos(vehicles[..., 2] - ego.heading[:, None])
    with np.errstate(divide="ignore", invalid="ignore"):
        time_s = np.where((gap > -length) & (closing > 0), np.maximum(gap, 0.0) / closing, np.inf)
    time_s = np.where(batch.vehicle_valid, time_s, np.inf)
    # the nearest in each of the three lanes: (K, N, 3) → (K, 3), inf where the lane has none
    in_lane = relative_lane[..., None] == np.arange(-1, 2)
    ttc = np.min(np.where(in_lane, time_s[..., None], np.inf), axis=1, initial=np.inf)
    return np.where(lane_exists, ttc, 0.0)


class TTCGrid(Sensor):
    """Discrete highway state: time-to-collision bins of 3 lanes and a speed bin (``Discrete(192)``);
    batched, the observations are ``(K,)`` integers."""

    name = "ttc_grid"
    help = "discrete highway state: time-to-collision bins of 3 lanes x speed bin (192 states)"

    def __init__(self) -> None:
        self.bins = len(TTC_EDGES_S) + 1
        self._space = spaces.Discrete(self.bins**3 * (len(SPEED_EDGES_MPS) + 1))

    def _observe(self, batch: WorldBatch, out: np.ndarray) -> None:
        lanes = np.searchsorted(TTC_EDGES_S, lane_ttc_s(batch), side="right")  # (K, 3)
        speed = np.searchsorted(SPEED_EDGES_MPS, batch.ego.speed_mps, side="right")  # (K,)
        out[...] = lanes[:, 0] + self.bins * lanes[:, 1] + self.bins**2 * lanes[:, 2] + self.bins**3 * speed
