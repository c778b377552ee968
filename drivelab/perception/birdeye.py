"""Bird's-eye RGB view, ego-centred and heading-aligned: for videos and RGB-input agents.

Same view as ``topdown`` (its ``to_pixels`` mapping: ego at the centre, heading up, the ego's
right on the image's right), drawn in colour with anti-aliasing.
"""

from __future__ import annotations

import cv2
import numpy as np
from gymnasium import spaces

from drivelab.perception.base import Sensor, zebra_stripes
from drivelab.perception.topdown import (
    SHIFT,
    View,
    fill_boxes,
    fill_each,
    fixed_point,
    segments_near,
    stop_bars,
)
from drivelab.world.batch import WorldBatch
from drivelab.world.state import MARKING_DASHED, MARKING_SOLID, RoadMap, WorldState

GRASS = (96, 140, 84)
ROAD = (70, 70, 74)
ROUTE = (86, 86, 120)  # a faint blue band on the road
SOLID_LINE = (235, 235, 235)
DASHED_LINE = (200, 200, 200)
VEHICLE = (60, 110, 220)
PEDESTRIAN = (200, 60, 160)
ZEBRA = (225, 225, 225)
EGO = (60, 200, 70)
EGO_CRASHED = (230, 40, 40)
LIGHT_COLOURS = ((40, 200, 60), (240, 200, 30), (230, 30, 30))  # green, yellow, red stop bars
ROUTE_WIDTH_M = 1.0
DASH_LENGTH_M, DASH_PERIOD_M = 3.0, 8.0  # painted 3 m, then a 5 m gap


class DashedMarkings:
    """A road's dashed markings with the arc length at which each segment starts along its chain
    of touching segments, so that dashes keep their rhythm around bends and stay put in the world;
    only the dashes in sight are cut each frame."""

    def __init__(self, road: RoadMap) -> None:
        segments = np.asarray(road.markings, dtype=float)[road.marking_kinds == MARKING_DASHED]
        length = np.hypot(*(segments[:, 1] - segments[:, 0]).T)
        self.segments, self.length = segments[length > 1e-9], length[length > 1e-9]
        start, end = self.segments[:, 0], self.segments[:, 1]
        count = len(self.length)
        joined = np.zeros(count, dtype=bool)
        joined[1:] = np.all(np.isclose(start[1:], end[:-1]), axis=1)
        cumulative = np.cumsum(self.length) - self.length
        chain_head = np.maximum.accumulate(np.where(joined, 0, np.arange(count)))
        self.arc = cumulative - cumulative[chain_head]

    def dashes_around(self, centres: np.ndarray, radius: float) -> list[np.ndarray]:
        """Per centre of the W ``centres`` (W, 2), the dashes (D, 2, 2) within ``radius`` of it, in
        world coordinates."""
        seen = segments_near(self.segments, centres, radius)  # (W, M)
        around, index = np.nonzero(seen)  # (segment, centre) pairs, centre by centre
        segments, length, arc = self.segments[index], self.length[index], self.arc[index]
        centre = centres[around]
        # the stretch of each segment inside the circle, as arc lengths [low, high] along it
        direction = (segments[:, 1] - segments[:, 0]) / length[:, None]
        nearest = np.einsum("ij,ij->i", centre - segments[:, 0], direction)
        offset = segments[:, 0] + nearest[:, None] * direction - centre
        half_chord = np.sqrt(np.maximum(radius * radius - np.einsum("ij,ij->i", offset, offset), 0.0))
        low = np.clip(nearest - half_chord, 0.0, length)
        high = np.clip(nearest + half_chord, 0.0, length)
        # dash k covers arc [k·P, k·P + D] of its line; it overlaps [arc + low, arc + high] for
        # first <= k <= last
        first = np.floor((arc + low - DASH_LENGTH_M) / DASH_PERIOD_M).astype(int) + 1
        last = np.ceil((arc + high) / DASH_PERIOD_M).astype(int) - 1
        counts = np.maximum(last - first + 1, 0)
        owner = np.repeat(np.arange(len(counts)), counts)
        k = first[owner] + np.arange(len(owner)) - np.repeat(np.cumsum(counts) - counts, counts)
        begin = np.clip(k * DASH_PERIOD_M - arc[owner], 0.0, length[owner])
        finish = np.clip(k * DASH_PERIOD_M + DASH_LENGTH_M - arc[owner], 0.0, length[owner])
        origin, unit = segments[owner, 0], direction[owner]
        dashes = np.stack([origin + begin[:, None] * unit, origin + finish[:, None] * unit], axis=1)
        return np.split(dashes, np.searchsorted(around[owner], np.arange(1, len(centres))))


