"""LiDAR: beams around the ego that stop at other vehicles and at road edges (seed 003)."""

from __future__ import annotations

import numpy as np
from gymnasium import spaces

from drivelab.perception.base import Sensor, box_corners, ego_frame
from drivelab.world.state import WorldState


def _near_parts(segments: np.ndarray, range_m: float) -> np.ndarray:
    """The parts (K, 2, 2) of segments (M, 2, 2), given relative to the ray origin, within ``range_m``.

    A segment is kept by the distance of its nearest point, not its end points (a 10 km road
    edge passes by the ego far from both ends), and cut down to the stretch inside the range
    circle, so what follows works on short, origin-relative segments (float32 is then exact
    to micrometres).
    """
    start = segments[:, 0]
    edge = segments[:, 1] - start
    length2 = np.einsum("ij,ij->i", edge, edge)
    safe_length2 = np.maximum(length2, 1e-12)
    nearest_at = np.clip(-np.einsum("ij,ij->i", start, edge) / safe_length2, 0.0, 1.0)
    nearest = start + nearest_at[:, None] * edge
    distance2 = np.einsum("ij,ij->i", nearest, nearest)
    near = distance2 <= range_m * range_m
    if not near.all():
        start, edge, nearest_at = start[near], edge[near], nearest_at[near]
        distance2, safe_length2 = distance2[near], safe_length2[near]
    # half the chord the range circle cuts on the segment's line, in units of the segment
    half_chord = np.sqrt((range_m * range_m - distance2) / safe_length2)
    low = np.clip(nearest_at - half_chord, 0.0, 1.0)
    high = np.clip(nearest_at + half_chord, 0.0, 1.0)
    return np.stack([start + low[:, None] * edge, start + high[:, None] * edge], axis=1)


class RayCaster:
    """A fixed fan of rays from the origin, cast against origin-relative segments.

    All rays × all segments at once in float32, in scratch arrays kept between calls: allocating
    fresh (rays × segments) arrays every step costs more than the arithmetic (page faults).

    :param directions: (N, 2) unit ray directions.
    """

    def __init__(self, directions: np.ndarray) -> None:
        self.directions = np.ascontiguousarray(directions, dtype=np.float32)
        self._capacity = 0

    def _scratch(self, segments: int) -> tuple[np.ndarray, ...]:
        if segments > self._capacity:
            self._capacity = max(segments, 2 * self._capacity, 64)
            size = len(self.directions) * self._capacity
            self._columns = np.empty(4 * self._capacity, dtype=np.float32)
            self._products = np.empty(2 * size, dtype=np.float32)
            self._along_ray = np.empty(size, dtype=np.float32)
            self._hit, self._test = np.empty(size, dtype=bool), np.empty(size, dtype=bool)
        rays = len(self.directions)
        return (
            self._columns[: 4 * segments].reshape(2, 2 * segments),
            self._products[: 2 * rays * segments].reshape(rays, 2 * segments),
            self._along_ray[: rays * segments].reshape(rays, segments),
            self._hit[: rays * segments].reshape(rays, segments),
            self._test[: rays * segments].reshape(rays, segments),
        )

    def __call__(self, segments: np.ndarray, range_m: float) -> np.ndarray:
        """Distance along each ray to the first segment it meets, ``range_m`` when none is nearer.

        :param segments: (M, 2, 2) segments relative to the rays' origin, float64.
        :return: (N,) float64 distances.
        """
        distances = np.full(len(self.directions), float(range_m))
        parts = _near_parts(segments, range_m) if len(segments) else segments
        count = len(parts)
        if count == 0:
            return distances
        columns, products, along_ray, hit, test = self._scratch(count)
        start, edge = parts[:, 0], parts[:, 1] - parts[:, 0]
        # ray t·d meets segment s + u·e where t = (s × e) / (d × e) and u = (s × d) / (d × e);
        # both d × e and s × d = d × (−s) are dot products of d with one matrix product
        columns[0, :count], columns[1, :count] = edge[:, 1], -edge[:, 0]
        columns[0, count:], columns[1, count:] = -start[:, 1], start[:, 0]
        np.matmul(self.directions, columns, out=products)
        d_cross_e, along_segment = products[:, :count], products[:, count:]
        s_cross_e = (start[:, 0] * edge[:, 1] - start[:, 1] * edge[:, 0]).astype(np.float32)
        # parallel pairs divide by zero and give inf or nan, which the tests below reject
        with np.errstate(divide="ignore", invalid="ignore"):
            np.divide(s_cross_e, d_cross_e, out=along_ray)
            np.divide(along_segment, d_cross_e, out=along_segment)
        np.greater_equal(along_ray, 0.0, out=hit)
        hit &= np.greater_equal(along_segment, 0.0, out=test)
        hit &= np.less_equal(along_segment, 1.0, out=test)
        np.copyto(along_ray, np.float32(np.inf), where=np.logical_not(hit, out=test))
        return np.minimum(along_ray.min(axis=1), range_m, out=distances)


