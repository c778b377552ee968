"""Top-down semantic image: the 5 channels of the MetaDrive study, ego-centred and heading-aligned.

Pixel convention (shared with ``birdeye``): the ego sits at the image centre, heading up. A point
``x`` m ahead of the ego and ``y`` m to its right lies at ``column = W/2 + y·ppm``, ``row = H/2 −
x·ppm`` in continuous image coordinates; ``to_pixels`` returns OpenCV's (integers at pixel
centres: those values minus 0.5), so the view is exactly symmetric.
"""

from __future__ import annotations

from collections.abc import Iterable

import cv2
import numpy as np
from gymnasium import spaces

from drivelab.perception.base import Sensor, box_corners, ego_frame
from drivelab.world.batch import WorldBatch, pad_slots
from drivelab.world.state import RoadMap

SHIFT = 4  # OpenCV sub-pixel bits: coordinates are drawn to 1/16 pixel
SCALE = 1 << SHIFT
ROUTE_WIDTH_M = 2.0  # the route is drawn as a band this wide (about half a lane)
# OpenCV fills every pixel whose centre lies within about half a pixel of a shape's outline (it
# rounds the vertices, then fills inclusively); rectangles drawn half a pixel smaller on every
# side cover exactly the pixels whose centres they contain, so a 2 m wide car is 4 px at 2 px/m.
EXACT_INSET_PX = 0.5
PAST_DOT_M = 1.0  # a past ego position is an image-aligned square dot this wide
CHANNELS = ("road", "route", "past_ego", "traffic", "traffic_previous")
STOP_BAR_M = (1.0, 4.0)  # a traffic light is drawn as a bar across its lane at the stop line
LIGHT_LEVELS = np.array([85, 170, 255])  # green, yellow, red in the optional lights channel


def stop_bars(lights: np.ndarray) -> np.ndarray:
    """Rectangles (..., 5) ``x, y, heading, length, width`` of the stop bars of lights (..., 4)."""
    lights = np.asarray(lights, dtype=float)
    return np.concatenate([lights[..., :3], np.broadcast_to(STOP_BAR_M, (*lights.shape[:-1], 2))], axis=-1)


def to_pixels(
    points_world: np.ndarray,
    ego_position: np.ndarray,
    ego_heading: float,
    size_hw: tuple[int, int],
    pixels_per_meter: float,
) -> np.ndarray:
    """World points (..., 2) → float image coordinates (..., 2) as (column, row): ``column = W/2 −
    0.5 + y·ppm``, ``row = H/2 − 0.5 − x·ppm`` for a point ``x`` m ahead and ``y`` m right of the ego.
    """
    local = ego_frame(points_world, ego_position, ego_heading)
    height, width = size_hw
    column = (width / 2 - 0.5) + local[..., 1] * pixels_per_meter
    row = (height / 2 - 0.5) - local[..., 0] * pixels_per_meter
    return np.stack([column, row], axis=-1)


def fixed_point(pixels: np.ndarray) -> np.ndarray:
    """Float pixel coordinates → the int32 fixed-point form OpenCV draws with ``shift=SHIFT``."""
    return np.round(pixels * SCALE).astype(np.int32)


def segments_near(segments: np.ndarray, centre: np.ndarray, radius: float) -> np.ndarray:
    """Mask (M,) of the segments (M, 2, 2) whose nearest point comes within ``radius`` of
    ``centre`` (2,), or mask (W, M) for W centres (W, 2)."""
    centre = np.asarray(centre, dtype=float)
    start = segments[:, 0] - centre[..., None, :]  # (..., M, 2)
    edge = segments[:, 1] - segments[:, 0]
    length2 = np.maximum(np.einsum("ij,ij->i", edge, edge), 1e-12)
    along = np.clip(-np.einsum("...ij,ij->...i", start, edge) / length2, 0.0, 1.0)
    nearest = start + along[..., None] * edge
    return np.einsum("...ij,...ij->...i", nearest, nearest) <= radius * radius