def render_birdeye(
    world: WorldState, size_hw: tuple[int, int] = (128, 128), pixels_per_meter: float = 3.0
) -> np.ndarray:
    """An RGB uint8 image (H, W, 3) of the road, route, markings, traffic and ego of one world.

    Grass background, dark road (lane polygons), the route as a faint band, white solid and
    light-grey dashed markings, traffic lights as stop bars in their colour, other vehicles blue,
    pedestrians magenta, the ego green (red after a collision).

    :param size_hw: image height and width in pixels (videos use larger ones, e.g. (256, 512)).
    :param pixels_per_meter: resolution.
    """
    image = np.empty((1, *size_hw, 3), dtype=np.uint8)
    draw_birdeye(WorldBatch.stack([world]), image, pixels_per_meter)
    return image[0]


def zebra_boxes(road: RoadMap) -> np.ndarray:
    """The road's zebra stripes as rectangles (S, 5) (computed once per map)."""
    return zebra_stripes(road.crossings)


def solid_markings(road: RoadMap) -> np.ndarray:
    """The road's solid markings (M, 2, 2) (computed once per map)."""
    return np.asarray(road.markings, dtype=float).reshape(-1, 2, 2)[road.marking_kinds == MARKING_SOLID]


def markings_in_sight(
    batch: WorldBatch, radius_m: float, centres: np.ndarray | None = None
) -> list[tuple[np.ndarray, np.ndarray]]:
    """Per world, the (solid segments (S, 2, 2), dashes (D, 2, 2)) of its road within ``radius_m``
    of its view's centre (``centres`` (K, 2); default its ego), culled map by map for all the
    worlds on that map at once."""
    centres = batch.ego.position if centres is None else centres
    found: list = [None] * batch.num_worlds
    for index, road in enumerate(batch.roads):
        worlds = np.flatnonzero(batch.road_index == index)
        positions = centres[worlds]  # (W, 2)
        solid = road.derived(solid_markings, solid_markings)
        solid_near = segments_near(solid, positions, radius_m)  # (W, S)
        dashes = road.derived(DashedMarkings, DashedMarkings).dashes_around(positions, radius_m)
        for w, k in enumerate(worlds):
            found[k] = (solid[solid_near[w]], dashes[w])
    return found


LAYERS = ("all", "road", "moving")


