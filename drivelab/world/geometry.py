"""Plane geometry shared by the simulators, sensors and reward terms (the bottom layer).

Every function works on arrays with any leading batch shape: pass ``(K, N, 2)`` points with a
``(K, 1, 2)`` position and ``(K, 1)`` heading to transform K worlds' points at once.
"""

from __future__ import annotations

import numpy as np

FULL_LOCK_RAD = np.pi / 4  # highway-env's ContinuousAction: normalised steering 1 is 45° at the wheels
FULL_LOCK_DEG = 45.0
FULL_ACCELERATION_MPS2 = 5.0  # highway-env's ContinuousAction: normalised acceleration 1 is 5 m/s²
ROACH_MAX_SPEED_MPS = 6.0  # Roach's / RLAD's v_max in the town: target_speed's 1, the reward's v*


def wrap_to_pi(angle: np.ndarray | float) -> np.ndarray | float:
    """Angles wrapped to [-π, π)."""
    return (np.asarray(angle) + np.pi) % (2 * np.pi) - np.pi


def ego_frame(points: np.ndarray, position: np.ndarray, heading: np.ndarray | float) -> np.ndarray:
    """World points (..., 2) → ego frame: x forward along the heading, y to the ego's right.

    ``position`` (..., 2) and ``heading`` (...) broadcast against the points' leading axes.
    """
    cos_h, sin_h = np.cos(heading), np.sin(heading)
    delta = np.asarray(points, dtype=float) - position
    x = delta[..., 0] * cos_h + delta[..., 1] * sin_h
    y = -delta[..., 0] * sin_h + delta[..., 1] * cos_h
    return np.stack([x, y], axis=-1)


def box_corners(boxes: np.ndarray) -> np.ndarray:
    """Corners (..., 4, 2) of rotated rectangles given as rows (..., 5): x, y, heading, length, width."""
    boxes = np.asarray(boxes, dtype=float)
    x, y, heading, length, width = (boxes[..., i, None] for i in range(5))
    cos_h, sin_h = np.cos(heading), np.sin(heading)
    half_l = np.array([1, 1, -1, -1]) * (length / 2)
    half_w = np.array([-1, 1, 1, -1]) * (width / 2)
    corners_x = x + half_l * cos_h - half_w * sin_h
    corners_y = y + half_l * sin_h + half_w * cos_h
    return np.stack([corners_x, corners_y], axis=-1)