class LanePolygons:
    """All lane outlines of a road as one vertex array, with a bounding circle per lane."""

    def __init__(self, road: RoadMap) -> None:
        self._index([np.asarray(p, dtype=float).reshape(-1, 2) for p in road.lane_polygons])

    def _index(self, polygons: list[np.ndarray]) -> None:
        self.counts = np.array([len(p) for p in polygons], dtype=int)
        self.vertices = np.concatenate(polygons) if polygons else np.zeros((0, 2))
        self.owner = np.repeat(np.arange(len(polygons)), self.counts)
        low = np.array([p.min(axis=0) for p in polygons]).reshape(-1, 2)
        high = np.array([p.max(axis=0) for p in polygons]).reshape(-1, 2)
        self.centres = (low + high) / 2
        self.radii = np.hypot(*(high - low).T) / 2


def _clip_half_plane(
    points: np.ndarray, counts: np.ndarray, row: float, keep_below: bool
) -> tuple[np.ndarray, np.ndarray]:
    """One Sutherland–Hodgman pass over many polygons at once: keep the side of the line ``row``.

    :param points: (P, 2) pixel vertices (column, row) of the polygons, one after another.
    :param counts: (L,) vertices per polygon.
    """
    owner = np.repeat(np.arange(len(counts)), counts)
    following = np.arange(1, len(points) + 1)
    following[np.cumsum(counts)[counts > 0] - 1] = (np.cumsum(counts) - counts)[counts > 0]
    start, end = points, points[following]
    start_in = (start[:, 1] <= row) if keep_below else (start[:, 1] >= row)
    end_in = (end[:, 1] <= row) if keep_below else (end[:, 1] >= row)
    crosses = start_in != end_in
    rise = np.where(crosses, end[:, 1] - start[:, 1], 1.0)
    crossing = start + ((row - start[:, 1]) / rise)[:, None] * (end - start)
    # per edge start → end, emit the crossing if the edge crosses, then the end if it is kept
    emit = np.stack([crosses, end_in], axis=1)
    points = np.stack([crossing, end], axis=1)[emit]
    counts = np.bincount(np.repeat(owner, 2)[emit.reshape(-1)], minlength=len(counts))
    return points, counts


def _clip_rows_counts(
    points: np.ndarray, counts: np.ndarray, top: float, bottom: float
) -> tuple[np.ndarray, np.ndarray]:
    """Polygons (pixel vertices (P, 2), one after another, ``counts`` (L,)) cut to the rows
    ``top``..``bottom``: the cut vertices and the (L,) new counts (0 for a polygon cut away)."""
    if len(points) and points[:, 1].min() < top:
        points, counts = _clip_half_plane(points, counts, top, keep_below=False)
    if len(points) and points[:, 1].max() > bottom:
        points, counts = _clip_half_plane(points, counts, bottom, keep_below=True)
    return points, counts


