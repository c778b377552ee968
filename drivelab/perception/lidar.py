"""LiDAR: beams around the ego that stop at other vehicles and at road edges (the MetaDrive study)."""

from __future__ import annotations

import numpy as np
from gymnasium import spaces
from numba import njit

from drivelab.perception.base import Sensor
from drivelab.world.batch import WorldBatch
from drivelab.world.state import WorldState

_CORNER_LENGTH = np.array([1.0, 1.0, -1.0, -1.0])  # corners of a box, as ``box_corners`` orders them
_CORNER_WIDTH = np.array([-1.0, 1.0, 1.0, -1.0])
_NEXT_CORNER = np.array([1, 2, 3, 0])


@njit(cache=True, error_model="numpy")
def _cast_parts(
    start_x, start_y, end_x, end_y, worlds, range_m, beams, step, close_m, direction_x, direction_y, nearest
) -> None:
    """``Lidar.distances_m``'s beams against every segment (M,) of ``_segments``, compiled: per
    segment the part within range (float64), the beams of its angular span with one beam of margin
    either side (every beam for a part very close to the ego), and a float32 hit test (the numpy
    arithmetic of tests/perception/rays.py), keeping the nearest hit of each (world, beam) in
    ``nearest`` (K · beams,) float32. The margin means a beam outside the span cannot pass the hit
    test, so a last-bit difference in the span's arctan2 changes nothing."""
    range2 = range_m * range_m
    for m in range(start_x.shape[0]):
        sx, sy = start_x[m], start_y[m]
        edge_x, edge_y = end_x[m] - sx, end_y[m] - sy
        safe_length2 = max(edge_x * edge_x + edge_y * edge_y, 1e-12)
        nearest_at = min(max(-(sx * edge_x + sy * edge_y) / safe_length2, 0.0), 1.0)
        nearest_x, nearest_y = sx + nearest_at * edge_x, sy + nearest_at * edge_y
        distance2 = nearest_x * nearest_x + nearest_y * nearest_y
        if not distance2 <= range2:
            continue
        half_chord = np.sqrt((range2 - distance2) / safe_length2)
        low = min(max(nearest_at - half_chord, 0.0), 1.0)
        high = min(max(nearest_at + half_chord, 0.0), 1.0)
        part_x, part_y = sx + low * edge_x, sy + low * edge_y
        part_end_x, part_end_y = sx + high * edge_x, sy + high * edge_y
        angle_start = np.arctan2(part_y, part_x)
        turn = np.arctan2(part_end_y, part_end_x) - angle_start
        turn = (turn + np.pi) % (2 * np.pi) - np.pi
        span = int(np.abs(turn) // step) + 4
        first = int(min(angle_start, angle_start + turn) // step) - 1
        if span >= beams or np.sqrt(distance2) < close_m:
            span, first = beams, 0
        part_edge_x, part_edge_y = part_end_x - part_x, part_end_y - part_y
        s_x, s_y = np.float32(part_x), np.float32(part_y)
        e_x, e_y = np.float32(part_edge_x), np.float32(part_edge_y)
        s_cross_e = np.float32(part_x * part_edge_y - part_y * part_edge_x)
        row = worlds[m] * beams
        for offset in range(span):
            beam = (first + offset) % beams
            d_x, d_y = direction_x[beam], direction_y[beam]
            d_cross_e = d_x * e_y - d_y * e_x
            along_ray = s_cross_e / d_cross_e
            along_segment = (d_y * s_x - d_x * s_y) / d_cross_e
            if along_ray >= 0.0 and along_segment >= 0.0 and along_segment <= 1.0:
                if along_ray < nearest[row + beam]:
                    nearest[row + beam] = along_ray


class Lidar(Sensor):
    """``beams`` distances around the ego, divided by ``range_m`` (1 = nothing within range).

    Beam ``i`` points ``2π·i/beams`` clockwise from the heading: beam 0 straight ahead, beam
    ``beams/4`` to the right. Beams stop at other vehicles, pedestrians and the road edges.

    :param beams: number of beams (the MetaDrive study: 240).
    :param range_m: maximum range.
    :param noise_std: std of Gaussian noise added to the normalised distances (then clipped to
        [0, 1]), drawn from world k's generator handed to ``reset``.
    """

    name = "lidar"
    help = "240 beams (configurable) hitting vehicles and road edges, distance / range"

    def __init__(self, *, beams: int = 240, range_m: float = 50.0, noise_std: float = 0.0) -> None:
        if beams < 1 or range_m <= 0 or noise_std < 0:
            raise ValueError("lidar needs beams >= 1, range_m > 0 and noise_std >= 0")
        self.beams, self.range_m, self.noise_std = int(beams), float(range_m), float(noise_std)
        self.uses_rng = self.noise_std > 0
        self.beam_step = 2 * np.pi / self.beams
        offsets = self.beam_step * np.arange(self.beams)
        # beams in the ego frame (x forward, y right): the world is turned into it instead
        self.direction_x = np.cos(offsets).astype(np.float32)
        self.direction_y = np.sin(offsets).astype(np.float32)
        # A part this close to the ego is tested against every beam: nearer, the float32 rounding
        # of the part (~1e-7 · range) could move its ends by more than the one-beam margin below.
        self.close_m = 1e-4 * self.range_m / min(self.beam_step, 1.0)
        self._pairs: tuple | None = None  # (key, _world_edge_pairs) of the last batch on several roads
        self._space = spaces.Box(0.0, 1.0, shape=(self.beams,), dtype=np.float32)

    def _edges_within(self, batch: WorldBatch, reach_m: float) -> tuple[np.ndarray, np.ndarray]:
        """(worlds (W,), edges (W, 2, 2)): every road edge whose bounding box lies within
        ``reach_m`` of its world's ego along x and along y, with that world."""
        position = batch.ego.position
        if len(batch.roads) == 1:
            derived = batch.roads[0].derived(EdgeBoxes, EdgeBoxes)
            centre_x, centre_y, half_x, half_y = derived.boxes  # (E,) each
            near = np.abs(centre_x - position[:, 0, None]) <= half_x + reach_m  # (K, E)
            near &= np.abs(centre_y - position[:, 1, None]) <= half_y + reach_m
            world, edge = np.nonzero(near)
            return world, derived.edges[edge]
        # worlds on many maps (procedural maps: often one world per map): every world's (world,
        # edge) pairs with its own map, made when the maps change, then one pass over all of them
        key = (batch.roads, batch.road_index.tobytes())
        if self._pairs is None or self._pairs[0][0] is not key[0] or self._pairs[0][1] != key[1]:
            self._pairs = (key, _world_edge_pairs(batch))
        world, boxes, edges = self._pairs[1]
        near = np.abs(boxes[0] - position[world, 0]) <= boxes[2] + reach_m
        near &= np.abs(boxes[1] - position[world, 1]) <= boxes[3] + reach_m
        return world[near], edges[near]

    def _segments(self, batch: WorldBatch) -> tuple[np.ndarray, ...]:
        """Everything the beams can hit, as flat (M,) arrays: start x, start y, end x, end y in
        the ego frame of the world each segment belongs to, and that world."""
        ego = batch.ego
        cos_h, sin_h = np.cos(ego.heading)[:, None], np.sin(ego.heading)[:, None]  # (K, 1)
        position_x, position_y = ego.position[:, 0, None], ego.position[:, 1, None]
        # road edges whose bounding box comes within range, as (world, edge) pairs (W,) in ego frames
        edge_world, chosen = self._edges_within(batch, self.range_m + 1.0)  # a metre over rounding
        delta_x = chosen[..., 0] - position_x[edge_world]
        delta_y = chosen[..., 1] - position_y[edge_world]
        edge_x = delta_x * cos_h[edge_world] + delta_y * sin_h[edge_world]  # (W, 2)
        edge_y = -delta_x * sin_h[edge_world] + delta_y * cos_h[edge_world]
        # other bodies (pedestrians reflect beams too): their centres in the ego frame
        users, valid = batch.road_users()  # (K, U, 6)
        delta_x, delta_y = users[..., 0] - position_x, users[..., 1] - position_y
        box_x = delta_x * cos_h + delta_y * sin_h  # (K, U)
        box_y = -delta_x * sin_h + delta_y * cos_h
        # a body whose centre is farther than range + half its diagonal cannot be hit
        reach = self.range_m + 0.5 * np.hypot(users[..., 4], users[..., 5])
        kept = valid & (box_x * box_x + box_y * box_y <= reach * reach)
        # the bodies within reach (V,) as boxes in the ego frame, so that their corners come out there
        body_world = np.nonzero(kept)[0]
        box_x, box_y, bodies = box_x[kept][:, None], box_y[kept][:, None], users[kept]
        turn = bodies[:, 2] - ego.heading[body_world]
        cos_b, sin_b = np.cos(turn)[:, None], np.sin(turn)[:, None]
        half_l = _CORNER_LENGTH * (bodies[:, 4, None] / 2)  # (V, 4), as box_corners
        half_w = _CORNER_WIDTH * (bodies[:, 5, None] / 2)
        corner_x = box_x + half_l * cos_b - half_w * sin_b
        corner_y = box_y + half_l * sin_b + half_w * cos_b
        next_x, next_y = corner_x[:, _NEXT_CORNER], corner_y[:, _NEXT_CORNER]
        # only sides facing the ego (start × following < 0) can be hit first; an ego inside a box
        # (a crash) faces none of them and keeps all four
        facing = corner_x * next_y - corner_y * next_x < 0  # (V, 4)
        facing |= ~facing.any(axis=1, keepdims=True)
        return (
            np.concatenate([edge_x[:, 0], corner_x[facing]]),
            np.concatenate([edge_y[:, 0], corner_y[facing]]),
            np.concatenate([edge_x[:, 1], next_x[facing]]),
            np.concatenate([edge_y[:, 1], next_y[facing]]),
            np.concatenate([edge_world, body_world[np.nonzero(facing)[0]]]),
        )

    def distances_m(self, batch: WorldBatch | WorldState) -> np.ndarray:
        """Noise-free distances in metres, (K, beams); (beams,) for a WorldState."""
        if isinstance(batch, WorldState):
            return self.distances_m(WorldBatch.stack([batch]))[0]
        beams, step = self.beams, self.beam_step
        *segments, worlds = self._segments(batch)
        nearest = np.full(batch.num_worlds * beams, np.inf, dtype=np.float32)
        directions = (self.direction_x, self.direction_y)
        _cast_parts(*segments, worlds, self.range_m, beams, step, self.close_m, *directions, nearest)
        return np.minimum(nearest.reshape(batch.num_worlds, beams).astype(float), self.range_m)

    def _observe(self, batch: WorldBatch, out: np.ndarray) -> None:
        normalised = self.distances_m(batch) / self.range_m
        if self.noise_std > 0:
            # each world draws from its own episode generator: one call per world
            for k in range(batch.num_worlds):
                normalised[k] += self.rngs[k].normal(0.0, self.noise_std, size=self.beams)
        out[...] = np.clip(normalised, 0.0, 1.0)


class EdgeBoxes:
    """A road's edges (E, 2, 2) and their bounding boxes as (4, E): centre x, centre y, half
    width, half height."""

    def __init__(self, road) -> None:
        self.edges = edges = np.asarray(road.edges, dtype=float).reshape(-1, 2, 2)
        low, high = edges.min(axis=1), edges.max(axis=1)  # (E, 2)
        self.boxes = np.concatenate([(low + high) / 2, (high - low) / 2], axis=1).T.copy()


def _world_edge_pairs(batch: WorldBatch) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Every (world, edge of its road) pair of a batch on several roads: the worlds (P,), the
    edges' boxes (4, P) as EdgeBoxes and the edges (P, 2, 2), world by world."""
    worlds, boxes, edges = [], [], []
    for k in range(batch.num_worlds):
        derived = batch.roads[int(batch.road_index[k])].derived(EdgeBoxes, EdgeBoxes)
        worlds.append(np.full(derived.boxes.shape[1], k))
        boxes.append(derived.boxes)
        edges.append(derived.edges)
    return np.concatenate(worlds), np.concatenate(boxes, axis=1), np.concatenate(edges)
