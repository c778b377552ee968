"""Where lines cross the ground ahead of K egos, as arrays of lateral offsets: numpy wrappers of
``drivelab.world.road_geometry``'s compiled search (``_nearest_crossings``, which the package
calls through ``segment_columns_into``), for the road-geometry and camera tests."""

from __future__ import annotations

import numpy as np

from drivelab.world.batch import WorldBatch
from drivelab.world.road_geometry import _nearest_crossings, guide_segment_sets
from drivelab.world.state import WorldState


def batch_guide_segments(batch: WorldBatch) -> np.ndarray:
    """Each world's guide-line segments (K, M, 2, 2): its road's, padded with NaN segments."""
    return guide_segment_sets(batch)[batch.road_index]


def batch_route_segments(batch: WorldBatch) -> np.ndarray:
    """Each world's route polyline as segments (K, R − 1, 2, 2); the padding of a shorter route
    repeats its last point, giving zero-length segments that cross nothing."""
    polyline = batch.route.polyline
    return np.stack([polyline[:, :-1], polyline[:, 1:]], axis=2)


def lateral_crossings(
    position: np.ndarray,
    heading: np.ndarray,
    segments: np.ndarray,
    distances_m: np.ndarray,
    index: np.ndarray | None = None,
) -> np.ndarray:
    """Where each world's segments cross the ground line ``x = d`` ahead of its ego (``position``
    (K, 2), ``heading`` (K,)), for ``distances_m`` (D,): the ego-frame y (m) of the crossing
    nearest the ego's axis, (K, D), nan where nothing crosses.

    ``segments`` is (K, M, 2, 2), one set per world, or with ``index`` (K,) a few sets (S, M, 2, 2)
    of which world k uses ``segments[index[k]]`` (the distinct maps' guide lines).
    """
    segments = np.asarray(segments, dtype=float)
    return _crossings(position, heading, segments[:, :, 0], segments[:, :, 1], distances_m, index)


def polyline_crossings(
    position: np.ndarray, heading: np.ndarray, polylines: np.ndarray, distances_m: np.ndarray
) -> np.ndarray:
    """:func:`lateral_crossings` of each world's polyline (K, P, 2) taken as its P − 1 segments
    (views of the points, not a segment array)."""
    polylines = np.asarray(polylines, dtype=float)
    return _crossings(position, heading, polylines[:, :-1], polylines[:, 1:], distances_m, None)


def _crossings(position, heading, starts, ends, distances_m, index) -> np.ndarray:
    distances = np.ascontiguousarray(distances_m, dtype=float).reshape(-1)
    heading = np.asarray(heading, dtype=float)
    out = np.empty((len(heading), len(distances)))
    index = np.asarray(np.arange(len(heading)) if index is None else index, dtype=np.int64)
    position, cos_h, sin_h = np.asarray(position, dtype=float), np.cos(heading), np.sin(heading)
    _nearest_crossings(starts, ends, index, position, cos_h, sin_h, distances, out)
    return out


def batch_lateral_at_distances(
    batch: WorldBatch, segments: np.ndarray, distances_m: np.ndarray, index: np.ndarray | None = None
) -> np.ndarray:
    """:func:`lateral_crossings` for the egos of ``batch``: (K, D) from segments (K, M, 2, 2), or
    from sets (S, M, 2, 2) chosen per world by ``index`` (K,)."""
    return lateral_crossings(batch.ego.position, batch.ego.heading, segments, distances_m, index)


def lateral_at_distances(world: WorldState, segments: np.ndarray, distances_m: np.ndarray) -> np.ndarray:
    """Where world ``segments`` (M, 2, 2) cross the ground line ``x = d`` ahead of the ego: the ego-frame
    y (m) of the crossing nearest the ego's axis, per distance (nan where nothing crosses)."""
    distances = np.asarray(distances_m, dtype=float)
    segments = np.asarray(segments, dtype=float).reshape(1, -1, 2, 2)
    position = np.asarray(world.ego.position, dtype=float).reshape(1, 2)
    heading = np.array([world.ego.heading], dtype=float)
    return lateral_crossings(position, heading, segments, distances.reshape(-1))[0].reshape(distances.shape)
