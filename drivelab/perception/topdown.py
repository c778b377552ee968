"""Top-down semantic image: the 5 channels of seed 003, ego-centred and heading-aligned.

Pixel convention (shared with ``birdeye``): the ego sits at the image centre with its heading
pointing up. In continuous image coordinates where pixel (row r, column c) covers
``[r, r+1) × [c, c+1)``, a point ``x`` m ahead of the ego and ``y`` m to its right lies at
``column = W/2 + y·ppm, row = H/2 − x·ppm``. ``to_pixels`` returns OpenCV's coordinates, where
integers are pixel *centres*, i.e. those values minus 0.5. So the ego is at the shared corner of
the four middle pixels of an even-sized image, and the view is exactly symmetric.
"""

from __future__ import annotations

import weakref
from collections import deque
from collections.abc import Callable, Iterable
from typing import TypeVar

import cv2
import numpy as np
from gymnasium import spaces

from drivelab.perception.base import Sensor, box_corners, ego_frame
from drivelab.world.state import RoadMap, WorldState

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
    """Rectangles (N, 5) ``x, y, heading, length, width`` of the lights' stop bars."""
    return np.column_stack([lights[:, :3], np.tile(STOP_BAR_M, (len(lights), 1))]).reshape(-1, 5)


T = TypeVar("T")


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
    """Mask (M,) of the segments (M, 2, 2) that come within ``radius`` of ``centre``.

    Tests each segment's nearest point, so a 10 km road line passing the ego counts.
    """
    start = segments[:, 0] - centre
    edge = segments[:, 1] - segments[:, 0]
    length2 = np.maximum(np.einsum("ij,ij->i", edge, edge), 1e-12)
    along = np.clip(-np.einsum("ij,ij->i", start, edge) / length2, 0.0, 1.0)
    nearest = start + along[:, None] * edge
    return np.einsum("ij,ij->i", nearest, nearest) <= radius * radius


_PER_ROAD: dict[tuple[int, str], tuple[weakref.ref, object]] = {}


def per_road(road: RoadMap, build: Callable[[RoadMap], T]) -> T:
    """``build(road)``, computed once per RoadMap object: a road is immutable and lasts an episode."""
    key = (id(road), build.__qualname__)
    cached = _PER_ROAD.get(key)
    if cached is not None and cached[0]() is road:  # the weak reference guards against id reuse
        return cached[1]  # type: ignore[return-value]
    value = build(road)
    if len(_PER_ROAD) >= 64:
        _PER_ROAD.pop(next(iter(_PER_ROAD)))
    _PER_ROAD[key] = (weakref.ref(road), value)
    return value


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


def clip_rows(points: np.ndarray, counts: np.ndarray, top: float, bottom: float) -> list[np.ndarray]:
    """Cut polygons (pixel vertices, one after another) to the rows ``top``..``bottom``.

    OpenCV's polygon fill costs time in proportion to the rows a polygon spans, in or out of the
    image (a 10 km lane: ~0.1 ms), so lanes are cut to a band around the image first.

    :return: the non-empty clipped polygons as float (K, 2) arrays.
    """
    if points[:, 1].min() < top:
        points, counts = _clip_half_plane(points, counts, top, keep_below=False)
    if len(points) and points[:, 1].max() > bottom:
        points, counts = _clip_half_plane(points, counts, bottom, keep_below=True)
    polygons = np.split(points, np.cumsum(counts)[:-1])
    return [polygon for polygon in polygons if len(polygon) >= 3]


