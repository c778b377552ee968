"""Bird's-eye RGB view, ego-centred and heading-aligned: for videos and RGB-input agents."""

from __future__ import annotations

import cv2
import numpy as np
from gymnasium import spaces

from drivelab.envs.world import MARKING_SOLID, WorldState
from drivelab.perception.base import Sensor, box_corners
from drivelab.perception.topdown import SHIFT, Projector

GRASS = (96, 140, 84)
ROAD = (70, 70, 74)
ROUTE = (86, 86, 120)
SOLID_LINE = (235, 235, 235)
DASHED_LINE = (170, 170, 170)
VEHICLE = (60, 110, 220)
EGO = (60, 200, 70)
EGO_CRASHED = (230, 40, 40)


def render_birdeye(
    world: WorldState, size_hw: tuple[int, int] = (128, 128), pixels_per_meter: float = 3.0
) -> np.ndarray:
    """An RGB uint8 image (H, W, 3) of the road, route, markings, traffic and ego."""
    height, width = size_hw
    image = np.empty((height, width, 3), dtype=np.uint8)
    image[:] = GRASS
    project = Projector(world, size_hw, pixels_per_meter)
    cv2.fillPoly(image, project.polygons(world.road.lane_polygons), ROAD, cv2.LINE_AA, SHIFT)
    if len(world.route.polyline) > 1:
        width_px = max(int(round(1.0 * pixels_per_meter)), 1)
        cv2.polylines(image, [project(world.route.polyline)], False, ROUTE, width_px, cv2.LINE_AA, SHIFT)
    markings = world.road.markings
    if len(markings):
        for kind, colour in ((MARKING_SOLID, SOLID_LINE), (1, DASHED_LINE)):
            chosen = markings[world.road.marking_kinds == kind]
            if len(chosen):
                lines = list(project(chosen))
                cv2.polylines(image, lines, False, colour, 1, cv2.LINE_AA, SHIFT)
    cv2.fillPoly(image, project.vehicles(world.vehicles), VEHICLE, cv2.LINE_AA, SHIFT)
    ego = world.ego
    ego_box = np.array([[*ego.position, ego.heading, ego.length_m, ego.width_m]])
    colour = EGO_CRASHED if world.events.collided else EGO
    cv2.fillPoly(image, list(project(box_corners(ego_box))), colour, cv2.LINE_AA, SHIFT)
    return image


class BirdEye(Sensor):
    """RGB bird's-eye image, channels last ``(size, size, 3)``.

    :param size: image height and width in pixels.
    :param pixels_per_meter: resolution.
    """

    name = "birdeye"

    def __init__(self, *, size: int = 128, pixels_per_meter: float = 3.0) -> None:
        if size < 8 or pixels_per_meter <= 0:
            raise ValueError("birdeye needs size >= 8 and pixels_per_meter > 0")
        self.size, self.ppm = int(size), float(pixels_per_meter)
        self._space = spaces.Box(0, 255, shape=(self.size, self.size, 3), dtype=np.uint8)

    @property
    def space(self) -> spaces.Box:
        return self._space

    def observe(self, world: WorldState) -> np.ndarray:
        return render_birdeye(world, (self.size, self.size), self.ppm)
