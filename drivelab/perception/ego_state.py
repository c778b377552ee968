"""Ego state: a short measurement vector about the ego and the vehicle in front (seed 003).

Seed 003's fusion PPO feeds five numbers next to the image and the LiDAR: ego speed, lane offset,
distance to the front vehicle, relative speed to it and heading alignment. Its Dueling DDQN reads
"10 features" per frame next to the 240 LiDAR beams without listing them; ``features=10`` adds
five of our choosing that a driver also knows (heading error's sine, steering, acceleration, lane
curvature, lane position).
"""

from __future__ import annotations

import numpy as np
from gymnasium import spaces

from drivelab.perception.base import Sensor, ego_frame
from drivelab.world.state import WorldState

FUSION_FEATURES = ("speed", "lane_offset", "front_distance", "front_relative_speed", "heading_alignment")
EXTRA_FEATURES = ("heading_error_sin", "steering", "acceleration", "lane_curvature", "lane_position")
MAX_STEERING_RAD = np.pi / 4  # highway-env's steering range
MAX_ACCELERATION_MPS2 = 5.0  # highway-env's acceleration range
CURVATURE_SCALE_M = 50.0  # curvature · 50 m: a 50 m radius reads 1


class EgoState(Sensor):
    """``features`` numbers in [-1, 1] (``FUSION_FEATURES``, then ``EXTRA_FEATURES`` when 10).

    - speed: ego speed over the world's maximum speed;
    - lane_offset: signed offset from the lane centre over half the lane width (+ right);
    - front_distance: gap (centre to centre) to the nearest vehicle ahead within half a lane
      width of the ego's line of travel, over ``range_m``; 1 when there is none;
    - front_relative_speed: that vehicle's speed along the ego heading minus the ego's, over the
      maximum speed; 0 when there is none;
    - heading_alignment: cos(ego heading − lane heading), 1 when aligned with the lane.

    :param features: 5 (the seed's fusion vector) or 10 (adds ``EXTRA_FEATURES``).
    :param range_m: distance at which the front gap saturates.
    """

    name = "ego_state"

    def __init__(self, *, features: int = 5, range_m: float = 50.0) -> None:
        if features not in (5, 10) or range_m <= 0:
            raise ValueError("ego_state needs features 5 or 10 and range_m > 0")
        self.features, self.range_m = int(features), float(range_m)
        self._space = spaces.Box(-1.0, 1.0, shape=(self.features,), dtype=np.float32)

    @property
    def space(self) -> spaces.Box:
        return self._space

    def front_vehicle(self, world: WorldState) -> tuple[float, float]:
        """(gap in metres, speed along the ego heading) of the nearest vehicle ahead; (inf, 0) if none."""
        ego, others = world.ego, world.vehicles
        if len(others) == 0:
            return np.inf, 0.0
        local = ego_frame(others[:, :2], ego.position, ego.heading)
        in_path = (local[:, 0] > 0) & (np.abs(local[:, 1]) < ego.lane_width_m / 2)
        if not in_path.any():
            return np.inf, 0.0
        nearest = np.flatnonzero(in_path)[np.argmin(local[in_path, 0])]
        speed_along = others[nearest, 3] * np.cos(others[nearest, 2] - ego.heading)
        return float(local[nearest, 0]), float(speed_along)

    def observe(self, world: WorldState) -> np.ndarray:
        ego = world.ego
        heading_error = ego.heading - ego.lane_heading
        gap_m, front_speed = self.front_vehicle(world)
        has_front = np.isfinite(gap_m)
        values = [
            ego.speed_mps / world.max_speed_mps,
            ego.lateral_offset_m / max(ego.lane_width_m / 2, 1e-6),
            min(gap_m / self.range_m, 1.0) if has_front else 1.0,
            (front_speed - ego.speed_mps) / world.max_speed_mps if has_front else 0.0,
            np.cos(heading_error),
        ]
        if self.features == 10:
            values += [
                np.sin(heading_error),
                ego.steering / MAX_STEERING_RAD,
                ego.acceleration_mps2 / MAX_ACCELERATION_MPS2,
                ego.lane_curvature * CURVATURE_SCALE_M,
                ego.lane_id / max(ego.lane_count - 1, 1),
            ]
        return np.clip(np.asarray(values, dtype=np.float32), -1.0, 1.0)