def cast_rays(origin: np.ndarray, angles: np.ndarray, segments: np.ndarray, range_m: float) -> np.ndarray:
    """Distance along each ray to the first segment it meets, ``range_m`` when none is nearer.

    All rays × all segments in one go (float32 inside, accurate to about 1e-5 m); segments out
    of range are dropped first. ``Lidar`` uses the same ``RayCaster``.

    :param origin: (2,) ray origin, world metres.
    :param angles: (N,) world-frame ray directions, radians (from +x towards +y).
    :param segments: (M, 2, 2) segments as pairs of end points.
    :param range_m: the farthest distance reported.
    :return: (N,) float64 distances in metres.
    """
    angles = np.asarray(angles, dtype=float)
    relative = np.asarray(segments, dtype=float).reshape(-1, 2, 2) - np.asarray(origin, dtype=float)
    return RayCaster(np.stack([np.cos(angles), np.sin(angles)], axis=-1))(relative, range_m)


class Lidar(Sensor):
    """``beams`` distances around the ego, divided by ``range_m`` (1 = nothing within range).

    Beam ``i`` points ``2π·i/beams`` clockwise from the heading (towards the ego's right):
    beam 0 straight ahead, beam ``beams/4`` to the right, ``beams/2`` behind, ``3·beams/4`` left.
    Beams stop at the outlines of other vehicles and at the road edges (``world.road.edges``).

    :param beams: number of beams (seed 003: 240).
    :param range_m: maximum range.
    :param noise_std: std of Gaussian noise added to the normalised distances (then clipped to
        [0, 1]), drawn from the generator handed to ``reset``.
    """

    name = "lidar"

    def __init__(self, *, beams: int = 240, range_m: float = 50.0, noise_std: float = 0.0) -> None:
        if beams < 1 or range_m <= 0 or noise_std < 0:
            raise ValueError("lidar needs beams >= 1, range_m > 0 and noise_std >= 0")
        self.beams, self.range_m, self.noise_std = int(beams), float(range_m), float(noise_std)
        offsets = 2 * np.pi * np.arange(self.beams) / self.beams
        # beams in the ego frame (x forward, y right): the world is turned into it instead
        self.caster = RayCaster(np.stack([np.cos(offsets), np.sin(offsets)], axis=-1))
        self._space = spaces.Box(0.0, 1.0, shape=(self.beams,), dtype=np.float32)
        self.rng = np.random.default_rng(0)  # replaced by the episode's generator in ``reset``

    @property
    def space(self) -> spaces.Box:
        return self._space

    def segments(self, world: WorldState) -> np.ndarray:
        """Everything the beams can hit, as (M, 2, 2) segments in the ego frame."""
        ego = world.ego
        edges = ego_frame(world.road.edges, ego.position, ego.heading)
        vehicles = world.road_users()  # pedestrians reflect beams too
        if len(vehicles) == 0:
            return edges
        # boxes in the ego frame (centre turned, heading made relative), so corners come out there
        boxes = vehicles[:, [0, 1, 2, 4, 5]]
        boxes[:, :2] = ego_frame(boxes[:, :2], ego.position, ego.heading)
        boxes[:, 2] -= ego.heading
        # a vehicle whose centre is farther than range + half its diagonal cannot be hit
        reach = self.range_m + 0.5 * np.hypot(boxes[:, 3], boxes[:, 4])
        boxes = boxes[np.einsum("ij,ij->i", boxes[:, :2], boxes[:, :2]) <= reach * reach]
        if len(boxes) == 0:
            return edges
        corners = box_corners(boxes)
        following = np.roll(corners, -1, axis=1)
        # Only sides facing the ego can be hit first (back-face culling halves the work). Corners
        # run around the box so that the ego is outside a side when start × following < 0; an
        # ego inside a box (a crash) faces none of them and keeps all four.
        facing = corners[..., 0] * following[..., 1] - corners[..., 1] * following[..., 0] < 0
        facing |= ~facing.any(axis=1, keepdims=True)
        sides = np.stack([corners[facing], following[facing]], axis=1)
        return np.concatenate([edges, sides]) if len(edges) else sides

    def distances_m(self, world: WorldState) -> np.ndarray:
        """Noise-free distances in metres, (beams,)."""
        return self.caster(self.segments(world), self.range_m)

    def observe(self, world: WorldState) -> np.ndarray:
        normalised = self.distances_m(world) / self.range_m
        if self.noise_std > 0:
            normalised += self.rng.normal(0.0, self.noise_std, size=self.beams)
        return np.clip(normalised, 0.0, 1.0).astype(np.float32)
