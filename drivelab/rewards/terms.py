"""Reward terms: small pure functions ``term(prev, batch, control) -> (K,)``.

Each reads only WorldBatches (the K worlds before the step and after it) and the controls that
were applied, and returns one unweighted value per world as a float ``(K,)`` array; presets and
users weight them (see ``drivelab.rewards.shapers``). ``control`` is ``(K,)`` meta-action indices
or ``(K, 2)`` normalised ``[acceleration, steering]`` in [-1, 1] (highway-env's order); terms
that do not read it accept None. All arithmetic is over the K worlds at once.
"""

from __future__ import annotations

import functools
from collections.abc import Callable

import numpy as np
from numba import njit

from drivelab.world.batch import WorldBatch
from drivelab.world.geometry import FULL_LOCK_DEG, FULL_LOCK_RAD, ROACH_MAX_SPEED_MPS
from drivelab.world.pinhole import LANE_CAMERA, LANE_ROWS_M, LINE_CAMERA, LINE_ROWS_M, PinholeModel
from drivelab.world.road_geometry import guide_segment_sets, segment_columns_into
from drivelab.world.scenario import META_ACTIONS
from drivelab.world.state import LIGHT_GREEN, WorldState

Term = Callable[[WorldBatch, WorldBatch, np.ndarray | None], np.ndarray]
TERMS: dict[str, Term] = {}


def term(function: Term) -> Term:
    """Register ``function`` under its own name."""
    TERMS[function.__name__] = function
    return function


def _flag(values: np.ndarray) -> np.ndarray:
    return np.asarray(values, dtype=float)


def _lateral_fraction(batch: WorldBatch) -> np.ndarray:
    """(K,) |lateral offset| as a fraction of half the lane width, in [0, 1]."""
    half_width = np.maximum(batch.ego.lane_width_m / 2, 1e-6)
    return np.minimum(np.abs(batch.ego.lateral_offset_m) / half_width, 1.0)


# --- highway-env's own reward (HighwayEnv._rewards) -------------------------------------------
@term
def collision(prev: WorldBatch, batch: WorldBatch, control) -> np.ndarray:
    """1 when the ego collided during the step."""
    return _flag(batch.events.collided)


@term
def right_lane(prev: WorldBatch, batch: WorldBatch, control) -> np.ndarray:
    """Target lane index over the rightmost index: 1 on the rightmost lane, 0 on the leftmost."""
    return batch.ego.target_lane_id / np.maximum(batch.ego.lane_count - 1, 1)


@term
def high_speed(prev: WorldBatch, batch: WorldBatch, control) -> np.ndarray:
    """Forward speed mapped linearly from [2/3, 1]·speed limit to [0, 1], clipped.

    On highway (limit 30 m/s) this is highway-env's ``reward_speed_range`` [20, 30].
    """
    return _speed_fraction(batch, top=1.0)


@term
def cruise_speed(prev: WorldBatch, batch: WorldBatch, control) -> np.ndarray:
    """Forward speed mapped linearly from [2/3, 5/6]·speed limit to [0, 1], clipped: ``high_speed``
    with nothing more paid past 5/6 of the limit (25 m/s on highway), so a policy gains by holding
    that speed (passing slower traffic) and nothing by pressing on to the limit."""
    return _speed_fraction(batch, top=5 / 6)


def _speed_fraction(batch: WorldBatch, top: float) -> np.ndarray:
    """(K,) forward speed mapped linearly from [2/3, top]·speed limit to [0, 1], clipped."""
    low, high = batch.speed_limit_mps * 2 / 3, batch.speed_limit_mps * top
    return np.clip((batch.ego.forward_speed_mps - low) / (high - low), 0.0, 1.0)


@term
def on_road(prev: WorldBatch, batch: WorldBatch, control) -> np.ndarray:
    """1 while the ego is on a lane."""
    return _flag(batch.ego.on_road)


LANE_CHANGES = np.array([META_ACTIONS.index("LANE_LEFT"), META_ACTIONS.index("LANE_RIGHT")])


@term
def lane_change(prev: WorldBatch, batch: WorldBatch, control) -> np.ndarray:
    """1 when the step's meta-action is a lane change (LANE_LEFT or LANE_RIGHT): highway-env's
    ``lane_change_reward`` of its merge and roundabout (weight it −0.05 as they do); 0 for the
    other meta-actions and for continuous controls."""
    if control is None or np.ndim(control) != 1:
        return np.zeros(batch.num_worlds)
    return _flag(np.isin(control, LANE_CHANGES))


