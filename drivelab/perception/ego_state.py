"""Ego state: a short measurement vector about the ego and the vehicle in front (the MetaDrive study's
five fusion features; ``features=10`` adds five of our choosing for its Dueling DDQN's unlisted
"10 features").
"""

from __future__ import annotations

import numpy as np
from gymnasium import spaces

from drivelab.perception.base import Sensor, ego_frame
from drivelab.world.batch import WorldBatch
from drivelab.world.geometry import FULL_LOCK_RAD
from drivelab.world.state import WorldState

FUSION_FEATURES = ("speed", "lane_offset", "front_distance", "front_relative_speed", "heading_alignment")
EXTRA_FEATURES = ("heading_error_sin", "steering", "acceleration", "lane_curvature", "lane_position")
MAX_STEERING_RAD = FULL_LOCK_RAD  # highway-env's steering range
MAX_ACCELERATION_MPS2 = 5.0  # highway-env's acceleration range
CURVATURE_SCALE_M = 50.0  # curvature · 50 m: a 50 m radius reads 1


class EgoState(Sensor):
    """``features`` numbers in [-1, 1] (``FUSION_FEATURES``, then ``EXTRA_FEATURES`` when 10):
    speed over the maximum speed; lane offset over half the lane width (+ right); the gap to the
    nearest vehicle ahead in the ego's lane over ``range_m`` (1: none); that vehicle's speed along
    the ego heading minus the ego's, over the maximum speed (0: none); cos(heading − lane heading).

    :param features: 5 (the seed's fusion vector) or 10 (adds ``EXTRA_FEATURES``).
    :param range_m: distance at which the front gap saturates.
    """

    name = "ego_state"
    help = "speed, lane offset, front gap, front relative speed, heading alignment (features=10: +5)"

    def __init__(self, *, features: int = 5, range_m: float = 50.0) -> None:
        if features not in (5, 10) or range_m <= 0:
            raise ValueError("ego_state needs features 5 or 10 and range_m > 0")
        self.features, self.range_m = int(features), float(range_m)
        self._space = spaces.Box(-1.0, 1.0, shape=(self.features,), dtype=np.float32)

    def front_vehicle(self, batch: WorldBatch | WorldState) -> tuple[np.ndarray, np.ndarray]:
        """(K,) gaps in metres and (K,) speeds along the ego heading of the nearest vehicle ahead
        within half a lane width of the ego's line of travel: (inf, 0) where there is none.
        Floats for a WorldState."""
        if isinstance(batch, WorldState):
            gap, speed = self.front_vehicle(WorldBatch.stack([batch]))
            return float(gap[0]), float(speed[0])
        ego, others, count = batch.ego, batch.vehicles, batch.num_worlds  # others (K, N, 6)
        if others.shape[1] == 0:
            return np.full(count, np.inf), np.zeros(count)
        local = ego_frame(others[..., :2], ego.position[:, None], ego.heading[:, None])  # (K, N, 2)
        half_lane = ego.lane_width_m[:, None] / 2
        in_path = batch.vehicle_valid & (local[..., 0] > 0) & (np.abs(local[..., 1]) < half_lane)
        gaps = np.where(in_path, local[..., 0], np.inf)
        nearest = np.argmin(gaps, axis=1)  # the first of the nearest, as a search of one world's rows
        rows = np.arange(count)
        gap, front = gaps[rows, nearest], others[rows, nearest]  # gap: inf where none is in the path
        speed_along = np.where(np.isfinite(gap), front[:, 3] * np.cos(front[:, 2] - ego.heading), 0.0)
        return gap, speed_along

    def _observe(self, batch: WorldBatch, out: np.ndarray) -> None:
        ego = batch.ego
        heading_error = ego.heading - ego.lane_heading
        gap_m, front_speed = self.front_vehicle(batch)
        has_front = np.isfinite(gap_m)
        values = [
            ego.speed_mps / batch.max_speed_mps,
            ego.lateral_offset_m / np.maximum(ego.lane_width_m / 2, 1e-6),
            np.where(has_front, np.minimum(gap_m / self.range_m, 1.0), 1.0),
            np.where(has_front, (front_speed - ego.speed_mps) / batch.max_speed_mps, 0.0),
            np.cos(heading_error),
        ]
        if self.features == 10:
            values += [
                np.sin(heading_error),
                ego.steering / MAX_STEERING_RAD,
                ego.acceleration_mps2 / MAX_ACCELERATION_MPS2,
                ego.lane_curvature * CURVATURE_SCALE_M,
                ego.lane_id / np.maximum(ego.lane_count - 1, 1),
            ]
        out[...] = np.stack(values, axis=1)  # (K, features)
        np.clip(out, -1.0, 1.0, out=out)
