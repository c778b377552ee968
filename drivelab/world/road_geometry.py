"""Road geometry shared by the camera sensors and seed 004's reward terms (the bottom layer).

Segments are ``(M, 2, 2)`` arrays of (start, end) points in world metres; over K worlds they are
``(K, M, 2, 2)``, padded with NaN segments (which never cross anything). Where a painted line or
a route's centre crosses the ground ``distances_m`` ahead of the ego is what the line/lane rows of
the seed 004 camera see.
"""

from __future__ import annotations

import numpy as np

from drivelab.world.batch import WorldBatch
from drivelab.world.geometry import ego_frame
from drivelab.world.state import RoadMap, WorldState


def ego_ground(world: WorldState, points_world: np.ndarray) -> np.ndarray:
    """World points (..., 2) → the ego frame of ``world`` (x forward, y to the right)."""
    return ego_frame(points_world, world.ego.position, world.ego.heading)


def polyline_segments(polyline: np.ndarray) -> np.ndarray:
    """A polyline (P, 2) as its P − 1 segments (P − 1, 2, 2); none for fewer than 2 points."""
    return np.stack([polyline[:-1], polyline[1:]], axis=1) if len(polyline) > 1 else np.zeros((0, 2, 2))


class GuideSegments:
    """All guide-line polylines of a road as one segment array ``segments`` (M, 2, 2)."""

    def __init__(self, road: RoadMap) -> None:
        parts = [polyline_segments(np.asarray(line, dtype=float)) for line in road.guide_lines]
        self.segments = np.concatenate(parts) if parts else np.zeros((0, 2, 2))


def guide_segments(road: RoadMap) -> np.ndarray:
    """The guide-line segments (M, 2, 2) of ``road``, built once and kept on the map."""
    return road.derived(GuideSegments, GuideSegments).segments


def batch_guide_segments(batch: WorldBatch) -> np.ndarray:
    """Each world's guide-line segments (K, M, 2, 2): its road's, padded with NaN segments."""
    per_road = [guide_segments(road) for road in batch.roads]
    size = max(len(segments) for segments in per_road)
    padded = np.full((len(per_road), size, 2, 2), np.nan)
    for index, segments in enumerate(per_road):  # one per distinct map, not per world
        padded[index, : len(segments)] = segments
    return padded[batch.road_index]


def batch_route_segments(batch: WorldBatch) -> np.ndarray:
    """Each world's route polyline as segments (K, R − 1, 2, 2); the padding of a shorter route
    repeats its last point, giving zero-length segments that cross nothing."""
    polyline = batch.route.polyline
    return np.stack([polyline[:, :-1], polyline[:, 1:]], axis=2)


def lateral_crossings(
    position: np.ndarray, heading: np.ndarray, segments: np.ndarray, distances_m: np.ndarray
) -> np.ndarray:
    """Where each world's ``segments`` (K, M, 2, 2) cross the ground line ``x = d`` ahead of its ego
    (``position`` (K, 2), ``heading`` (K,)), for ``distances_m`` (D,): the ego-frame y (m) of the
    crossing nearest the ego's axis, (K, D), nan where nothing crosses."""
    distances = np.asarray(distances_m, dtype=float).reshape(-1)
    count = len(heading)
    if segments.shape[1] == 0:
        return np.full((count, len(distances)), np.nan)
    local = ego_frame(segments, position[:, None, None, :], heading[:, None, None])  # (K, M, 2, 2)
    x0, x1 = local[:, None, :, 0, 0], local[:, None, :, 1, 0]  # (K, 1, M)
    y0, y1 = local[:, None, :, 0, 1], local[:, None, :, 1, 1]
    d = distances[None, :, None]  # (1, D, 1)
    span = np.where(np.abs(x1 - x0) < 1e-12, np.nan, x1 - x0)
    with np.errstate(invalid="ignore"):
        t = (d - x0) / span
        y = np.where((t >= 0) & (t <= 1), y0 + t * (y1 - y0), np.nan)  # (K, D, M)
    y = np.where(np.isnan(y), np.inf, y)
    best = np.take_along_axis(y, np.argmin(np.abs(y), axis=2)[..., None], axis=2)[..., 0]
    return np.where(np.isfinite(best), best, np.nan)


def batch_lateral_at_distances(
    batch: WorldBatch, segments: np.ndarray, distances_m: np.ndarray
) -> np.ndarray:
    """:func:`lateral_crossings` for the egos of ``batch``: (K, D) from segments (K, M, 2, 2)."""
    return lateral_crossings(batch.ego.position, batch.ego.heading, segments, distances_m)


def lateral_at_distances(world: WorldState, segments: np.ndarray, distances_m: np.ndarray) -> np.ndarray:
    """Where world ``segments`` (M, 2, 2) cross the ground line ``x = d`` ahead of the ego: the ego-frame
    y (m) of the crossing nearest the ego's axis, per distance (nan where nothing crosses)."""
    distances = np.asarray(distances_m, dtype=float)
    segments = np.asarray(segments, dtype=float).reshape(1, -1, 2, 2)
    position = np.asarray(world.ego.position, dtype=float).reshape(1, 2)
    heading = np.array([world.ego.heading], dtype=float)
    return lateral_crossings(position, heading, segments, distances.reshape(-1))[0].reshape(distances.shape)