# --- the MetaDrive study, the MetaDrive course reward ----------------------------------------------------
@term
def progress_lateral(prev: WorldBatch, batch: WorldBatch, control) -> np.ndarray:
    """Metres of route progress weighted by lane centring, progress · (1 − |lateral|³) (MetaDrive study)."""
    progress_m = batch.route.progress_m - prev.route.progress_m
    return progress_m * (1.0 - _lateral_fraction(batch) ** 3)


@term
def speed(prev: WorldBatch, batch: WorldBatch, control) -> np.ndarray:
    """Speed over 70 % of the top speed, clipped to 1, halved inside junctions (the MetaDrive study)."""
    value = np.minimum(batch.ego.speed_mps / (0.7 * batch.max_speed_mps), 1.0)
    return np.where(batch.ego.in_intersection, value / 2, value)


@term
def crash(prev: WorldBatch, batch: WorldBatch, control) -> np.ndarray:
    """1 on a collision with anything (MetaDrive's crash penalty is weighted −5)."""
    return _flag(batch.events.collided)


@term
def off_road(prev: WorldBatch, batch: WorldBatch, control) -> np.ndarray:
    """1 when the ego has left the road."""
    return _flag(batch.events.off_road)


@term
def arrival(prev: WorldBatch, batch: WorldBatch, control) -> np.ndarray:
    """1 when the scenario's goal is reached."""
    return _flag(batch.events.arrived)


# --- MetaDrive's default reward (metadrive/envs/metadrive_env.py, reward_function) ---------
# r = 1.0 · Δs + 0.1 · speed / 80 km/h per step; a terminal event replaces it, checked in
# MetaDrive's order: +10 arrival, −5 out of road, −5 crash (weights in the "metadrive" preset)
METADRIVE_MAX_SPEED_MPS = 80 / 3.6  # MetaDrive's ego's max_speed_km_h (cmp/vehicle/vehicle_type.py)


