"""WorldState: the plain snapshot every sensor, reward term and metric reads.

Backends export one per step; nothing downstream ever touches simulator objects. All
coordinates are world-frame metres (x forward along the road at spawn, y to the right as in
highway-env), angles in radians, speeds in m/s.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

# Columns of ``WorldState.vehicles``.
VEHICLE_COLUMNS = ("x", "y", "heading", "speed", "length", "width")

# Marking kinds of ``RoadMap.marking_kinds`` (same numbering as highway-env's LineType).
MARKING_NONE, MARKING_DASHED, MARKING_SOLID = 0, 1, 2


@dataclass(frozen=True)
class RoadMap:
    """Static road geometry, converted to arrays once per reset.

    :param lane_polygons: one (K, 2) closed outline per lane (left edge then right edge reversed).
    :param lane_centerlines: one (K, 2) polyline per lane, sampled every few metres.
    :param lane_widths_m: (L,) lane widths.
    :param markings: (M, 2, 2) line segments painted on the road.
    :param marking_kinds: (M,) ``MARKING_DASHED`` or ``MARKING_SOLID``.
    :param edges: (E, 2, 2) segments of the drivable area's border (solid outer lines); LiDAR hits these.
    :param guide_lines: (K, 2) polylines of painted yellow guide lines (follow-line circuits); the
        camera draws them yellow, other sensors ignore them.
    """

    lane_polygons: tuple[np.ndarray, ...]
    lane_centerlines: tuple[np.ndarray, ...]
    lane_widths_m: np.ndarray
    markings: np.ndarray
    marking_kinds: np.ndarray
    edges: np.ndarray
    guide_lines: tuple[np.ndarray, ...] = ()

    @staticmethod
    def empty() -> RoadMap:
        """A map with no road at all (useful for hand-built test worlds)."""
        no_segments = np.zeros((0, 2, 2))
        return RoadMap((), (), np.zeros(0), no_segments, np.zeros(0, dtype=int), no_segments)


@dataclass(frozen=True)
class Ego:
    """The controlled vehicle and where it stands relative to its lane and route."""

    position: np.ndarray  # (2,) metres
    heading: float  # rad
    speed_mps: float
    steering: float = 0.0  # rad, last applied front-wheel angle
    acceleration_mps2: float = 0.0  # last applied
    length_m: float = 5.0
    width_m: float = 2.0
    lane_id: int = 0  # index of the lane among its parallel lanes, 0 = leftmost
    lane_count: int = 1  # number of parallel lanes on the current road
    target_lane_id: int = 0  # lane the ego's lane-keeping controller steers to (= lane_id without one)
    lane_width_m: float = 4.0
    lateral_offset_m: float = 0.0  # signed distance from the lane centre, + to the right
    lane_heading: float = 0.0  # rad, lane direction at the ego's position
    lane_curvature: float = 0.0  # 1/m at the ego's position
    on_road: bool = True
    in_intersection: bool = False

    @property
    def forward_speed_mps(self) -> float:
        """Speed projected on the lane direction."""
        return self.speed_mps * float(np.cos(self.heading - self.lane_heading))


@dataclass(frozen=True)
class Route:
    """The ego's planned path and how far along it the ego is."""

    polyline: np.ndarray  # (K, 2) from the ego's lane start to the destination (or look-ahead)
    progress_m: float = 0.0  # arc length travelled along the polyline
    length_m: float = 0.0  # total arc length; ``inf`` where the road does not end

    @property
    def remaining_m(self) -> float:
        return max(self.length_m - self.progress_m, 0.0)


@dataclass(frozen=True)
class Events:
    """What happened during the last step."""

    collided: bool = False
    collision_with: str = ""  # "vehicle", "object" or "" when no collision
    off_road: bool = False
    arrived: bool = False  # the scenario's goal was reached (intersection crossed, merge done, ...)
    red_light_crossed: bool = False


@dataclass(frozen=True)
class WorldState:
    """One snapshot of the world, exported by a backend after each step."""

    time_s: float
    dt_s: float  # policy step duration
    ego: Ego
    vehicles: np.ndarray  # (N, 6) other vehicles, columns ``VEHICLE_COLUMNS``
    road: RoadMap
    route: Route
    events: Events = field(default_factory=Events)
    traffic_lights: np.ndarray = field(default_factory=lambda: np.zeros((0, 4)))  # x, y, heading, state
    max_speed_mps: float = 40.0
    speed_limit_mps: float = 30.0