class View:
    """The world → image transforms for K ego poses, with culling of what is out of sight.

    :param positions: (K, 2) ego positions.
    :param headings: (K,) ego headings.
    """

    def __init__(
        self, positions: np.ndarray, headings: np.ndarray, size_hw: tuple[int, int], pixels_per_meter: float
    ) -> None:
        self.positions = np.asarray(positions, dtype=float).reshape(-1, 2)
        self.headings = np.asarray(headings, dtype=float).reshape(-1)
        self.size_hw, self.ppm = size_hw, float(pixels_per_meter)
        # the image's half diagonal in metres, plus a margin for line widths
        self.radius_m = np.hypot(*size_hw) / 2 / self.ppm + 2.0

    @staticmethod
    def of(batch: WorldBatch, size_hw: tuple[int, int], pixels_per_meter: float) -> View:
        """The view from each ego of ``batch``."""
        return View(batch.ego.position, batch.ego.heading, size_hw, pixels_per_meter)

    def pixels(self, points_world: np.ndarray) -> np.ndarray:
        """World points (K, ..., 2), world k's in row k → float pixel coordinates (column, row)."""
        points = np.asarray(points_world, dtype=float)
        inner = (1,) * (points.ndim - 2)
        count = len(self.headings)
        position = self.positions.reshape(count, *inner, 2)
        return to_pixels(points, position, self.headings.reshape(count, *inner), self.size_hw, self.ppm)

    def pixels_of(self, k: int, points_world: np.ndarray) -> np.ndarray:
        """World points (..., 2) seen from ego ``k`` → float pixel coordinates (..., 2)."""
        return to_pixels(points_world, self.positions[k], self.headings[k], self.size_hw, self.ppm)

    def lanes(self, batch: WorldBatch) -> list[list[np.ndarray]]:
        """Per world, the lane polygons of its map that reach its image, as fixed-point pixel
        polygons cut to its rows: culled per map for all its worlds at once, then projected and
        cut for all K worlds in one go."""
        vertices, world_of_vertex, counts, owners = [], [], [], []
        for index, road in enumerate(batch.roads):
            worlds = np.flatnonzero(batch.road_index == index)
            lanes: LanePolygons = road.derived(LanePolygons, LanePolygons)
            offset = lanes.centres[None] - self.positions[worlds, None]  # (W, L, 2)
            visible = np.hypot(offset[..., 0], offset[..., 1]) <= self.radius_m + lanes.radii  # (W, L)
            seen_by, vertex = np.nonzero(visible[:, lanes.owner])  # world-major, each world's lanes in order
            vertices.append(lanes.vertices[vertex])
            world_of_vertex.append(worlds[seen_by])
            counts.append(np.broadcast_to(lanes.counts, visible.shape)[visible])
            owners.append(np.repeat(worlds, visible.sum(axis=1)))
        polygons: list[list[np.ndarray]] = [[] for _ in self.headings]
        counts, owners = np.concatenate(counts), np.concatenate(owners)
        if counts.sum() == 0:
            return polygons
        world_of_vertex = np.concatenate(world_of_vertex)
        position, heading = self.positions[world_of_vertex], self.headings[world_of_vertex]
        pixels = to_pixels(np.concatenate(vertices), position, heading, self.size_hw, self.ppm)
        margin = 4.0  # rows beyond the image: the cut edges (and their anti-aliasing) stay unseen
        pixels, counts = _clip_rows_counts(pixels, counts, -margin, self.size_hw[0] - 1 + margin)
        for world, polygon in zip(owners, np.split(fixed_point(pixels), np.cumsum(counts)[:-1]), strict=True):
            if len(polygon) >= 3:
                polygons[world].append(polygon)
        return polygons

    def polylines(self, polylines: np.ndarray, counts: np.ndarray, width_px: int) -> list[list[np.ndarray]]:
        """Per world, the segments of its polyline (K, R, 2) (``counts[k]`` real points) that reach
        its image, as (2, 2) fixed-point pixel arrays cut to a band of rows around the image."""
        pixels = self.pixels(polylines)  # (K, R, 2)
        start, end = pixels[:, :-1], pixels[:, 1:]
        margin = width_px / 2 + 2.0
        top, bottom = -margin, self.size_hw[0] - 1 + margin
        low = np.minimum(start[..., 1], end[..., 1])
        high = np.maximum(start[..., 1], end[..., 1])
        real = np.arange(start.shape[1]) < (np.asarray(counts) - 1)[:, None]
        seen = real & (high >= top) & (low <= bottom)  # (K, R - 1)
        rise = end[..., 1] - start[..., 1]
        flat = np.abs(rise) < 1e-9
        rise = np.where(flat, 1.0, rise)
        # parameters of the segment where it crosses the top and bottom rows, ordered
        at_top, at_bottom = (top - start[..., 1]) / rise, (bottom - start[..., 1]) / rise
        enter = np.where(flat, 0.0, np.clip(np.minimum(at_top, at_bottom), 0.0, 1.0))
        leave = np.where(flat, 1.0, np.clip(np.maximum(at_top, at_bottom), 0.0, 1.0))
        delta = end - start
        cut = fixed_point(
            np.stack([start + enter[..., None] * delta, start + leave[..., None] * delta], axis=2)
        )
        return [list(cut[k][seen[k]]) for k in range(len(cut))]

    def boxes(
        self, boxes: np.ndarray, valid: np.ndarray, inset_px: float = 0.0
    ) -> tuple[np.ndarray, np.ndarray]:
        """Fixed-point corners (K, N, 4, 2) of the rectangles (K, N, 5) ``x, y, heading, length,
        width``, each side moved ``inset_px`` pixels inwards (see ``EXACT_INSET_PX``), and the
        (K, N) mask of those valid and in sight."""
        boxes = np.asarray(boxes, dtype=float)
        reach = self.radius_m + np.hypot(boxes[..., 3], boxes[..., 4]) / 2
        offset = boxes[..., :2] - self.positions[:, None]
        seen = valid & (offset[..., 0] * offset[..., 0] + offset[..., 1] * offset[..., 1] <= reach * reach)
        if inset_px:
            boxes = boxes.copy()
            boxes[..., 3:] = np.maximum(boxes[..., 3:] - 2 * inset_px / self.ppm, 0.0)
        return fixed_point(self.pixels(box_corners(boxes))), seen

    def box_groups(
        self, groups: list[tuple[np.ndarray, np.ndarray]], inset_px: float = 0.0
    ) -> list[tuple[np.ndarray, np.ndarray]]:
        """``boxes`` of several groups of rectangles [(boxes (K, N_i, 5), valid (K, N_i))] in one
        pass: [(corners (K, N_i, 4, 2), seen (K, N_i))], group by group."""
        corners, seen = self.boxes(
            np.concatenate([boxes for boxes, _ in groups], axis=1),
            np.concatenate([valid for _, valid in groups], axis=1),
            inset_px,
        )
        edges = np.cumsum([0] + [boxes.shape[1] for boxes, _ in groups])
        return [(corners[:, a:b], seen[:, a:b]) for a, b in zip(edges[:-1], edges[1:], strict=True)]

    def boxes_of(self, k: int, boxes: np.ndarray, inset_px: float = 0.0) -> np.ndarray:
        """Fixed-point corners (M, 4, 2) of the rectangles (N, 5) in sight of ego ``k`` (see ``boxes``)."""
        boxes = np.asarray(boxes, dtype=float).reshape(1, -1, 5)
        one = View(self.positions[k : k + 1], self.headings[k : k + 1], self.size_hw, self.ppm)
        corners, seen = one.boxes(boxes, np.ones(boxes.shape[:2], dtype=bool), inset_px)
        return corners[0][seen[0]]


