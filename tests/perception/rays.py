"""The brute-force ray caster the LiDAR is tested against: every ray against every segment, in
numpy, with the arithmetic ``Lidar``'s compiled pass does on the pairs that can hit."""

from __future__ import annotations

import numpy as np


def _near_parts(
    start_x: np.ndarray, start_y: np.ndarray, end_x: np.ndarray, end_y: np.ndarray, range_m: float
) -> tuple[np.ndarray, ...]:
    """The parts within ``range_m`` of segments (M,) given relative to the ray origin: their
    start x, start y, end x, end y (T,), the (M,) mask of the segments kept, and each part's
    (T,) distance to the origin. A segment is kept by the distance of its nearest point and cut
    to the stretch inside the range circle, so that float32 is then exact to micrometres.
    """
    edge_x, edge_y = end_x - start_x, end_y - start_y
    safe_length2 = np.maximum(edge_x * edge_x + edge_y * edge_y, 1e-12)
    nearest_at = np.clip(-(start_x * edge_x + start_y * edge_y) / safe_length2, 0.0, 1.0)
    nearest_x, nearest_y = start_x + nearest_at * edge_x, start_y + nearest_at * edge_y
    distance2 = nearest_x * nearest_x + nearest_y * nearest_y
    near = distance2 <= range_m * range_m
    start_x, start_y, edge_x, edge_y = start_x[near], start_y[near], edge_x[near], edge_y[near]
    nearest_at, distance2, safe_length2 = nearest_at[near], distance2[near], safe_length2[near]
    # half the chord the range circle cuts on the segment's line, in units of the segment
    half_chord = np.sqrt((range_m * range_m - distance2) / safe_length2)
    low = np.clip(nearest_at - half_chord, 0.0, 1.0)
    high = np.clip(nearest_at + half_chord, 0.0, 1.0)
    return (
        start_x + low * edge_x,
        start_y + low * edge_y,
        start_x + high * edge_x,
        start_y + high * edge_y,
        near,
        np.sqrt(distance2),
    )


def _part_terms(start_x, start_y, end_x, end_y) -> tuple[np.ndarray, ...]:
    """Per origin-relative part (T,): float32 start x, start y, edge x, edge y and start × edge."""
    edge_x, edge_y = end_x - start_x, end_y - start_y
    cross = start_x * edge_y - start_y * edge_x
    return tuple(a.astype(np.float32) for a in (start_x, start_y, edge_x, edge_y, cross))


def _hit_distances(direction_x, direction_y, start_x, start_y, edge_x, edge_y, s_cross_e) -> np.ndarray:
    """Per (ray, part) pair (P,), the distance along the ray to the part: float32, ``inf`` on a miss.
    Ray t·d meets segment s + u·e at t = (s × e) / (d × e), u = (s × d) / (d × e); a hit needs
    t ≥ 0 and 0 ≤ u ≤ 1.
    """
    d_cross_e = direction_x * edge_y - direction_y * edge_x
    # parallel pairs divide by zero and give inf or nan, which the tests below reject
    with np.errstate(divide="ignore", invalid="ignore"):
        along_ray = s_cross_e / d_cross_e
        along_segment = (direction_y * start_x - direction_x * start_y) / d_cross_e
    hit = (along_ray >= 0.0) & (along_segment >= 0.0) & (along_segment <= 1.0)
    return np.where(hit, along_ray, np.float32(np.inf))


def cast_rays(origin: np.ndarray, angles: np.ndarray, segments: np.ndarray, range_m: float) -> np.ndarray:
    """Distance along each ray to the first segment it meets, ``range_m`` when none is nearer:
    every ray × every segment (``Lidar`` does the same arithmetic on the pairs that can hit).

    :param origin: (2,) ray origin, world metres.
    :param angles: (N,) world-frame ray directions, radians (from +x towards +y).
    :param segments: (M, 2, 2) segments as pairs of end points.
    :param range_m: the farthest distance reported.
    :return: (N,) float64 distances in metres.
    """
    angles = np.asarray(angles, dtype=float).reshape(-1)
    relative = np.asarray(segments, dtype=float).reshape(-1, 4) - np.tile(np.asarray(origin, dtype=float), 2)
    *parts, _, _ = _near_parts(*relative.T, float(range_m))
    rays, count = len(angles), len(parts[0])
    if count == 0:
        return np.full(rays, float(range_m))
    direction_x = np.repeat(np.cos(angles).astype(np.float32), count)
    direction_y = np.repeat(np.sin(angles).astype(np.float32), count)
    terms = [np.tile(term, rays) for term in _part_terms(*parts)]
    along_ray = _hit_distances(direction_x, direction_y, *terms).reshape(rays, count)
    return np.minimum(along_ray.min(axis=1).astype(float), float(range_m))
