"""LiDAR: beams around the ego that stop at other vehicles and at road edges (seed 003)."""

from __future__ import annotations

import numpy as np
from gymnasium import spaces

from drivelab.envs.world import WorldState
from drivelab.perception.base import Sensor, box_corners


def _cross(ax, ay, bx, by):
    return ax * by - ay * bx


def cast_rays(origin: np.ndarray, angles: np.ndarray, segments: np.ndarray, range_m: float) -> np.ndarray:
    """Distance along each ray to the first segment it meets, ``range_m`` when none.

    :param origin: (2,) ray origin.
    :param angles: (N,) world-frame ray directions, radians.
    :param segments: (M, 2, 2) segments as pairs of end points.
    """
    distances = np.full(len(angles), float(range_m))
    if len(segments) == 0:
        return distances
    start, end = segments[:, 0], segments[:, 1]
    # keep the segments whose nearest point lies within range (a 10 km edge counts by that point)
    edge = end - start
    length2 = np.maximum((edge**2).sum(axis=1), 1e-12)
    t = np.clip(((origin - start) * edge).sum(axis=1) / length2, 0.0, 1.0)
    near = np.hypot(*(start + t[:, None] * edge - origin).T) <= range_m
    if not near.any():
        return distances
    start, edge = start[near], edge[near]
    dx, dy = np.cos(angles)[:, None], np.sin(angles)[:, None]  # (N, 1)
    wx, wy = (start - origin).T  # (M,)
    ex, ey = edge.T
    denom = _cross(dx, dy, ex, ey)  # (N, M); origin + t·d = start + u·e
    parallel = np.abs(denom) < 1e-12
    denom = np.where(parallel, 1.0, denom)
    along_ray = _cross(wx, wy, ex, ey) / denom
    along_segment = _cross(wx, wy, dx, dy) / denom
    hit = ~parallel & (along_ray >= 0) & (along_segment >= 0) & (along_segment <= 1)
    return np.minimum(np.where(hit, along_ray, np.inf).min(axis=1), range_m)


class Lidar(Sensor):
    """``beams`` distances around the ego, divided by ``range_m`` (1 = nothing within range).

    Beam ``i`` points ``2π·i/beams`` clockwise from the heading (towards the ego's right):
    beam 0 straight ahead, beam ``beams/4`` to the right, ``beams/2`` behind, ``3·beams/4`` left.

    :param beams: number of beams (seed 003: 240).
    :param range_m: maximum range.
    :param noise_std: std of Gaussian noise added to the normalised distances (then clipped).
    """

    name = "lidar"

    def __init__(self, *, beams: int = 240, range_m: float = 50.0, noise_std: float = 0.0) -> None:
        if beams < 1 or range_m <= 0 or noise_std < 0:
            raise ValueError("lidar needs beams >= 1, range_m > 0 and noise_std >= 0")
        self.beams, self.range_m, self.noise_std = int(beams), float(range_m), float(noise_std)
        self.offsets = 2 * np.pi * np.arange(self.beams) / self.beams
        self._space = spaces.Box(0.0, 1.0, shape=(self.beams,), dtype=np.float32)
        self.rng = np.random.default_rng(0)

    @property
    def space(self) -> spaces.Box:
        return self._space

    def distances_m(self, world: WorldState) -> np.ndarray:
        """Noise-free distances in metres."""
        vehicles = world.vehicles
        parts = [world.road.edges]
        if len(vehicles):
            boxes = vehicles[:, [0, 1, 2, 4, 5]]
            corners = box_corners(boxes)
            parts.append(np.stack([corners, np.roll(corners, -1, axis=1)], axis=2).reshape(-1, 2, 2))
        segments = np.concatenate(parts) if len(parts) > 1 else parts[0]
        return cast_rays(world.ego.position, world.ego.heading + self.offsets, segments, self.range_m)

    def observe(self, world: WorldState) -> np.ndarray:
        normalised = self.distances_m(world) / self.range_m
        if self.noise_std > 0:
            normalised = normalised + self.rng.normal(0.0, self.noise_std, size=self.beams)
        return np.clip(normalised, 0.0, 1.0).astype(np.float32)