class View:
    """The world → image transform for one ego pose, with culling of what is out of sight."""

    def __init__(self, world: WorldState, size_hw: tuple[int, int], pixels_per_meter: float) -> None:
        self.position = np.asarray(world.ego.position, dtype=float)
        self.heading = float(world.ego.heading)
        self.size_hw, self.ppm = size_hw, float(pixels_per_meter)
        # the image's half diagonal in metres, plus a margin for line widths
        self.radius_m = np.hypot(*size_hw) / 2 / self.ppm + 2.0

    def pixels(self, points_world: np.ndarray) -> np.ndarray:
        """World points (..., 2) → float pixel coordinates (column, row), see ``to_pixels``."""
        return to_pixels(points_world, self.position, self.heading, self.size_hw, self.ppm)

    def __call__(self, points_world: np.ndarray) -> np.ndarray:
        """World points (..., 2) → int32 fixed-point pixels (..., 2) for ``shift=SHIFT``."""
        return fixed_point(self.pixels(points_world))

    def lanes(self, road: RoadMap) -> list[np.ndarray]:
        """The lane polygons that reach the image, projected in one go and cut to its rows."""
        lanes = per_road(road, LanePolygons)
        visible = np.hypot(*(lanes.centres - self.position).T) <= self.radius_m + lanes.radii
        if not visible.any():
            return []
        pixels = self.pixels(lanes.vertices[visible[lanes.owner]])
        margin = 4.0  # rows beyond the image: the cut edges (and their anti-aliasing) stay unseen
        polygons = clip_rows(pixels, lanes.counts[visible], -margin, self.size_hw[0] - 1 + margin)
        return [fixed_point(polygon) for polygon in polygons]

    def polyline(self, points_world: np.ndarray, width_px: int) -> list[np.ndarray]:
        """A polyline's segments that reach the image, as (2, 2) fixed-point pixel arrays.

        Each segment is cut to a band of rows around the image, because OpenCV's thick lines,
        like its polygons, cost time in proportion to the rows they span.
        """
        pixels = self.pixels(points_world)
        start, end = pixels[:-1], pixels[1:]
        margin = width_px / 2 + 2.0
        top, bottom = -margin, self.size_hw[0] - 1 + margin
        low = np.minimum(start[:, 1], end[:, 1])
        high = np.maximum(start[:, 1], end[:, 1])
        seen = (high >= top) & (low <= bottom)
        start, end = start[seen], end[seen]
        rise = end[:, 1] - start[:, 1]
        flat = np.abs(rise) < 1e-9
        rise = np.where(flat, 1.0, rise)
        # parameters of the segment where it crosses the top and bottom rows, ordered
        at_top, at_bottom = (top - start[:, 1]) / rise, (bottom - start[:, 1]) / rise
        enter = np.where(flat, 0.0, np.clip(np.minimum(at_top, at_bottom), 0.0, 1.0))
        leave = np.where(flat, 1.0, np.clip(np.maximum(at_top, at_bottom), 0.0, 1.0))
        delta = end - start
        cut = np.stack([start + enter[:, None] * delta, start + leave[:, None] * delta], axis=1)
        return list(fixed_point(cut))

    def boxes(self, boxes: np.ndarray, inset_px: float = 0.0) -> np.ndarray:
        """Fixed-point corners (K, 4, 2) of the rectangles (N, 5) ``x, y, heading, length, width``
        in sight, each side moved ``inset_px`` pixels inwards (see ``EXACT_INSET_PX``)."""
        if len(boxes) == 0:
            return np.zeros((0, 4, 2), dtype=np.int32)
        reach = self.radius_m + np.hypot(boxes[:, 3], boxes[:, 4]) / 2
        offset = boxes[:, :2] - self.position
        boxes = boxes[np.einsum("ij,ij->i", offset, offset) <= reach * reach]
        if inset_px:
            boxes = boxes.copy()
            boxes[:, 3:] = np.maximum(boxes[:, 3:] - 2 * inset_px / self.ppm, 0.0)
        return self(box_corners(boxes))

    def vehicles(self, vehicles: np.ndarray, inset_px: float = 0.0) -> np.ndarray:
        """Fixed-point corners (K, 4, 2) of the vehicles (rows of ``VEHICLE_COLUMNS``) in sight."""
        return self.boxes(vehicles[:, [0, 1, 2, 4, 5]], inset_px)