def draw_birdeye(
    batch: WorldBatch, out: np.ndarray, pixels_per_meter: float, view: View | None = None, layers: str = "all"
) -> None:
    """Draw the K worlds' bird's-eye images into ``out`` (K, H, W, 3) uint8 (see ``render_birdeye``).

    :param view: the camera of each world (centre (K, 2), the world direction drawn upwards (K,),
        ``out``'s size and ``pixels_per_meter``); default each ego's, heading up (the sensor's).
    :param layers: "all"; "road": only what never moves (grass, lanes, markings, crossings), which
        a video draws once per map (``envs/video.py``); "moving": only the rest (route, lights,
        traffic, ego), over what ``out`` holds. "road" then "moving" draws the route above the
        markings, "all" below them.
    """
    if layers not in LAYERS:
        raise ValueError(f"layers must be one of {LAYERS}, got {layers!r}")
    count = batch.num_worlds
    size_hw = out.shape[1:3]
    view = View.of(batch, size_hw, pixels_per_meter) if view is None else view
    road_layer, moving_layer = layers != "moving", layers != "road"
    if road_layer:
        lanes = view.lanes(batch)
        markings = markings_in_sight(batch, view.radius_m, view.positions)
        out[:] = GRASS
    if moving_layer:
        width_px = max(int(round(ROUTE_WIDTH_M * pixels_per_meter)), 1)
        routes = view.polylines(batch.route.polyline, batch.route.count, width_px)
        lights = batch.traffic_lights  # (K, L, 4)
        bars = stop_bars(lights)  # (K, L, 5)
        ego = batch.ego
        ego_boxes = np.column_stack([ego.position, ego.heading, ego.length_m, ego.width_m])[:, None]
        columns = [0, 1, 2, 4, 5]  # vehicle rows → rectangles x, y, heading, length, width
        # every rectangle of every world moved to its ego frame and culled in one pass
        (bar_corners, bars_seen), (vehicles, vehicles_seen), (pedestrians, pedestrians_seen), (egos, _) = (
            view.box_groups(
                [
                    (bars, batch.light_valid),
                    (batch.vehicles[..., columns], batch.vehicle_valid),
                    (batch.pedestrians[..., columns], batch.pedestrian_valid),
                    (ego_boxes, np.ones((count, 1), dtype=bool)),
                ]
            )
        )
    for k in range(count):  # one OpenCV raster per world
        image, road = out[k], batch.road_of(k)
        if road_layer:
            fill_each(image, lanes[k], ROAD, cv2.LINE_AA)
        if moving_layer and batch.route.count[k] > 1:
            cv2.polylines(image, routes[k], False, ROUTE, width_px, cv2.LINE_AA, SHIFT)
        if road_layer:
            for lines, colour in zip(markings[k], (SOLID_LINE, DASHED_LINE), strict=True):
                if len(lines):
                    pixels = fixed_point(view.pixels_of(k, lines))
                    cv2.polylines(image, list(pixels), False, colour, 1, cv2.LINE_AA, SHIFT)
            if len(road.crossings):
                zebras = view.boxes_of(k, road.derived(zebra_boxes, zebra_boxes))
                fill_boxes(image, zebras, ZEBRA, cv2.LINE_AA)
        if not moving_layer:
            continue
        for corners, state in zip(bar_corners[k][bars_seen[k]], lights[k, bars_seen[k], 3], strict=True):
            cv2.fillConvexPoly(image, corners, LIGHT_COLOURS[int(state)], cv2.LINE_AA, SHIFT)
        fill_boxes(image, vehicles[k][vehicles_seen[k]], VEHICLE, cv2.LINE_AA)
        fill_boxes(image, pedestrians[k][pedestrians_seen[k]], PEDESTRIAN, cv2.LINE_AA)
        colour = EGO_CRASHED if batch.events.collided[k] else EGO
        cv2.fillConvexPoly(image, egos[k, 0], colour, cv2.LINE_AA, SHIFT)


class BirdEye(Sensor):
    """RGB bird's-eye image, channels last ``(size, size, 3)`` uint8 (see ``render_birdeye``).

    :param size: image height and width in pixels.
    :param pixels_per_meter: resolution; 3 px/m shows about 21 m on each side at 128 px.
    """

    name = "birdeye"
    help = "128x128 RGB bird's-eye view, ego-centred and heading-aligned"

    def __init__(self, *, size: int = 128, pixels_per_meter: float = 3.0) -> None:
        if size < 8 or pixels_per_meter <= 0:
            raise ValueError("birdeye needs size >= 8 and pixels_per_meter > 0")
        self.size, self.ppm = int(size), float(pixels_per_meter)
        self._space = spaces.Box(0, 255, shape=(self.size, self.size, 3), dtype=np.uint8)

    def _observe(self, batch: WorldBatch, out: np.ndarray) -> None:
        draw_birdeye(batch, out, self.ppm)
