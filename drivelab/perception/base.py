"""The Sensor protocol: a WorldState in, one observation array out."""

from __future__ import annotations

from abc import ABC, abstractmethod

import numpy as np
from gymnasium import spaces

from drivelab.envs.world import WorldState


class Sensor(ABC):
    """Turns a WorldState into one observation array with a declared gymnasium space.

    A sensor may keep history (past ego positions, the previous traffic); ``reset`` clears it
    at the start of each episode and hands over the episode's random generator.
    """

    name: str = "sensor"

    @property
    @abstractmethod
    def space(self) -> spaces.Box:
        """The observation space, fixed at construction."""

    def reset(self, world: WorldState, rng: np.random.Generator) -> None:
        """Clear history at the start of an episode. ``rng`` is the only source of noise."""
        self.rng = rng

    @abstractmethod
    def observe(self, world: WorldState) -> np.ndarray:
        """The observation for ``world``; called once per policy step, after ``reset``."""


def ego_frame(points: np.ndarray, position: np.ndarray, heading: float) -> np.ndarray:
    """World points (..., 2) → ego frame: x forward along the heading, y to the ego's right."""
    cos_h, sin_h = np.cos(heading), np.sin(heading)
    delta = np.asarray(points, dtype=float) - position
    x = delta[..., 0] * cos_h + delta[..., 1] * sin_h
    y = -delta[..., 0] * sin_h + delta[..., 1] * cos_h
    return np.stack([x, y], axis=-1)


def box_corners(boxes: np.ndarray) -> np.ndarray:
    """Corners (N, 4, 2) of rotated rectangles given as rows (x, y, heading, length, width)."""
    x, y, heading, length, width = (boxes[:, i] for i in range(5))
    cos_h, sin_h = np.cos(heading), np.sin(heading)
    half_l = np.array([1, 1, -1, -1]) * (length[:, None] / 2)
    half_w = np.array([-1, 1, 1, -1]) * (width[:, None] / 2)
    corners_x = x[:, None] + half_l * cos_h[:, None] - half_w * sin_h[:, None]
    corners_y = y[:, None] + half_l * sin_h[:, None] + half_w * cos_h[:, None]
    return np.stack([corners_x, corners_y], axis=-1)


ZEBRA_STRIPE_M = (0.5, 1.0)  # stripe width, and stripe-to-stripe pitch across the road


def zebra_stripes(crossings: np.ndarray) -> np.ndarray:
    """The painted stripes of zebra crossings (rows x, y, walking heading, length, width) as boxes
    (K, 5) ``x, y, heading, length, width``: stripes run along the street, as wide as the crossing,
    one every metre across the road."""
    boxes = []
    width_m, pitch_m = ZEBRA_STRIPE_M
    for x, y, heading, length_m, crossing_width_m in np.asarray(crossings, dtype=float).reshape(-1, 5):
        across = np.array([np.cos(heading), np.sin(heading)])
        offsets = np.arange(-length_m / 2 + pitch_m / 2, length_m / 2, pitch_m)
        centres = np.array([x, y]) + offsets[:, None] * across
        street_heading = heading + np.pi / 2
        boxes += [[cx, cy, street_heading, crossing_width_m, width_m] for cx, cy in centres]
    return np.array(boxes, dtype=float).reshape(-1, 5)