def _metadrive_events(batch: WorldBatch) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(K,) each: arrived; out of road and not arrived; crashed and neither (MetaDrive's order)."""
    events = batch.events
    arrived = events.arrived
    out_of_road = events.off_road & ~arrived
    crashed = events.collided & ~arrived & ~events.off_road
    return arrived, out_of_road, crashed


def _metadrive_running(batch: WorldBatch) -> np.ndarray:
    """(K,) 1.0 where no terminal event replaces the step reward, else 0.0."""
    arrived, out_of_road, crashed = _metadrive_events(batch)
    return _flag(~(arrived | out_of_road | crashed))


@term
def metadrive_progress(prev: WorldBatch, batch: WorldBatch, control) -> np.ndarray:
    """Metres of route progress in the step (MetaDrive's driving_reward term, use_lateral_reward
    off), 0 on a terminal step."""
    return (batch.route.progress_m - prev.route.progress_m) * _metadrive_running(batch)


@term
def metadrive_speed(prev: WorldBatch, batch: WorldBatch, control) -> np.ndarray:
    """Speed over MetaDrive's 80 km/h top speed (its speed_reward term), 0 on a terminal step."""
    return batch.ego.speed_mps / METADRIVE_MAX_SPEED_MPS * _metadrive_running(batch)


@term
def metadrive_success(prev: WorldBatch, batch: WorldBatch, control) -> np.ndarray:
    """1 on arrival at the destination (MetaDrive's success_reward)."""
    return _flag(_metadrive_events(batch)[0])


@term
def metadrive_out_of_road(prev: WorldBatch, batch: WorldBatch, control) -> np.ndarray:
    """1 when out of road without arriving (MetaDrive's out_of_road_penalty)."""
    return _flag(_metadrive_events(batch)[1])


@term
def metadrive_crash(prev: WorldBatch, batch: WorldBatch, control) -> np.ndarray:
    """1 on a collision, neither arrived nor out of road (MetaDrive's crash_vehicle_penalty)."""
    return _flag(_metadrive_events(batch)[2])


# --- the MetaDrive study, the safety-focused table used with SB3 DQN (values are the table's) ------------
@term
def centered(prev: WorldBatch, batch: WorldBatch, control) -> np.ndarray:
    """+0.3 while within 0.5 m of the lane centre."""
    return np.where(np.abs(batch.ego.lateral_offset_m) < 0.5, 0.3, 0.0)


OVERSPEED_MPS = 20 / 3.6  # the seed capped its agent at 20 km/h


@term
def overspeed(prev: WorldBatch, batch: WorldBatch, control) -> np.ndarray:
    """−1.0 above 20 km/h (the seed's cap; re-weight or drop it on fast roads)."""
    return np.where(batch.ego.speed_mps > OVERSPEED_MPS, -1.0, 0.0)


CURVE_CURVATURE = 0.01  # 1/m: radius under 100 m counts as a curve
CURVE_LATERAL_ACCEL_MPS2 = 3.0  # comfortable lateral acceleration that sets the safe curve speed


@term
def curve_control(prev: WorldBatch, batch: WorldBatch, control) -> np.ndarray:
    """In curves: +0.2 below the safe speed sqrt(a_lat/|κ|) or while slowing down, else −0.5."""
    curvature = np.abs(batch.ego.lane_curvature)
    in_curve = curvature >= CURVE_CURVATURE
    # straight worlds get a stand-in curvature: their value is 0 whatever the safe speed
    safe_speed = np.sqrt(CURVE_LATERAL_ACCEL_MPS2 / np.where(in_curve, curvature, 1.0))
    speed_mps = batch.ego.speed_mps
    calm = (speed_mps <= safe_speed) | (speed_mps < prev.ego.speed_mps)
    return np.where(in_curve, np.where(calm, 0.2, -0.5), 0.0)


def _heading_error(heading: np.ndarray, reference: np.ndarray) -> np.ndarray:
    """(K,) |heading − reference| wrapped to [0, π]."""
    return np.abs(np.angle(np.exp(1j * (heading - reference))))


@term
def intersection_heading(prev: WorldBatch, batch: WorldBatch, control) -> np.ndarray:
    """In junctions: +0.3 when heading within 15° of the lane direction, else −0.5."""
    aligned = _heading_error(batch.ego.heading, batch.ego.lane_heading) < np.radians(15)
    return np.where(batch.ego.in_intersection, np.where(aligned, 0.3, -0.5), 0.0)


@term
def destination_proximity(prev: WorldBatch, batch: WorldBatch, control) -> np.ndarray:
    """+0.4 within 50 m of the route's end (routes that never end give 0)."""
    near = np.isfinite(batch.route.length_m) & (batch.route.remaining_m < 50)
    return np.where(near, 0.4, 0.0)


@term
def steering_smoothness(prev: WorldBatch, batch: WorldBatch, control) -> np.ndarray:
    """+0.1 for a steering change under 0.05 rad in a step, −0.2 over 0.2 rad."""
    change = np.abs(batch.ego.steering - prev.ego.steering)
    return np.where(change < 0.05, 0.1, np.where(change > 0.2, -0.2, 0.0))


def _vehicles_alongside_ahead(batch: WorldBatch) -> tuple[np.ndarray, np.ndarray]:
    """(K,) vehicles in the next lanes within 30 m ahead, and (K,) the nearest vehicle's distance
    (inf without vehicles)."""
    ego = batch.ego
    delta = batch.vehicles[..., :2] - ego.position[:, None, :]  # (K, N, 2)
    cos_h, sin_h = np.cos(ego.heading)[:, None], np.sin(ego.heading)[:, None]
    ahead = delta[..., 0] * cos_h + delta[..., 1] * sin_h
    beside = np.abs(-delta[..., 0] * sin_h + delta[..., 1] * cos_h)
    alongside = batch.vehicle_valid & (ahead > 0) & (ahead < 30) & (beside > 1.5) & (beside < 8)
    distance = np.where(batch.vehicle_valid, np.hypot(delta[..., 0], delta[..., 1]), np.inf)
    return alongside.sum(axis=1), np.min(distance, axis=1, initial=np.inf)


@term
def overtaking(prev: WorldBatch, batch: WorldBatch, control) -> np.ndarray:
    """When a vehicle in a next lane goes from ahead to behind: +0.2 if passed with > 3 m
    clearance, −0.5 if closer (the seed's LiDAR-based rule, read from the WorldBatch)."""
    before, _ = _vehicles_alongside_ahead(prev)
    after, nearest_m = _vehicles_alongside_ahead(batch)
    return np.where(after >= before, 0.0, np.where(nearest_m > 3.0, 0.2, -0.5))


@term
def sidewalk_crash(prev: WorldBatch, batch: WorldBatch, control) -> np.ndarray:
    """−4.0 when the ego leaves the road."""
    return np.where(batch.events.off_road, -4.0, 0.0)


# --- the RLAD paper (RLAD) trains with CARLA-Roach's reward (shared/notes/RLAD-NOTES.md) -----------
ROACH_STEER_RAD = FULL_LOCK_RAD  # steering is compared as the normalised command (highway-env: ±45°)


def roach_desired_speed(batch: WorldBatch | WorldState) -> np.ndarray:
    """(K,) v* = min(v_max, v_vehicle, v_pedestrian, v_light): slow for a vehicle within 9.5 m and
    ±45° ahead (d0 = 8 m), for a pedestrian in the ego's path (ahead, within a lane's half width of
    its axis; d0 = 6 m) and for a red or yellow light whose stop line is ahead in the ego's lane
    (d0 = 5 m). A WorldState gives its one value as a float."""
    if isinstance(batch, WorldState):
        return float(roach_desired_speed(WorldBatch.stack([batch]))[0])
    ego, (cos_h, sin_h) = batch.ego, batch.heading_cos_sin()
    state, distance_m = batch.light_ahead(max_distance_m=np.inf)
    desired = np.empty(batch.num_worlds)
    _roach_desired_speed(
        batch.vehicles, batch.vehicle_valid, batch.pedestrians, batch.pedestrian_valid, ego.position,
        cos_h, sin_h, ego.lane_width_m, state, distance_m, desired,
    )  # fmt: skip
    return desired


@njit(inline="always")
def _hazard(distance_m, stop_distance_m):
    """Roach: v_max · clip(d − d0, 0, 5) / 5, a speed that falls to 0 at d0 from the hazard."""
    room = distance_m - stop_distance_m
    room = 0.0 if room < 0.0 else (5.0 if room > 5.0 else room)
    return ROACH_MAX_SPEED_MPS * room / 5.0


@njit(cache=True)
def _roach_desired_speed(
    vehicles, vehicle_valid, pedestrians, pedestrian_valid, position, cos_h, sin_h, lane_width,
    light_state, light_distance, out,
) -> None:  # fmt: skip
    """:func:`roach_desired_speed` into ``out`` (K,), the ego frame as ``ego_frame`` computes it
    (``cos_h`` / ``sin_h`` from numpy); the light ahead's state and distance given. hypot and
    arctan2 are libm's: where numpy dispatches AVX-512 ones they can differ by an ulp, which
    moves the value only for a vehicle within an ulp of 9.5 m or of 45°."""
    for k in range(out.shape[0]):
        desired = ROACH_MAX_SPEED_MPS
        nearest, seen = np.inf, False
        for i in range(vehicles.shape[1]):
            dx, dy = vehicles[k, i, 0] - position[k, 0], vehicles[k, i, 1] - position[k, 1]
            x, y = dx * cos_h[k] + dy * sin_h[k], -dx * sin_h[k] + dy * cos_h[k]
            distance = np.hypot(x, y)
            if vehicle_valid[k, i] and distance < 9.5 and abs(np.arctan2(y, x)) <= np.pi / 4:
                nearest, seen = min(nearest, distance), True
        if seen:
            desired = min(desired, _hazard(nearest, 8.0))
        nearest, seen = np.inf, False
        for i in range(pedestrians.shape[1]):
            dx, dy = pedestrians[k, i, 0] - position[k, 0], pedestrians[k, i, 1] - position[k, 1]
            x, y = dx * cos_h[k] + dy * sin_h[k], -dx * sin_h[k] + dy * cos_h[k]
            if pedestrian_valid[k, i] and x > 0 and abs(y) < lane_width[k] / 2:
                nearest, seen = min(nearest, x), True
        if seen:
            desired = min(desired, _hazard(nearest, 6.0))
        if light_state[k] >= 0 and light_state[k] != LIGHT_GREEN:
            desired = min(desired, _hazard(light_distance[k], 5.0))
        out[k] = desired


@term
def roach_speed(prev: WorldBatch, batch: WorldBatch, control) -> np.ndarray:
    """1 − |v − v*| / v_max: drive at the hazard-aware desired speed."""
    return 1.0 - np.abs(batch.ego.speed_mps - roach_desired_speed(batch)) / ROACH_MAX_SPEED_MPS


@term
def roach_position(prev: WorldBatch, batch: WorldBatch, control) -> np.ndarray:
    """−(distance from the route, m) / 2."""
    point, _ = batch.route.pose()
    return -np.linalg.norm(batch.ego.position - point, axis=1) / 2.0


@term
def roach_rotation(prev: WorldBatch, batch: WorldBatch, control) -> np.ndarray:
    """−|heading error against the route| (rad)."""
    _, heading = batch.route.pose()
    return -_heading_error(batch.ego.heading, heading)


@term
def roach_action(prev: WorldBatch, batch: WorldBatch, control) -> np.ndarray:
    """−0.1 when the normalised steering changed by more than 0.01 in the step."""
    change = np.abs(batch.ego.steering - prev.ego.steering) / ROACH_STEER_RAD
    return np.where(change > 0.01, -0.1, 0.0)


@term
def roach_terminal(prev: WorldBatch, batch: WorldBatch, control) -> np.ndarray:
    """−1 when the episode fails (collision, red light run, off-road, blocked, off the route), and
    a further −speed (m/s) for a collision or a red light run."""
    events = batch.events
    failed = events.collided | events.red_light_crossed | events.off_road | events.blocked | events.off_route
    value = np.where(failed, -1.0, 0.0)
    return np.where(events.collided | events.red_light_crossed, value - batch.ego.speed_mps, value)


# --- the CARLA study, follow-line (eqs. 2, 3) and follow-lane (eq. 4) ---------------------------------
# Both read where the painted line / the lane centre crosses the perception rows of the camera,
# projected from the WorldBatch's geometry (ground truth), in pixels of the seed's own frame
# width (640 for the line, 1024 for the lane) so that its pixel bands apply unchanged.
LINE_BAND_EDGES_PX = np.array([38.0, 2 * 38, 3 * 38, 5 * 38, 6 * 38])
# the extracted fourth value reads "39"; we take 3 so that the values keep falling (15, 12, 10, 3, 1)
LINE_BAND_VALUES = np.array([15.0, 12.0, 10.0, 3.0, 1.0, -100.0])
STEERING_BASE = 1.02  # the seed's λ
LANE_BAND_EDGES_PX = np.array([15.0, 2 * 15, 3 * 20, 4 * 20])  # as extracted: 15, 30, 60, 80
LANE_BAND_VALUES = np.array([10.0, 5.0, 2.5, 1.0, -10.0])
LANE_ALIGNED_DEG = 6.0  # the seed's ζ
LINE_ROWS, LANE_ROWS = np.array(LINE_ROWS_M), np.array(LANE_ROWS_M)  # ground rows ahead (m)
LANE_ROWS_PX = LANE_CAMERA.row_of_distance(LANE_ROWS)  # image rows of the lane rows


def crossing_columns(
    batch: WorldBatch,
    segments: np.ndarray,
    model: PinholeModel,
    distances_m: np.ndarray,
    index: np.ndarray | None = None,
) -> np.ndarray:
    """(K, D) image columns where each world's ``segments`` (K, M, 2, 2) cross the ground rows
    ``distances_m`` (D,) ahead of its ego (nan: not in view); with ``index`` (K,), world k's
    segments are ``segments[index[k]]``; ``segments`` (K, P, 2) are polylines. One compiled call
    (``segment_columns_into``)."""
    distances = np.asarray(distances_m, dtype=float)
    if segments.ndim == 3:  # polylines (K, P, 2): the segments between consecutive points
        starts, ends = segments[:, :-1], segments[:, 1:]
    else:
        starts, ends = segments[:, :, 0], segments[:, :, 1]
    if index is None:
        index = _world_indices(batch.num_worlds)
    cos_h, sin_h = batch.heading_cos_sin()
    out = np.empty((batch.num_worlds, len(distances)))
    position, terms = batch.ego.position, model.ground_terms
    segment_columns_into(starts, ends, index, position, cos_h, sin_h, distances, terms, out)
    return out


@functools.cache
def _world_indices(count: int) -> np.ndarray:
    """0 … count − 1 (int64, read-only), made once per count."""
    indices = np.arange(count, dtype=np.int64)
    indices.setflags(write=False)
    return indices


def _steering_deg(control, num_worlds: int) -> np.ndarray:
    """(K,) commanded front-wheel angle in degrees: 0 for meta-actions (no steering command)."""
    if control is not None and np.shape(control)[1:] == (2,):
        return np.asarray(control, dtype=float)[:, 1] * FULL_LOCK_DEG
    return np.zeros(num_worlds)


@term
def line_centring(prev: WorldBatch, batch: WorldBatch, control) -> np.ndarray:
    """Σ_j f(C_j) over the 4 line rows: 15 … 1 as the line's centre moves away from the image centre
    (in pixels of 640: 15 under 38, 12 under 76, 10 under 114, 3 under 190, 1 under 228), −100 farther
    out or for a row where the line is out of view (the CARLA study, eq. 2; ``LINE_BAND_EDGES_PX``)."""
    columns = crossing_columns(batch, guide_segment_sets(batch), LINE_CAMERA, LINE_ROWS, batch.road_index)
    out = np.empty(batch.num_worlds)
    line_centring_into(columns, float(LINE_CAMERA.centre[0]), float(LINE_CAMERA.width), out)
    return out


@njit(cache=True)
def line_centring_into(columns, centre_px, width_px, out) -> None:
    """:func:`line_centring`'s values from the line's columns (K, D) in an image ``width_px`` wide
    centred on ``centre_px`` into ``out`` (K,)."""
    for k in range(columns.shape[0]):
        total = 0.0
        for j in range(columns.shape[1]):
            offset_px = abs(columns[k, j] - centre_px) * 640 / width_px
            # nan (the row out of view) sorts after every number, as in numpy: the last band (−100)
            total += LINE_BAND_VALUES[np.searchsorted(LINE_BAND_EDGES_PX, offset_px, "right")]
        out[k] = total


@term
def speed_mps(prev: WorldBatch, batch: WorldBatch, control) -> np.ndarray:
    """The ego's speed in m/s (the CARLA study, eq. 3: ``+ v``)."""
    return np.asarray(batch.ego.speed_mps, dtype=float)


@term
def steering_power(prev: WorldBatch, batch: WorldBatch, control) -> np.ndarray:
    """λ^|α| with λ = 1.02 and α the commanded front-wheel angle in degrees (the CARLA study, eq. 3; the
    extracted formula is garbled: we read it as a penalty growing with the steering angle)."""
    return STEERING_BASE ** np.abs(_steering_deg(control, batch.num_worlds))


@term
def lane_keeping(prev: WorldBatch, batch: WorldBatch, control) -> np.ndarray:
    """The CARLA study, eq. 4: f*(C) by the lane centre's offset C from the image centre (10, 5, 2.5, 1,
    −10 in bands 15/30/60/80 px of 1024), doubled when the lane is within ζ = 6° of the image vertical and
    the action goes straight, halved when aligned but steering (the extracted text is garbled there;
    this is our reading of "higher reward when aligned and going straight")."""
    columns = crossing_columns(batch, batch.route.polyline, LANE_CAMERA, LANE_ROWS)  # (K, D)
    out = np.empty(batch.num_worlds)
    centre_px, width_px = float(LANE_CAMERA.centre[0]), float(LANE_CAMERA.width)
    steering_deg = _steering_deg(control, batch.num_worlds)
    lane_keeping_into(columns, LANE_ROWS_PX, centre_px, width_px, steering_deg, out)
    return out


@njit(cache=True)
def lane_keeping_into(columns, rows, centre_px, width_px, steering_deg, out) -> None:
    """:func:`lane_keeping`'s values from the lane centre's columns (K, D) at the image ``rows``
    (D,), nearest first, and the commanded steering (K,) degrees, into ``out`` (K,). C is the mean
    of the rows where the centre is seen (summed in row order, as numpy sums so few); g* the angle
    between the image vertical and the line from the nearest to the farthest seen row (libm's
    arctan2: where numpy dispatches an AVX-512 one, the angle can differ by an ulp, which moves
    the value only for an angle within an ulp of ζ)."""
    for k in range(columns.shape[0]):
        count, total, near, far = 0, 0.0, -1, -1
        for j in range(columns.shape[1]):
            if np.isfinite(columns[k, j]):
                count, total, far = count + 1, total + columns[k, j], j
                near = j if near < 0 else near
        if count == 0:
            out[k] = LANE_BAND_VALUES[-1]
            continue
        offset_px = abs(total / count - centre_px) * 1024 / width_px
        value = LANE_BAND_VALUES[np.searchsorted(LANE_BAND_EDGES_PX, offset_px, "right")]
        if count >= 2:
            angle = np.arctan2(columns[k, far] - columns[k, near], rows[near] - rows[far])
            if abs(np.degrees(angle)) <= LANE_ALIGNED_DEG:
                value = 2.0 * value if abs(steering_deg[k]) < 1e-6 else value / 2.0
        out[k] = value
