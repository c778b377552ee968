"""Top-down semantic image: the 5 channels of seed 003, ego-centred and heading-aligned."""

from __future__ import annotations

from collections import deque

import cv2
import numpy as np
from gymnasium import spaces

from drivelab.envs.world import WorldState
from drivelab.perception.base import Sensor, box_corners, ego_frame

SHIFT = 4  # OpenCV sub-pixel bits: coordinates are drawn to 1/16 pixel
SCALE = 1 << SHIFT
PAST_DOT_M = 1.0  # side of the square marking a past ego position
CHANNELS = ("road", "route", "past_ego", "traffic", "traffic_previous")


def to_pixels(
    points: np.ndarray,
    ego_position: np.ndarray,
    ego_heading: float,
    size_hw: tuple[int, int],
    pixels_per_meter: float,
) -> np.ndarray:
    """World points (..., 2) → image coordinates (..., 2) as (column, row), float.

    The ego sits at the image centre facing up: a point ``x`` m ahead and ``y`` m to the right
    is at column ``W/2 − 0.5 + y·ppm`` and row ``H/2 − 0.5 − x·ppm``, in OpenCV's convention
    where integer coordinates are pixel centres (so the ego is at the corner of the 4 middle
    pixels of an even-sized image).
    """
    local = ego_frame(points, ego_position, ego_heading)
    height, width = size_hw
    column = (width / 2 - 0.5) + local[..., 1] * pixels_per_meter
    row = (height / 2 - 0.5) - local[..., 0] * pixels_per_meter
    return np.stack([column, row], axis=-1)


def fixed_point(pixels: np.ndarray) -> np.ndarray:
    """Float pixel coordinates → the int32 fixed-point form OpenCV draws with ``shift=SHIFT``."""
    return np.round(pixels * SCALE).astype(np.int32)


class Projector:
    """World → image transform for one WorldState (shared by the top-down renderers)."""

    def __init__(self, world: WorldState, size_hw: tuple[int, int], pixels_per_meter: float) -> None:
        self.position, self.heading = world.ego.position, world.ego.heading
        self.size_hw, self.ppm = size_hw, pixels_per_meter
        self.view_radius_m = np.hypot(*size_hw) / 2 / pixels_per_meter + 1.0

    def __call__(self, points: np.ndarray) -> np.ndarray:
        return fixed_point(to_pixels(points, self.position, self.heading, self.size_hw, self.ppm))

    def polygons(self, polygons: tuple[np.ndarray, ...]) -> list[np.ndarray]:
        """Project the polygons that can reach the view (cheap bounding-box cull first)."""
        kept = []
        for polygon in polygons:
            low, high = polygon.min(axis=0), polygon.max(axis=0)
            nearest = np.clip(self.position, low, high)
            if np.hypot(*(nearest - self.position)) <= self.view_radius_m:
                kept.append(self(polygon))
        return kept

    def vehicles(self, vehicles: np.ndarray) -> list[np.ndarray]:
        """Outlines of the vehicles within view, one (4, 2) int32 array each."""
        if len(vehicles) == 0:
            return []
        near = np.hypot(*(vehicles[:, :2] - self.position).T) <= self.view_radius_m + 10
        corners = box_corners(vehicles[near][:, [0, 1, 2, 4, 5]])
        return list(self(corners))


class TopDown(Sensor):
    """Five uint8 channels (0 or 255), channels first, ``(5, size, size)``.

    0 road layout (lanes filled), 1 planned route (a 2 m wide band along the route polyline),
    2 past ego positions (1 m squares at the last ``history`` positions, not the current one),
    3 other vehicles now, 4 other vehicles one step earlier (the same as now on an episode's
    first frame). The view is ego-centred and heading-aligned (see ``to_pixels``).

    :param size: image height and width in pixels (seed 003: 84).
    :param pixels_per_meter: resolution; 2 px/m shows 42 m around the ego at 84 px.
    :param history: number of past ego positions drawn.
    """

    name = "topdown"

    def __init__(self, *, size: int = 84, pixels_per_meter: float = 2.0, history: int = 10) -> None:
        if size < 8 or pixels_per_meter <= 0 or history < 0:
            raise ValueError("topdown needs size >= 8, pixels_per_meter > 0, history >= 0")
        self.size, self.ppm = int(size), float(pixels_per_meter)
        self._space = spaces.Box(0, 255, shape=(len(CHANNELS), self.size, self.size), dtype=np.uint8)
        self.past_positions: deque[np.ndarray] = deque(maxlen=max(int(history), 1))
        self.history = int(history)
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
        project = Projector(world, (self.size, self.size), self.ppm)
        cv2.fillPoly(image[0], project.polygons(world.road.lane_polygons), 255, cv2.LINE_8, SHIFT)
        if len(world.route.polyline) > 1:
            width_px = max(int(round(2.0 * self.ppm)), 1)
            cv2.polylines(image[1], [project(world.route.polyline)], False, 255, width_px, cv2.LINE_8, SHIFT)
        if self.history:
            # each past position as a 1 m square, drawn like a vehicle (x, y, heading, _, length, width)
            past = np.zeros((len(self.past_positions), 6))
            past[:, :2] = np.array(self.past_positions).reshape(-1, 2)
            past[:, 2], past[:, 4:] = world.ego.heading, PAST_DOT_M
            cv2.fillPoly(image[2], project.vehicles(past), 255, cv2.LINE_8, SHIFT)
            self.past_positions.append(np.array(world.ego.position, dtype=float))
        cv2.fillPoly(image[3], project.vehicles(world.vehicles), 255, cv2.LINE_8, SHIFT)
        previous = world.vehicles if self.previous_vehicles is None else self.previous_vehicles
        cv2.fillPoly(image[4], project.vehicles(previous), 255, cv2.LINE_8, SHIFT)
        self.previous_vehicles = world.vehicles
        return image