Colour = int | tuple[int, int, int]


def fill_each(
    image: np.ndarray, polygons: Iterable[np.ndarray], colour: Colour, line_type: int = cv2.LINE_8
) -> None:
    """Fill polygons one by one: a single ``cv2.fillPoly`` call with several polygons fills by
    the even-odd rule and leaves holes where they overlap (crossing lanes, touching cars)."""
    for polygon in polygons:
        cv2.fillPoly(image, [polygon], colour, line_type, SHIFT)


def fill_boxes(image: np.ndarray, corners: np.ndarray, colour: Colour, line_type: int = cv2.LINE_8) -> None:
    """Fill rectangles (N, 4, 2) given as fixed-point corners (convex, so the fast fill)."""
    for box in corners:
        cv2.fillConvexPoly(image, box, colour, line_type, SHIFT)


class TopDown(Sensor):
    """Five uint8 channels (0 or 255), channels first, ``(5, size, size)``, ego-centred, heading up.

    0 road layout (lane polygons), 1 planned route (a 2 m wide band), 2 past ego positions (1 m
    square dots at the last ``history`` positions), 3 other vehicles now, 4 other vehicles at the
    previous ``observe`` (as now on an episode's first frame), all in the current ego frame.
    Vehicles and dots cover exactly the pixels whose centres they contain.

    :param size: image height and width in pixels (the MetaDrive study: 84).
    :param pixels_per_meter: resolution; 2 px/m shows 21 m on each side of the ego at 84 px.
    :param history: number of past ego positions drawn.
    :param lights: add a sixth channel with the traffic lights' stop bars (1 m x 4 m across the
        lane), 85 for green, 170 for yellow, 255 for red.
    """

    name = "topdown"
    help = "5x84x84 semantic image: road, route, past ego positions, traffic now / one step earlier"

    def __init__(
        self, *, size: int = 84, pixels_per_meter: float = 2.0, history: int = 10, lights: bool = False
    ) -> None:
        if size < 8 or pixels_per_meter <= 0 or history < 0:
            raise ValueError("topdown needs size >= 8, pixels_per_meter > 0, history >= 0")
        self.size, self.ppm, self.history = int(size), float(pixels_per_meter), int(history)
        self.lights = bool(lights)
        channels = len(CHANNELS) + int(self.lights)
        self._space = spaces.Box(0, 255, shape=(channels, self.size, self.size), dtype=np.uint8)
        self._allocate(0)

    def _allocate(self, count: int) -> None:
        """History of ``count`` worlds: the last ``history`` ego positions (oldest first, the newest
        ``past_count[k]`` rows real) and the traffic (K, M, 6) at the previous observe."""
        self.past_positions = np.zeros((count, self.history, 2))
        self.past_count = np.zeros(count, dtype=np.int64)
        self.previous_traffic = np.zeros((count, 0, 6))
        self.previous_valid = np.zeros((count, 0), dtype=bool)
        self.has_previous = np.zeros(count, dtype=bool)  # False on an episode's first frame

    def _reset(self, batch: WorldBatch, mask: np.ndarray) -> None:
        if len(self.past_count) != batch.num_worlds:
            self._allocate(batch.num_worlds)
        self.past_count[mask] = 0
        self.has_previous[mask] = False

    def _observe(self, batch: WorldBatch, out: np.ndarray) -> None:
        count = batch.num_worlds
        if len(self.past_count) != count:  # observed before any reset: every world starts now
            self._reset(batch, np.ones(count, dtype=bool))
        view = View.of(batch, (self.size, self.size), self.ppm)
        width_px = max(int(round(ROUTE_WIDTH_M * self.ppm)), 1)
        routes = view.polylines(batch.route.polyline, batch.route.count, width_px)
        # squares, not cv2.circle: OpenCV's sub-pixel circles are off by up to half a pixel
        dots = np.empty((count, self.history, 5))
        dots[..., :2] = self.past_positions
        dots[..., 2], dots[..., 3:] = batch.ego.heading[:, None], PAST_DOT_M
        past = np.arange(self.history) >= self.history - self.past_count[:, None]  # (K, history)
        traffic, traffic_valid = batch.road_users()
        size = max(traffic.shape[1], self.previous_traffic.shape[1])
        first = ~self.has_previous[:, None, None]  # the first frame shows the traffic now twice
        previous = np.where(first, pad_slots(traffic, size), pad_slots(self.previous_traffic, size))
        previous_valid = np.where(
            first[..., 0], pad_slots(traffic_valid, size), pad_slots(self.previous_valid, size)
        )
        columns = [0, 1, 2, 4, 5]  # vehicle rows → rectangles x, y, heading, length, width
        groups = [
            (dots, past),
            (traffic[..., columns], traffic_valid),
            (previous[..., columns], previous_valid),
        ]
        if self.lights:
            groups.append((stop_bars(batch.traffic_lights), batch.light_valid))  # (K, L, 5)
            levels = LIGHT_LEVELS[batch.traffic_lights[..., 3].astype(int)]
        # every rectangle of every world moved to its ego frame and culled in one pass
        boxes = view.box_groups(groups, EXACT_INSET_PX)
        out[...] = 0
        lanes = view.lanes(batch)
        for k in range(count):  # one OpenCV raster per world
            image = out[k]
            fill_each(image[0], lanes[k], 255)
            if batch.route.count[k] > 1:
                cv2.polylines(image[1], routes[k], False, 255, width_px, cv2.LINE_8, SHIFT)
            for channel, (corners, seen) in zip((2, 3, 4), boxes, strict=False):  # dots, traffic now, before
                fill_boxes(image[channel], corners[k][seen[k]], 255)
            if self.lights:
                bar_corners, bars_seen = boxes[3]
                for corners, level in zip(bar_corners[k][bars_seen[k]], levels[k][bars_seen[k]], strict=True):
                    cv2.fillConvexPoly(image[5], corners, int(level), cv2.LINE_8, SHIFT)
        if self.history:
            self.past_positions[:, :-1] = self.past_positions[:, 1:].copy()
            self.past_positions[:, -1] = batch.ego.position
            self.past_count = np.minimum(self.past_count + 1, self.history)
        self.previous_traffic, self.previous_valid = traffic.copy(), traffic_valid.copy()
        self.has_previous[:] = True
