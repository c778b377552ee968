"""The single-world reward terms as they were before the batch-first rewrite (issue 16), kept as
the reference the batched terms must reproduce: ``term(prev, world, control) -> float``.

Each reads only WorldStates (the one before the step and the one after) and returns an
unweighted value; presets and users weight them (see ``drivelab.rewards.shapers``).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from drivelab.world.geometry import ego_frame
from drivelab.world.pinhole import LANE_CAMERA, LANE_ROWS_M, LINE_CAMERA, LINE_ROWS_M
from drivelab.world.road_geometry import GuideSegments, polyline_segments
from drivelab.world.state import LIGHT_GREEN, WorldState

Term = Callable[[WorldState, WorldState, object], float]
LEGACY_TERMS: dict[str, Term] = {}


def term(function: Term) -> Term:
    """Register ``function`` under its own name."""
    LEGACY_TERMS[function.__name__] = function
    return function


def _lateral_fraction(world: WorldState) -> float:
    """|lateral offset| as a fraction of half the lane width, in [0, 1]."""
    half_width = max(world.ego.lane_width_m / 2, 1e-6)
    return float(min(abs(world.ego.lateral_offset_m) / half_width, 1.0))


# --- highway-env's own reward (HighwayEnv._rewards) -------------------------------------------
@term
def collision(prev: WorldState, world: WorldState, control) -> float:
    """1 when the ego collided during the step."""
    return float(world.events.collided)


@term
def right_lane(prev: WorldState, world: WorldState, control) -> float:
    """Target lane index over the rightmost index: 1 on the rightmost lane, 0 on the leftmost."""
    return world.ego.target_lane_id / max(world.ego.lane_count - 1, 1)


@term
def high_speed(prev: WorldState, world: WorldState, control) -> float:
    """Forward speed mapped linearly from [2/3, 1]·speed limit to [0, 1], clipped.

    On highway (limit 30 m/s) this is highway-env's ``reward_speed_range`` [20, 30].
    """
    low, high = world.speed_limit_mps * 2 / 3, world.speed_limit_mps
    return float(np.clip((world.ego.forward_speed_mps - low) / (high - low), 0.0, 1.0))


@term
def cruise_speed(prev: WorldState, world: WorldState, control) -> float:
    """Forward speed mapped linearly from [2/3, 5/6]·speed limit to [0, 1], clipped."""
    low, high = world.speed_limit_mps * 2 / 3, world.speed_limit_mps * 5 / 6
    return float(np.clip((world.ego.forward_speed_mps - low) / (high - low), 0.0, 1.0))


@term
def on_road(prev: WorldState, world: WorldState, control) -> float:
    """1 while the ego is on a lane."""
    return float(world.ego.on_road)


@term
def lane_change(prev: WorldState, world: WorldState, control) -> float:
    """1 for the meta-actions LANE_LEFT (0) and LANE_RIGHT (2), 0 otherwise and for continuous
    controls (added with the term, issue 51: its one-world reference)."""
    if control is None or np.ndim(control) != 0:
        return 0.0
    return float(int(control) in (0, 2))


# --- seed 003, the MetaDrive course reward ----------------------------------------------------
@term
def progress_lateral(prev: WorldState, world: WorldState, control) -> float:
    """Metres of route progress weighted by lane centring: progress · (1 − |lateral|³) (seed 003)."""
    progress_m = world.route.progress_m - prev.route.progress_m
    return progress_m * (1.0 - _lateral_fraction(world) ** 3)


@term
def speed(prev: WorldState, world: WorldState, control) -> float:
    """Speed over 70 % of the top speed, clipped to 1, halved inside junctions (seed 003)."""
    value = min(world.ego.speed_mps / (0.7 * world.max_speed_mps), 1.0)
    return value / 2 if world.ego.in_intersection else value


@term
def crash(prev: WorldState, world: WorldState, control) -> float:
    """1 on a collision with anything (MetaDrive's crash penalty is weighted −5)."""
    return float(world.events.collided)


@term
def off_road(prev: WorldState, world: WorldState, control) -> float:
    """1 when the ego has left the road."""
    return float(world.events.off_road)


@term
def arrival(prev: WorldState, world: WorldState, control) -> float:
    """1 when the scenario's goal is reached."""
    return float(world.events.arrived)


# --- seed 003, the safety-focused table used with SB3 DQN (values are the table's) ------------
@term
def centered(prev: WorldState, world: WorldState, control) -> float:
    """+0.3 while within 0.5 m of the lane centre."""
    return 0.3 if abs(world.ego.lateral_offset_m) < 0.5 else 0.0


OVERSPEED_MPS = 20 / 3.6  # the seed capped its agent at 20 km/h


@term
def overspeed(prev: WorldState, world: WorldState, control) -> float:
    """−1.0 above 20 km/h (the seed's cap; re-weight or drop it on fast roads)."""
    return -1.0 if world.ego.speed_mps > OVERSPEED_MPS else 0.0


CURVE_CURVATURE = 0.01  # 1/m: radius under 100 m counts as a curve
CURVE_LATERAL_ACCEL_MPS2 = 3.0  # comfortable lateral acceleration that sets the safe curve speed


@term
def curve_control(prev: WorldState, world: WorldState, control) -> float:
    """In curves: +0.2 below the safe speed sqrt(a_lat/|κ|) or while slowing down, else −0.5."""
    curvature = abs(world.ego.lane_curvature)
    if curvature < CURVE_CURVATURE:
        return 0.0
    safe_speed = np.sqrt(CURVE_LATERAL_ACCEL_MPS2 / curvature)
    slowing = world.ego.speed_mps < prev.ego.speed_mps
    return 0.2 if world.ego.speed_mps <= safe_speed or slowing else -0.5


@term
def intersection_heading(prev: WorldState, world: WorldState, control) -> float:
    """In junctions: +0.3 when heading within 15° of the lane direction, else −0.5."""
    if not world.ego.in_intersection:
        return 0.0
    error = abs(np.angle(np.exp(1j * (world.ego.heading - world.ego.lane_heading))))
    return 0.3 if error < np.radians(15) else -0.5


@term
def destination_proximity(prev: WorldState, world: WorldState, control) -> float:
    """+0.4 within 50 m of the route's end (routes that never end give 0)."""
    return 0.4 if np.isfinite(world.route.length_m) and world.route.remaining_m < 50 else 0.0


@term
def steering_smoothness(prev: WorldState, world: WorldState, control) -> float:
    """+0.1 for a steering change under 0.05 rad in a step, −0.2 over 0.2 rad."""
    change = abs(world.ego.steering - prev.ego.steering)
    return 0.1 if change < 0.05 else (-0.2 if change > 0.2 else 0.0)


def _vehicles_alongside_ahead(world: WorldState) -> tuple[int, float]:
    """Vehicles in the next lanes within 30 m ahead, and the nearest vehicle's distance."""
    if len(world.vehicles) == 0:
        return 0, np.inf
    delta = world.vehicles[:, :2] - world.ego.position
    cos_h, sin_h = np.cos(world.ego.heading), np.sin(world.ego.heading)
    ahead = delta[:, 0] * cos_h + delta[:, 1] * sin_h
    beside = np.abs(-delta[:, 0] * sin_h + delta[:, 1] * cos_h)
    count = int(np.sum((ahead > 0) & (ahead < 30) & (beside > 1.5) & (beside < 8)))
    return count, float(np.min(np.hypot(delta[:, 0], delta[:, 1])))


@term
def overtaking(prev: WorldState, world: WorldState, control) -> float:
    """When a vehicle in a next lane goes from ahead to behind: +0.2 if passed with > 3 m
    clearance, −0.5 if closer (the seed's LiDAR-based rule, read from the WorldState)."""
    before, _ = _vehicles_alongside_ahead(prev)
    after, nearest_m = _vehicles_alongside_ahead(world)
    if after >= before:
        return 0.0
    return 0.2 if nearest_m > 3.0 else -0.5


@term
def sidewalk_crash(prev: WorldState, world: WorldState, control) -> float:
    """−4.0 when the ego leaves the road."""
    return -4.0 if world.events.off_road else 0.0


# --- seed 000 (RLAD) trains with CARLA-Roach's reward (shared/notes/RLAD-NOTES.md) -----------
ROACH_MAX_SPEED_MPS = 6.0
ROACH_STEER_RAD = np.pi / 4  # steering is compared as the normalised command (highway-env: ±45°)


def _hazard_speed(distance_m: float, stop_distance_m: float) -> float:
    """Roach: v_max · clip(d − d0, 0, 5) / 5, a speed that falls to 0 at d0 from the hazard."""
    return ROACH_MAX_SPEED_MPS * float(np.clip(distance_m - stop_distance_m, 0.0, 5.0)) / 5.0


def roach_desired_speed(world: WorldState) -> float:
    """v* = min(v_max, v_vehicle, v_pedestrian, v_light): slow for a vehicle within 9.5 m and ±45°
    ahead (d0 = 8 m), for a pedestrian in the ego's path (ahead, within a lane's half width of its
    axis; d0 = 6 m) and for a red or yellow light whose stop line is ahead in the ego's lane
    (d0 = 5 m)."""
    desired = ROACH_MAX_SPEED_MPS
    ego = world.ego
    if len(world.vehicles):
        local = ego_frame(world.vehicles[:, :2], ego.position, ego.heading)
        distance = np.hypot(local[:, 0], local[:, 1])
        ahead = (distance < 9.5) & (np.abs(np.arctan2(local[:, 1], local[:, 0])) <= np.pi / 4)
        if ahead.any():
            desired = min(desired, _hazard_speed(float(distance[ahead].min()), 8.0))
    if len(world.pedestrians):
        local = ego_frame(world.pedestrians[:, :2], ego.position, ego.heading)
        in_path = (local[:, 0] > 0) & (np.abs(local[:, 1]) < ego.lane_width_m / 2)
        if in_path.any():
            desired = min(desired, _hazard_speed(float(local[in_path, 0].min()), 6.0))
    light = world.light_ahead(max_distance_m=np.inf)
    if light is not None and light[0] != LIGHT_GREEN:
        desired = min(desired, _hazard_speed(light[1], 5.0))
    return desired


def _route_pose(world: WorldState) -> tuple[np.ndarray, float]:
    point, heading = world.route.poses_at(world.route.progress_m)
    return point, float(heading)


@term
def roach_speed(prev: WorldState, world: WorldState, control) -> float:
    """1 − |v − v*| / v_max: drive at the hazard-aware desired speed."""
    return 1.0 - abs(world.ego.speed_mps - roach_desired_speed(world)) / ROACH_MAX_SPEED_MPS


@term
def roach_position(prev: WorldState, world: WorldState, control) -> float:
    """−(distance from the route, m) / 2."""
    point, _ = _route_pose(world)
    return -float(np.linalg.norm(world.ego.position - point)) / 2.0


@term
def roach_rotation(prev: WorldState, world: WorldState, control) -> float:
    """−|heading error against the route| (rad)."""
    _, heading = _route_pose(world)
    return -abs(float(np.angle(np.exp(1j * (world.ego.heading - heading)))))


@term
def roach_action(prev: WorldState, world: WorldState, control) -> float:
    """−0.1 when the normalised steering changed by more than 0.01 in the step."""
    change = abs(world.ego.steering - prev.ego.steering) / ROACH_STEER_RAD
    return -0.1 if change > 0.01 else 0.0


@term
def roach_terminal(prev: WorldState, world: WorldState, control) -> float:
    """−1 when the episode fails (collision, red light run, off-road, blocked, off the route), and
    a further −speed (m/s) for a collision or a red light run."""
    events = world.events
    failed = (
        events.collided or events.red_light_crossed or events.off_road or events.blocked or events.off_route
    )
    value = -1.0 if failed else 0.0
    if events.collided or events.red_light_crossed:
        value -= world.ego.speed_mps
    return value


# --- seed 004, follow-line (eqs. 2, 3) and follow-lane (eq. 4) ---------------------------------
# Both read where the painted line / the lane centre crosses the perception rows of the camera,
# projected from the WorldState's geometry (ground truth), in pixels of the seed's own frame
# width (640 for the line, 1024 for the lane) so that its pixel bands apply unchanged.
LINE_BAND_EDGES_PX = np.array([38.0, 2 * 38, 3 * 38, 5 * 38, 6 * 38])
# the extracted fourth value reads "39"; we take 3 so that the values keep falling (15, 12, 10, 3, 1)
LINE_BAND_VALUES = np.array([15.0, 12.0, 10.0, 3.0, 1.0, -100.0])
STEERING_BASE = 1.02  # the seed's λ
LANE_BAND_EDGES_PX = np.array([15.0, 2 * 15, 3 * 20, 4 * 20])  # as extracted: 15, 30, 60, 80
LANE_BAND_VALUES = np.array([10.0, 5.0, 2.5, 1.0, -10.0])
LANE_ALIGNED_DEG = 6.0  # the seed's ζ
FULL_LOCK_DEG = 45.0  # normalised steering 1 (highway-env's ContinuousAction)


def _crossing_columns(world: WorldState, segments: np.ndarray, model, distances_m) -> np.ndarray:
    """Image columns where ``segments`` cross the ground rows ``distances_m`` ahead (nan: not in view)."""
    distances = np.asarray(distances_m, dtype=float)
    lateral = lateral_at_distances(world, segments, distances)
    columns = model.project_ground(np.stack([distances, np.nan_to_num(lateral)], axis=1))[:, 0]
    inside = np.isfinite(lateral) & (columns >= -0.5) & (columns <= model.width - 0.5)
    return np.where(inside, columns, np.nan)


def _steering_deg(control) -> float:
    values = np.asarray(control, dtype=float).reshape(-1)
    return float(values[1]) * FULL_LOCK_DEG if values.size == 2 else 0.0


@term
def line_centring(prev: WorldState, world: WorldState, control) -> float:
    """Σ_j f(C_j) over the 4 line rows: 15 … 1 as the line's centre moves away from the image centre
    in 38 px bands (of 640), −100 for a row where the line is out of view (seed 004, eq. 2)."""
    guide = GuideSegments(world.road).segments
    columns = _crossing_columns(world, guide, LINE_CAMERA, LINE_ROWS_M)
    offset_px = np.abs(columns - LINE_CAMERA.centre[0]) * 640 / LINE_CAMERA.width
    values = LINE_BAND_VALUES[np.searchsorted(LINE_BAND_EDGES_PX, np.nan_to_num(offset_px, nan=1e9), "right")]
    return float(values.sum())


@term
def speed_mps(prev: WorldState, world: WorldState, control) -> float:
    """The ego's speed in m/s (seed 004, eq. 3: ``+ v``)."""
    return world.ego.speed_mps


@term
def steering_power(prev: WorldState, world: WorldState, control) -> float:
    """λ^|α| with λ = 1.02 and α the commanded front-wheel angle in degrees (seed 004, eq. 3; the
    extracted formula is garbled: we read it as a penalty growing with the steering angle)."""
    return STEERING_BASE ** abs(_steering_deg(control))


@term
def lane_keeping(prev: WorldState, world: WorldState, control) -> float:
    """Seed 004, eq. 4: f*(C) by the lane centre's offset C from the image centre (10, 5, 2.5, 1, −10 in
    bands 15/30/60/80 px of 1024), doubled when the lane is within ζ = 6° of the image vertical and
    the action goes straight, halved when aligned but steering (the extracted text is garbled there;
    this is our reading of "higher reward when aligned and going straight")."""
    centre = polyline_segments(np.asarray(world.route.polyline, dtype=float))
    columns = _crossing_columns(world, centre, LANE_CAMERA, LANE_ROWS_M)
    seen = np.isfinite(columns)
    if not seen.any():
        return float(LANE_BAND_VALUES[-1])
    offset_px = abs(np.mean(columns[seen]) - LANE_CAMERA.centre[0]) * 1024 / LANE_CAMERA.width
    value = float(LANE_BAND_VALUES[np.searchsorted(LANE_BAND_EDGES_PX, offset_px, "right")])
    if seen.sum() < 2:
        return value
    # g*: angle between the image vertical (p1 → p2) and the lane direction (p3 → p4), nearest and
    # farthest rows where the centre is seen
    rows = LANE_CAMERA.row_of_distance(np.asarray(LANE_ROWS_M)[seen])
    near, far = np.array([columns[seen][0], rows[0]]), np.array([columns[seen][-1], rows[-1]])
    angle_deg = abs(np.degrees(np.arctan2(far[0] - near[0], near[1] - far[1])))
    if angle_deg > LANE_ALIGNED_DEG:
        return value
    return 2.0 * value if abs(_steering_deg(control)) < 1e-6 else value / 2.0


def lateral_at_distances(world: WorldState, segments: np.ndarray, distances_m: np.ndarray) -> np.ndarray:
    """perception/camera.py's single-world crossing search as it was."""
    distances = np.asarray(distances_m, dtype=float)
    if len(segments) == 0:
        return np.full(distances.shape, np.nan)
    local = ego_frame(segments, world.ego.position, world.ego.heading)
    x0, x1 = local[:, 0, 0][None, :], local[:, 1, 0][None, :]
    y0, y1 = local[:, 0, 1][None, :], local[:, 1, 1][None, :]
    d = distances.reshape(-1, 1)
    span = np.where(np.abs(x1 - x0) < 1e-12, np.nan, x1 - x0)
    t = (d - x0) / span
    y = np.where((t >= 0) & (t <= 1), y0 + t * (y1 - y0), np.nan)
    y = np.where(np.isnan(y), np.inf, y)
    best = np.take_along_axis(y, np.argmin(np.abs(y), axis=1)[:, None], axis=1)[:, 0]
    return np.where(np.isfinite(best), best, np.nan).reshape(distances.shape)


# --- MetaDrive's default reward (issue 18: written one world at a time, as the reference) ------
def _metadrive_terminal(world: WorldState) -> str:
    """The terminal event that replaces the step reward, in MetaDrive's order, or ""."""
    events = world.events
    if events.arrived:
        return "success"
    if events.off_road:
        return "out_of_road"
    return "crash" if events.collided else ""


@term
def metadrive_progress(prev: WorldState, world: WorldState, control) -> float:
    """Route progress of the step in metres, 0 on a terminal step."""
    if _metadrive_terminal(world):
        return 0.0
    return world.route.progress_m - prev.route.progress_m


@term
def metadrive_speed(prev: WorldState, world: WorldState, control) -> float:
    """Speed over 80 km/h, 0 on a terminal step."""
    return 0.0 if _metadrive_terminal(world) else world.ego.speed_mps / (80 / 3.6)


@term
def metadrive_success(prev: WorldState, world: WorldState, control) -> float:
    return float(_metadrive_terminal(world) == "success")


@term
def metadrive_out_of_road(prev: WorldState, world: WorldState, control) -> float:
    return float(_metadrive_terminal(world) == "out_of_road")


@term
def metadrive_crash(prev: WorldState, world: WorldState, control) -> float:
    return float(_metadrive_terminal(world) == "crash")