Colour = int | tuple[int, int, int]


def fill_each(
    image: np.ndarray, polygons: Iterable[np.ndarray], colour: Colour, line_type: int = cv2.LINE_8
) -> None:
    """Fill polygons one by one: a single ``cv2.fillPoly`` call with several polygons fills by
    the even-odd rule and leaves holes where they overlap (crossing lanes, touching cars)."""
    for polygon in polygons:
        cv2.fillPoly(image, [polygon], colour, line_type, SHIFT)


def fill_boxes(image: np.ndarray, corners: np.ndarray, colour: Colour, line_type: int = cv2.LINE_8) -> None:
    """Fill rectangles (K, 4, 2) given as fixed-point corners (convex, so the fast fill)."""
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

    :param size: image height and width in pixels (seed 003: 84).
    :param pixels_per_meter: resolution; 2 px/m shows 21 m on each side of the ego at 84 px.
    :param history: number of past ego positions drawn.
    :param lights: add a sixth channel with the traffic lights' stop bars (1 m x 4 m across the
        lane), 85 for green, 170 for yellow, 255 for red.
    """

    name = "topdown"

    def __init__(
        self, *, size: int = 84, pixels_per_meter: float = 2.0, history: int = 10, lights: bool = False
    ) -> None:
        if size < 8 or pixels_per_meter <= 0 or history < 0:
            raise ValueError("topdown needs size >= 8, pixels_per_meter > 0, history >= 0")
        self.size, self.ppm, self.history = int(size), float(pixels_per_meter), int(history)
        self.lights = bool(lights)
        channels = len(CHANNELS) + int(self.lights)
        self._space = spaces.Box(0, 255, shape=(channels, self.size, self.size), dtype=np.uint8)
        self.past_positions: deque[np.ndarray] = deque(maxlen=self.history)
        self.previous_vehicles: np.ndarray | None = None

    @property
    def space(self) -> spaces.Box:
        return self._space

    def reset(self, world: WorldState, rng: np.random.Generator) -> None:
        super().reset(world, rng)
        self.past_positions.clear()
        self.previous_vehicles = None

    def observe(self, world: WorldState) -> np.ndarray:
        image = np.zeros(self._space.shape, dtype=np.uint8)
        view = View(world, (self.size, self.size), self.ppm)
        fill_each(image[0], view.lanes(world.road), 255)
        route = world.route.polyline
        if len(route) > 1:
            width_px = max(int(round(ROUTE_WIDTH_M * self.ppm)), 1)
            cv2.polylines(image[1], view.polyline(route, width_px), False, 255, width_px, cv2.LINE_8, SHIFT)
        if self.past_positions:
            # squares, not cv2.circle: OpenCV's sub-pixel circles are off by up to half a pixel
            dots = np.empty((len(self.past_positions), 5))
            dots[:, :2] = self.past_positions
            dots[:, 2], dots[:, 3:] = world.ego.heading, PAST_DOT_M
            fill_boxes(image[2], view.boxes(dots, EXACT_INSET_PX), 255)
        if self.history:
            self.past_positions.append(np.array(world.ego.position, dtype=float))
        traffic = world.road_users()  # vehicles and pedestrians
        fill_boxes(image[3], view.vehicles(traffic, EXACT_INSET_PX), 255)
        previous = traffic if self.previous_vehicles is None else self.previous_vehicles
        fill_boxes(image[4], view.vehicles(previous, EXACT_INSET_PX), 255)
        self.previous_vehicles = np.array(traffic, dtype=float)
        if self.lights:
            for bar, state in zip(stop_bars(world.traffic_lights), world.traffic_lights[:, 3], strict=True):
                fill_boxes(image[5], view.boxes(bar[None], EXACT_INSET_PX), int(LIGHT_LEVELS[int(state)]))
        return image
