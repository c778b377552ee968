"""Top-down semantic image: the 5 channels of the MetaDrive study, ego-centred and heading-aligned.

Pixel convention (shared with ``birdeye``): the ego sits at the image centre with its heading
pointing up. In continuous image coordinates where pixel (row r, column c) covers
``[r, r+1) × [c, c+1)``, a point ``x`` m ahead of the ego and ``y`` m to its right lies at
``column = W/2 + y·ppm, row = H/2 − x·ppm``. ``to_pixels`` returns OpenCV's coordinates, where
integers are pixel *centres*, i.e. those values minus 0.5. So the ego is at the shared corner of
the four middle pixels of an even-sized image, and the view is exactly symmetric.
"""

from __future__ import annotations

from collections.abc import Iterable

import cv2
import numpy as np
from gymnasium import spaces

from drivelab.perception.base import Sensor, box_corners, ego_frame
from drivelab.world.batch import WorldBatch
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
    """World points (..., 2) → float image coordinates (..., 2) as (column, row).

    Ego-centred, heading up, OpenCV's pixel-centre convention (see the module docstring):
    ``column = W/2 − 0.5 + y·ppm``, ``row = H/2 − 0.5 − x·ppm`` for a point ``x`` m ahead and
    ``y`` m to the right of the ego.
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
    """Mask (M,) of the segments (M, 2, 2) that come within ``radius`` of ``centre`` (2,), or mask
    (W, M) for W centres (W, 2).

    Tests each segment's nearest point, so a 10 km road line passing the ego counts.
    """
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
        polygons = [np.asarray(p, dtype=float).reshape(-1, 2) for p in road.lane_polygons]
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


def clip_rows(points: np.ndarray, counts: np.ndarray, top: float, bottom: float) -> list[np.ndarray]:
    """Cut polygons (pixel vertices, one after another) to the rows ``top``..``bottom``.

    OpenCV's polygon fill costs time in proportion to the rows a polygon spans, in or out of the
    image (a 10 km lane: ~0.1 ms), so lanes are cut to a band around the image first.

    :return: the non-empty clipped polygons as float (K, 2) arrays.
    """
    points, counts = _clip_rows_counts(points, counts, top, bottom)
    polygons = np.split(points, np.cumsum(counts)[:-1])
    return [polygon for polygon in polygons if len(polygon) >= 3]


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
        pixels = to_pixels(
            np.concatenate(vertices),
            self.positions[world_of_vertex],
            self.headings[world_of_vertex],
            self.size_hw,
            self.ppm,
        )
        margin = 4.0  # rows beyond the image: the cut edges (and their anti-aliasing) stay unseen
        pixels, counts = _clip_rows_counts(pixels, counts, -margin, self.size_hw[0] - 1 + margin)
        for world, polygon in zip(owners, np.split(fixed_point(pixels), np.cumsum(counts)[:-1]), strict=True):
            if len(polygon) >= 3:
                polygons[world].append(polygon)
        return polygons

    def polylines(self, polylines: np.ndarray, counts: np.ndarray, width_px: int) -> list[list[np.ndarray]]:
        """Per world, the segments of its polyline (K, R, 2) (``counts[k]`` real points) that reach
        its image, as (2, 2) fixed-point pixel arrays.

        Each segment is cut to a band of rows around the image, because OpenCV's thick lines,
        like its polygons, cost time in proportion to the rows they span.
        """
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


def road_users(batch: WorldBatch) -> tuple[np.ndarray, np.ndarray]:
    """Every body besides the ego, (K, N + P, 6) vehicles then pedestrians, and its (K, N + P) valid mask."""
    if batch.pedestrians.shape[1] == 0:
        return batch.vehicles, batch.vehicle_valid
    return (
        np.concatenate([batch.vehicles, batch.pedestrians], axis=1),
        np.concatenate([batch.vehicle_valid, batch.pedestrian_valid], axis=1),
    )


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

    0 road layout (lane polygons filled), 1 planned route (a 2 m wide band along the route
    polyline), 2 past ego positions (1 m square dots at the last ``history`` positions, the
    current one excluded), 3 other vehicles now, 4 other vehicles at the previous ``observe``
    (the same as now on an episode's first frame). Everything is drawn in the current ego frame,
    so channels 3 and 4 together show the relative motion of traffic. See the module docstring
    for the pixel mapping: vehicles and dots cover exactly the pixels whose centres they contain;
    lanes and the route get OpenCV's usual extra half pixel around their outline.

    K worlds per call: routes, past positions, traffic and stop bars of all K worlds are moved to
    their ego frames and culled at once, lanes once per map; then one OpenCV raster per world.
    The history (past positions, previous traffic) is kept as (K, …) arrays, cleared by ``reset``
    for the worlds in its mask.

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
        # history over K worlds: the last ``history`` ego positions (oldest first, the newest
        # ``past_count[k]`` rows real) and the traffic at the previous observe
        self.past_positions = np.zeros((0, self.history, 2))  # (K, history, 2)
        self.past_count = np.zeros(0, dtype=np.int64)  # (K,)
        self.previous_traffic = np.zeros((0, 0, 6))  # (K, M, 6)
        self.previous_valid = np.zeros((0, 0), dtype=bool)  # (K, M)
        self.has_previous = np.zeros(0, dtype=bool)  # (K,) False on an episode's first frame

    @property
    def space(self) -> spaces.Box:
        return self._space

    def _reset(self, batch: WorldBatch, mask: np.ndarray) -> None:
        count = batch.num_worlds
        if len(self.past_count) != count:
            self.past_positions = np.zeros((count, self.history, 2))
            self.past_count = np.zeros(count, dtype=np.int64)
            self.previous_traffic = np.zeros((count, 0, 6))
            self.previous_valid = np.zeros((count, 0), dtype=bool)
            self.has_previous = np.zeros(count, dtype=bool)
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
        traffic, traffic_valid = road_users(batch)
        size = max(traffic.shape[1], self.previous_traffic.shape[1])
        first = ~self.has_previous[:, None, None]  # the first frame shows the traffic now twice
        previous = np.where(first, _pad_slots(traffic, size), _pad_slots(self.previous_traffic, size))
        previous_valid = np.where(
            first[..., 0], _pad_slots(traffic_valid, size), _pad_slots(self.previous_valid, size)
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


def _pad_slots(array: np.ndarray, size: int) -> np.ndarray:
    """``array`` (K, N, ...) zero-padded to ``size`` slots on axis 1."""
    missing = size - array.shape[1]
    if missing <= 0:
        return array
    return np.pad(array, [(0, 0), (0, missing)] + [(0, 0)] * (array.ndim - 2))
