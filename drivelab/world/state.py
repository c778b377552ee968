"""WorldState: the plain snapshot every sensor, reward term and metric reads.

Backends export one per step; nothing downstream ever touches simulator objects. All
coordinates are world-frame metres (x forward along the road at spawn, y to the right as in
highway-env), angles in radians, speeds in m/s.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

# Columns of ``WorldState.vehicles``.
VEHICLE_COLUMNS = ("x", "y", "heading", "speed", "length", "width")

# Traffic-light states of ``WorldState.traffic_lights[:, 3]``.
LIGHT_GREEN, LIGHT_YELLOW, LIGHT_RED = 0, 1, 2

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
    crossings: np.ndarray = field(default_factory=lambda: np.zeros((0, 5)))  # zebra crossings (C, 5):
    # centre x, y, heading (the direction pedestrians walk), length (across the road), width

    # geometry its readers derive from this immutable map, built once by ``derived``
    derived_cache: dict = field(default_factory=dict, compare=False, repr=False)

    def derived(self, key: object, build: Callable[[RoadMap], object]) -> object:
        """``build(self)``, computed on the first call with ``key`` and kept on this map."""
        if key not in self.derived_cache:
            self.derived_cache[key] = build(self)
        return self.derived_cache[key]

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
    stations_m: np.ndarray | None = None  # (K,) arc length of each polyline point (computed if None)
    closed: bool = False  # a circuit: arc lengths wrap round the lap

    @property
    def remaining_m(self) -> float:
        return max(self.length_m - self.progress_m, 0.0)

    def poses_at(self, distances_m: np.ndarray | float) -> tuple[np.ndarray, np.ndarray]:
        """Points (..., 2) and headings (...) at arc lengths along the polyline: clamped to its
        ends (so a finished route repeats its last point), wrapped round the lap on a circuit."""
        stations = stations_of(self.polyline) if self.stations_m is None else self.stations_m
        distances = np.asarray(distances_m, dtype=float)
        if self.closed and stations[-1] > 0:
            distances = np.mod(distances, stations[-1])
        distances = np.clip(distances, 0.0, stations[-1])
        segment = np.clip(np.searchsorted(stations, distances, side="right") - 1, 0, len(stations) - 2)
        start, end = self.polyline[segment], self.polyline[segment + 1]
        span = np.maximum(stations[segment + 1] - stations[segment], 1e-12)
        fraction = ((distances - stations[segment]) / span)[..., None]
        delta = end - start
        return start + fraction * delta, np.arctan2(delta[..., 1], delta[..., 0])


def stations_of(polyline: np.ndarray) -> np.ndarray:
    """Arc length (P,) of each point of a polyline (P, 2) from its first."""
    steps = np.linalg.norm(np.diff(np.asarray(polyline, dtype=float), axis=0), axis=1)
    return np.r_[0.0, np.cumsum(steps)]


@dataclass(frozen=True)
class Events:
    """What happened during the last step."""

    collided: bool = False
    collision_with: str = ""  # "vehicle", "pedestrian", "object" or "" when no collision
    off_road: bool = False
    arrived: bool = False  # the scenario's goal was reached (intersection crossed, merge done, ...)
    red_light_crossed: bool = False
    blocked: bool = False  # stopped for longer than the scenario allows
    off_route: bool = False  # farther from the planned route than the scenario allows


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
    # one row per controlled approach: stop-line centre x, y, the approach's heading, LIGHT_* state
    traffic_lights: np.ndarray = field(default_factory=lambda: np.zeros((0, 4)))
    # (P, 6) pedestrians, the same columns as ``vehicles`` (heading = walking direction)
    pedestrians: np.ndarray = field(default_factory=lambda: np.zeros((0, 6)))
    max_speed_mps: float = 40.0
    speed_limit_mps: float = 30.0
    # (N, 2) where each of ``vehicles`` is headed: the end of its planned route (highway-env's
    # ``Vehicle.destination``), its own position when it has none; None: no vehicle's is known
    vehicle_destinations: np.ndarray | None = None
    # (N,) each of ``vehicles``' acceleration along its heading in the last simulation frame (m/s²,
    # highway-env's ``Vehicle.action["acceleration"]`` after its limits); None: none is known
    vehicle_accelerations: np.ndarray | None = None

    def destinations(self) -> np.ndarray:
        """(N, 2) ``vehicle_destinations``, the vehicles' own positions where it is None."""
        if self.vehicle_destinations is None:
            return np.asarray(self.vehicles, dtype=float).reshape(-1, 6)[:, :2].copy()
        return np.asarray(self.vehicle_destinations, dtype=float).reshape(-1, 2)

    def accelerations(self) -> np.ndarray:
        """(N,) ``vehicle_accelerations``, zeros where it is None."""
        if self.vehicle_accelerations is None:
            return np.zeros(np.asarray(self.vehicles).reshape(-1, 6).shape[0])
        return np.asarray(self.vehicle_accelerations, dtype=float).reshape(-1)

    def road_users(self) -> np.ndarray:
        """(N + P, 6) every body on the road besides the ego: vehicles, then pedestrians."""
        if len(self.pedestrians) == 0:
            return self.vehicles
        return np.concatenate([np.asarray(self.vehicles).reshape(-1, 6), self.pedestrians])

    def light_ahead(self, max_distance_m: float) -> tuple[int, float] | None:
        """(LIGHT_* state, metres) of the nearest traffic light whose stop line is ahead of the ego
        within ``max_distance_m``, in its lane and facing its way (approach heading within 45°)."""
        lights = self.traffic_lights
        if len(lights) == 0:
            return None
        ego = self.ego
        cos_h, sin_h = np.cos(ego.heading), np.sin(ego.heading)
        delta = lights[:, :2] - ego.position
        ahead = delta[:, 0] * cos_h + delta[:, 1] * sin_h
        beside = -delta[:, 0] * sin_h + delta[:, 1] * cos_h
        aligned = np.abs(np.angle(np.exp(1j * (lights[:, 2] - ego.heading)))) < np.pi / 4
        mine = aligned & (ahead > 0) & (ahead <= max_distance_m) & (np.abs(beside) < ego.lane_width_m / 2)
        if not mine.any():
            return None
        nearest = int(np.flatnonzero(mine)[np.argmin(ahead[mine])])
        return int(lights[nearest, 3]), float(ahead[nearest])
