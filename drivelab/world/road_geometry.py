"""Road geometry shared by the camera sensors and the CARLA study's reward terms (the bottom layer):
where painted lines and routes cross the ground rows ahead of the ego that the line/lane camera
sees. Segments are ``(M, 2, 2)`` arrays of (start, end) points in world metres; over K worlds
``(K, M, 2, 2)``, padded with NaN segments (which never cross anything).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from drivelab.world.batch import WorldBatch
from drivelab.world.pinhole import visible_columns_into
from drivelab.world.state import RoadMap


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


_GUIDE_SETS = "guide segment sets"


def guide_segment_sets(batch: WorldBatch) -> np.ndarray:
    """The guide-line segments of each of the batch's distinct roads (R, M, 2, 2), padded with NaN
    segments; world k's are ``[batch.road_index[k]]``. One road: its own array, not copied."""
    return guide_segment_sets_of(batch.roads)


def guide_segment_sets_of(roads: tuple[RoadMap, ...]) -> np.ndarray:
    """:func:`guide_segment_sets` of the road maps ``roads`` (a batch's ``roads``)."""
    if len(roads) == 1:
        return guide_segments(roads[0])[None]
    # kept on the first map, with the maps it was made from (held, so their ids stay theirs)
    made = roads[0].derived_cache.get(_GUIDE_SETS)
    if made is not None and made[0] is roads:  # the same tuple as the last batch's (the usual case)
        return made[1]
    if (
        made is None
        or len(made[0]) != len(roads)
        or any(a is not b for a, b in zip(made[0], roads, strict=True))
    ):
        per_road = [guide_segments(road) for road in roads]
        padded = np.full((len(per_road), max(len(segments) for segments in per_road), 2, 2), np.nan)
        for index, segments in enumerate(per_road):  # one per distinct map, not per world
            padded[index, : len(segments)] = segments
        made = roads[0].derived_cache[_GUIDE_SETS] = (tuple(roads), padded)
    return made[1]


# a segment whose x range ends this far short of the nearest ground line (or starts beyond the
# farthest) crosses none: its t = (d - x0) / span is outside [0, 1] whatever the rounding, for
# coordinates well under 1e9 m (an ulp of them stays far below the margin)
_CROSSING_MARGIN_M = 1e-3


@njit(cache=True)
def _nearest_crossings(starts, ends, index, position, cos_h, sin_h, distances, out) -> None:
    """World k's segments, from ``starts[index[k]]`` to ``ends[index[k]]`` (M, 2), in its ego
    frame (x forward, y to the right), and for each ground line ``x = d`` the y of the crossing
    nearest the ego's axis (the first such segment on ties; nan where none crosses) into ``out``
    (K, D). The arithmetic is :func:`~drivelab.world.geometry.ego_frame`'s, operation for operation."""
    best_abs = np.empty(distances.shape[0])
    near, far = np.inf, -np.inf
    for j in range(distances.shape[0]):
        near, far = min(near, distances[j]), max(far, distances[j])
    near, far = near - _CROSSING_MARGIN_M, far + _CROSSING_MARGIN_M
    for k in range(index.shape[0]):
        first, last = starts[index[k]], ends[index[k]]
        c, s = cos_h[k], sin_h[k]
        out[k, :] = np.nan
        best_abs[:] = np.inf
        for m in range(first.shape[0]):
            dx0, dy0 = first[m, 0] - position[k, 0], first[m, 1] - position[k, 1]
            dx1, dy1 = last[m, 0] - position[k, 0], last[m, 1] - position[k, 1]
            x0, y0 = dx0 * c + dy0 * s, -dx0 * s + dy0 * c
            x1, y1 = dx1 * c + dy1 * s, -dx1 * s + dy1 * c
            span = x1 - x0
            # (a nan segment, padding, crosses nothing whether or not it is skipped here)
            if np.abs(span) < 1e-12 or max(x0, x1) < near or min(x0, x1) > far:
                continue
            for j in range(distances.shape[0]):
                t = (distances[j] - x0) / span
                if t >= 0 and t <= 1:  # false for NaN (padding segments)
                    y = y0 + t * (y1 - y0)
                    if np.abs(y) < best_abs[j]:
                        best_abs[j], out[k, j] = np.abs(y), y


@njit(cache=True)
def segment_columns_into(starts, ends, index, position, cos_h, sin_h, distances, camera_terms, out) -> None:
    """Image columns (K, D) into ``out`` where world k's segments (``starts[index[k]]`` to
    ``ends[index[k]]``) cross the ground rows ``distances`` (D,) ahead of its ego, nan where none
    crosses or the crossing is out of view: :func:`_nearest_crossings` then
    :func:`~drivelab.world.pinhole.visible_columns_into` (a camera's ``ground_terms``), in one
    compiled call (the CARLA study reward terms' hot path)."""
    lateral = np.empty(out.shape)
    _nearest_crossings(starts, ends, index, position, cos_h, sin_h, distances, lateral)
    visible_columns_into(distances, lateral, camera_terms, out)
