"""The pinhole camera model: intrinsics, mounting on the ego, and its projections (the CARLA study's camera).

The ego frame has x forward, y to the right, z up; the camera sits ``forward_m`` ahead of the
ego's centre, ``height_m`` above the ground, pitched down by ``pitch_deg``. Camera coordinates
(X right, Y down, Z along the axis) land at ``u = cx + f·X/Z``, ``v = cy + f·Y/Z`` with
``cx = (W − 1)/2``, ``cy = (H − 1)/2``, ``f = (W/2) / tan(fov/2)`` (OpenCV's pixel centres).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np
from numba import njit


@dataclass(frozen=True)
class PinholeModel:
    """Intrinsics and mounting of the camera, and the projections it defines.

    :param width: image width in pixels.
    :param height: image height in pixels.
    :param fov_deg: horizontal field of view.
    :param height_m: mounting height above the ground.
    :param pitch_deg: downward pitch of the optical axis.
    :param forward_m: mounting point ahead of the ego's centre.
    :param max_range_m: ground farther than this (ahead of the camera) is not drawn.
    :param near_m: ground nearer than this ahead of the camera is clipped away.
    """

    width: int = 84
    height: int = 84
    fov_deg: float = 90.0
    height_m: float = 1.5
    pitch_deg: float = 15.0
    forward_m: float = 1.0
    max_range_m: float = 50.0
    near_m: float = 0.3

    def __post_init__(self) -> None:
        if self.width < 8 or self.height < 8:
            raise ValueError("camera needs width and height >= 8")
        if not 10.0 <= self.fov_deg <= 170.0:
            raise ValueError("camera fov_deg must lie in [10, 170]")
        if self.height_m <= 0 or not -30.0 <= self.pitch_deg <= 80.0:
            raise ValueError("camera needs height_m > 0 and pitch_deg in [-30, 80]")
        if self.max_range_m <= self.near_m:
            raise ValueError("camera max_range_m must exceed near_m")

    @property
    def focal_px(self) -> float:
        return (self.width / 2) / np.tan(np.radians(self.fov_deg) / 2)

    @property
    def centre(self) -> tuple[float, float]:
        return (self.width - 1) / 2, (self.height - 1) / 2

    @property
    def horizon_row(self) -> float:
        """Row where the ground meets the sky at infinity."""
        return self.centre[1] - self.focal_px * np.tan(np.radians(self.pitch_deg))

    def to_camera(self, points_ego: np.ndarray) -> np.ndarray:
        """Ego-frame points (..., 3) → camera coordinates (..., 3): X right, Y down, Z forward."""
        pitch = np.radians(self.pitch_deg)
        cos_p, sin_p = np.cos(pitch), np.sin(pitch)
        q = np.asarray(points_ego, dtype=float)
        dx, dy, dz = q[..., 0] - self.forward_m, q[..., 1], q[..., 2] - self.height_m
        forward = dx * cos_p - dz * sin_p  # axis (cos p, 0, −sin p)
        down = -dx * sin_p - dz * cos_p  # axis (−sin p, 0, −cos p)
        return np.stack([dy, down, forward], axis=-1)

    def project(self, points_ego: np.ndarray) -> np.ndarray:
        """Ego-frame points (..., 3) in front of the camera → float pixels (..., 2) as (u, v)."""
        camera = self.to_camera(points_ego)
        cx, cy = self.centre
        depth = np.maximum(camera[..., 2], 1e-6)
        return np.stack(
            [cx + self.focal_px * camera[..., 0] / depth, cy + self.focal_px * camera[..., 1] / depth], -1
        )

    def project_ground(self, points_ego: np.ndarray) -> np.ndarray:
        """Ground points (..., 2) in the ego frame (z = 0) → float pixels (..., 2)."""
        points = np.asarray(points_ego, dtype=float)
        return self.project(np.concatenate([points, np.zeros(points.shape[:-1] + (1,))], axis=-1))

    @cached_property
    def ground_terms(self) -> np.ndarray:
        """(cx, focal, forward, cos p, sin p, camera height, image width) as ``project`` computes
        them, made once: the ``terms`` of the compiled :func:`visible_columns_into`."""
        pitch = np.radians(self.pitch_deg)
        cx, focal = self.centre[0], self.focal_px
        terms = np.array([cx, focal, self.forward_m, np.cos(pitch), np.sin(pitch), self.height_m, self.width])
        terms.setflags(write=False)
        return terms

    def row_of_distance(self, distance_m: np.ndarray | float) -> np.ndarray:
        """Image row (float) of the ground straight ahead at ``distance_m`` ahead of the ego centre."""
        distance = np.asarray(distance_m, dtype=float)
        return self.project_ground(np.stack([distance, np.zeros_like(distance)], axis=-1))[..., 1]

    def distance_of_row(self, row: np.ndarray | float) -> np.ndarray:
        """Ground distance ahead of the ego centre seen at image ``row`` (inf at or above the horizon)."""
        pitch = np.radians(self.pitch_deg)
        slope = (np.asarray(row, dtype=float) - self.centre[1]) / self.focal_px
        falling = np.sin(pitch) + slope * np.cos(pitch)  # downward component of the ray
        along = np.cos(pitch) - slope * np.sin(pitch)
        with np.errstate(divide="ignore"):
            return np.where(falling > 1e-9, self.forward_m + self.height_m * along / falling, np.inf)


@njit(cache=True)
def visible_columns_into(distances, lateral, terms, out) -> None:
    """Image columns (K, D) into ``out`` of ground points ``distances`` (D,) ahead and ``lateral``
    (K, D) to the right of the ego centre, nan where the point falls outside the image (or
    ``lateral`` is nan): ``project_ground(...)[..., 0]`` without building the 3-D points. ``terms``
    (7,) are the model's ``ground_terms`` (cx, focal, forward, cos p, sin p, camera height, image
    width); numpy's operations in numpy's order (no fused multiply-adds), so the columns are
    numpy's to the bit."""
    cx, focal, forward_m, cos_p, sin_p = terms[0], terms[1], terms[2], terms[3], terms[4]
    height_m, width = terms[5], terms[6]
    for j in range(distances.shape[0]):
        depth = max((distances[j] - forward_m) * cos_p - (0.0 - height_m) * sin_p, 1e-6)
        for k in range(lateral.shape[0]):
            column = cx + focal * lateral[k, j] / depth
            # false for nan: comparisons with nan never hold
            out[k, j] = column if column >= -0.5 and column <= width - 0.5 else np.nan


# The follow-line and follow-lane cameras of the CARLA study (their sensors and reward terms share them).
# A 160 x 120 camera with the line rows 3–8 m ahead, where the 0.3 m line is at least 3 px wide,
# so that a 3 x 3 opening keeps it. The seed does not give its rows; these are our choice.
LINE_CAMERA = PinholeModel(width=160, height=120, fov_deg=90, height_m=1.5, pitch_deg=15, max_range_m=80)
LINE_ROWS_M = (3.0, 4.5, 6.0, 8.0)  # nearest row first
LANE_CAMERA = PinholeModel(width=160, height=120, fov_deg=90, height_m=1.5, pitch_deg=15, max_range_m=80)
LANE_ROWS_M = (4.0, 6.0, 9.0, 13.0)  # nearest row first; the seed does not give its rows
