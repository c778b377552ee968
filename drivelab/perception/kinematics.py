"""Kinematics: the nearest vehicles' state in the ego frame, like highway-env's, for K worlds at once."""

from __future__ import annotations

import numpy as np
from gymnasium import spaces
from numba import njit

from drivelab.errors import UsageError
from drivelab.perception.base import Sensor, ego_frame
from drivelab.world.batch import WorldBatch

FEATURES = ("presence", "x", "y", "vx", "vy", "cos_h", "sin_h")
# highway-env's ``observe_intentions``: the direction to where each vehicle is headed (not by default)
INTENTION_FEATURES = ("cos_d", "sin_d")
# how hard each vehicle speeds up or brakes (not in highway-env's kinematics; not by default)
ACCELERATION_FEATURES = ("accel",)
# where each vehicle's straight path crosses the ego's route ahead, and when (not by default)
CROSSING_FEATURES = ("t_cross", "s_cross")
EXTRA_FEATURES = INTENTION_FEATURES + ACCELERATION_FEATURES + CROSSING_FEATURES
ALL_FEATURES = FEATURES + EXTRA_FEATURES


class Kinematics(Sensor):
    """``vehicles_count`` rows of the nearest vehicles' features, flat by default, all in [-1, 1].

    Row 0 is the ego (presence 1, position (0, 0), velocity (speed, 0), heading relative to its
    lane); rows 1… are the nearest other vehicles within ``perception_distance_m``, nearest first,
    relative to the ego in its frame (x forward, y right). Absent rows are all zero.

    :param vehicles_count: rows, the ego included.
    :param perception_distance_m: vehicles farther than this are not seen; also the position scale.
    :param speed_scale_mps: velocity normalisation; highway-env's 2 × its 40 m/s maximum speed.
    :param features: names of ``ALL_FEATURES`` joined by ``+`` (e.g. highway-env's default
        ``"presence+x+y+vx+vy"``), or a sequence of names; default every one of ``FEATURES``.
        ``cos_d`` and ``sin_d`` (highway-env's ``observe_intentions``) are the unit direction from
        a vehicle to its destination, the end of its planned route (zeros where it has none), in
        the ego frame (the world frame with ``absolute``); the ego's points to its route's end
        (zeros on a closed circuit). ``accel`` is a vehicle's acceleration along its heading in the
        last simulation frame (braking negative), divided by ``accel_scale_mps2``; the same in
        either frame, and 0 where the simulator exports none. ``t_cross`` and ``s_cross`` say
        where a vehicle driving on at its speed and heading would cross the ego's route ahead
        (within ``perception_distance_m`` of route): ``t_cross`` the seconds it needs to get there
        over ``crossing_horizon_s``, ``s_cross`` the ego's distance along its route to that point
        over ``perception_distance_m``; both 1 where it would not cross within the horizon (or is
        not moving towards the route), both 0 in the ego's row.
    :param flatten: one flat vector; false: highway-env's ``(vehicles_count, features)`` array.
    :param normalize: divide positions and velocities by the scales above; false: raw metres and
        m/s, unclipped.
    :param clip: clip the normalised values to [-1, 1] (highway-env's ``clip``).
    :param accel_scale_mps2: acceleration normalisation; highway-env's IDM limit (``ACC_MAX``),
        so that traffic's accelerations fill [-1, 1].
    :param crossing_horizon_s: how far ahead ``t_cross`` looks, and its scale.
    :param absolute: every row, the ego's included, in the world frame: position, velocity and
        heading as they are on the map (highway-env's ``absolute``, its intersection's default),
        which tells where on a fixed map each vehicle is and where it heads. The nearest
        vehicles are chosen as in the ego frame.
    """

    name = "kinematics"
    help = "nearest vehicles' presence, position, velocity, heading in the ego frame"

    def __init__(
        self,
        *,
        vehicles_count: int = 5,
        perception_distance_m: float = 100.0,
        speed_scale_mps: float = 80.0,
        features: str = "+".join(FEATURES),
        flatten: bool = True,
        normalize: bool = True,
        clip: bool = True,
        absolute: bool = False,
        accel_scale_mps2: float = 6.0,
        crossing_horizon_s: float = 8.0,
    ) -> None:
        scales = (perception_distance_m, speed_scale_mps, accel_scale_mps2, crossing_horizon_s)
        if vehicles_count < 1 or min(scales) <= 0:
            raise ValueError(
                "kinematics needs vehicles_count >= 1 and positive distance, speed, acceleration and "
                "crossing-horizon scales"
            )
        self.vehicles_count = int(vehicles_count)
        self.perception_distance_m = float(perception_distance_m)
        self.speed_scale_mps = float(speed_scale_mps)
        self.accel_scale_mps2 = float(accel_scale_mps2)
        self.crossing_horizon_s = float(crossing_horizon_s)
        self.features = feature_names(features)
        self.columns = np.array([ALL_FEATURES.index(name) for name in self.features], dtype=np.int64)
        self.intentions = any(name in INTENTION_FEATURES for name in self.features)
        self.accelerations = any(name in ACCELERATION_FEATURES for name in self.features)
        self.crossings = any(name in CROSSING_FEATURES for name in self.features)
        self.flatten, self.normalize = bool(flatten), bool(normalize)
        self.clip = bool(clip) and self.normalize  # highway-env clips only what it normalises
        self.absolute = bool(absolute)
        # every feature in FEATURES' order: the rows are written straight into the observation
        self._all_columns = self.features == FEATURES
        # the default layout (every feature, flat, normalised and clipped), which fused steps write
        self.plain = self._all_columns and self.flatten and self.clip and not self.absolute
        shape = (self.vehicles_count, len(self.features))
        bound = 1.0 if self.clip else np.inf
        self._space = spaces.Box(
            -bound, bound, shape=(shape[0] * shape[1],) if self.flatten else shape, dtype=np.float32
        )

    def _observe(self, batch: WorldBatch, out: np.ndarray) -> None:
        ego = batch.ego
        rows = np.zeros((batch.num_worlds, self.vehicles_count, len(FEATURES)))  # (K, rows, 7)
        relative_heading = ego.heading - ego.lane_heading
        position_scale = self.perception_distance_m if self.normalize else 1.0
        speed_scale = self.speed_scale_mps if self.normalize else 1.0
        others = batch.vehicles  # (K, N, 6)
        chosen = None  # the other vehicles' slots, row by row (-1: none)
        if others.shape[1] and self.vehicles_count > 1:
            # the selection compiled, the transcendental functions in numpy (its rounding
            # everywhere) on the selected vehicles' headings only
            cos_h, sin_h = batch.heading_cos_sin()
            chosen, heading = nearest_rows(
                others, batch.vehicle_valid, ego.position, ego.heading, cos_h, sin_h,
                self.perception_distance_m, position_scale, rows,
            )  # fmt: skip
            if self.absolute:  # the chosen vehicles' rows in the world frame instead
                present = chosen >= 0
                picked = np.take_along_axis(others, np.where(present, chosen, 0)[..., None], axis=1)
                world = _world_frame(picked[..., 0], picked[..., 1], picked[..., 2], picked[..., 3],
                                     position_scale, speed_scale)  # fmt: skip
                rows[:, 1:, 1:] = np.where(present[..., None], world, 0.0)
            else:
                cos_other, sin_other = np.cos(heading), np.sin(heading)
                motion_rows(others, chosen, ego.speed_mps, cos_other, sin_other, speed_scale, rows)
        if self.absolute:  # the ego's row too: its place and heading on the map
            rows[:, 0, 0] = 1.0
            rows[:, 0, 1:] = _world_frame(ego.position[:, 0], ego.position[:, 1], ego.heading, ego.speed_mps,
                                          position_scale, speed_scale)  # fmt: skip
            every = np.clip(rows, -1.0, 1.0) if self.clip else rows
            out[...] = self._with_extras(every, batch, chosen)[:, :, self.columns].reshape(out.shape)
            return
        cos_relative, sin_relative = np.cos(relative_heading), np.sin(relative_heading)
        in_place = self._all_columns and out.flags.c_contiguous  # the rows written into out's flat view
        flat = (batch.num_worlds, self.vehicles_count * len(FEATURES))
        every = out.reshape(flat) if in_place else np.empty(flat)
        ego_rows_into(rows, ego.speed_mps, cos_relative, sin_relative, speed_scale, self.clip, every)
        if not in_place:
            every = self._with_extras(every.reshape(rows.shape), batch, chosen)
            out[...] = every[:, :, self.columns].reshape(out.shape)

    def _with_extras(self, rows: np.ndarray, batch: WorldBatch, chosen: np.ndarray | None) -> np.ndarray:
        """``rows`` (K, rows, 7), with the columns of ``EXTRA_FEATURES`` after them when any is asked
        for (those not asked for left zero)."""
        if not (self.intentions or self.accelerations or self.crossings):
            return rows
        extra = np.zeros((*rows.shape[:2], len(EXTRA_FEATURES)))
        if self.intentions:
            extra[..., :2] = intention_rows(batch, chosen, self.vehicles_count, self.absolute)
        if self.accelerations:
            scale = self.accel_scale_mps2 if self.normalize else 1.0
            accel = acceleration_rows(batch, chosen, self.vehicles_count) / scale
            extra[..., 2] = np.clip(accel, -1.0, 1.0) if self.clip else accel
        if self.crossings and chosen is not None:
            route = batch.route
            crossing_rows(
                batch.vehicles, chosen, route.polyline, route.stations_m, route.count, route.progress_m,
                self.crossing_horizon_s, self.perception_distance_m, extra[:, 1:, 3:5],
            )  # fmt: skip
            if self.normalize:
                extra[..., 3] /= self.crossing_horizon_s
                extra[..., 4] /= self.perception_distance_m
        return np.concatenate([rows, extra], axis=2)


def intention_rows(batch: WorldBatch, chosen: np.ndarray | None, count: int, absolute: bool) -> np.ndarray:
    """(K, count, 2) the unit direction from each row's vehicle to its destination (highway-env's
    ``destination_direction``; zeros where they coincide or the row is empty), in the ego frame
    unless ``absolute``. Row 0, the ego's: to the last point of its route (zeros on a circuit);
    rows 1… the vehicles ``chosen`` (K, count - 1) slots, -1 for none (None: no vehicle)."""
    num_worlds = batch.num_worlds
    vectors = np.zeros((num_worlds, count, 2))
    route = batch.route
    vectors[:, 0] = np.where(route.closed[:, None], 0.0, route.polyline[:, -1] - batch.ego.position)
    if chosen is not None:
        present = chosen >= 0
        slot = np.where(present, chosen, 0)[..., None]
        destination = np.take_along_axis(batch.vehicle_destinations, slot, axis=1)
        position = np.take_along_axis(batch.vehicles[..., :2], slot, axis=1)
        vectors[:, 1 : 1 + chosen.shape[1]] = np.where(present[..., None], destination - position, 0.0)
    norm = np.hypot(vectors[..., 0], vectors[..., 1])[..., None]
    unit = np.divide(vectors, norm, out=np.zeros_like(vectors), where=norm > 0)
    return unit if absolute else ego_frame(unit, 0.0, batch.ego.heading[:, None])


def acceleration_rows(batch: WorldBatch, chosen: np.ndarray | None, count: int) -> np.ndarray:
    """(K, count) each row's vehicle's acceleration (m/s²): row 0 the ego's, rows 1… those of the
    vehicles ``chosen`` (K, count - 1) slots, -1 for none (zeros; None: no vehicle)."""
    accelerations = np.zeros((batch.num_worlds, count))
    accelerations[:, 0] = batch.ego.acceleration_mps2
    if chosen is not None:
        present = chosen >= 0
        picked = np.take_along_axis(batch.vehicle_accelerations, np.where(present, chosen, 0), axis=1)
        accelerations[:, 1 : 1 + chosen.shape[1]] = np.where(present, picked, 0.0)
    return accelerations


@njit(cache=True)
def crossing_rows(vehicles, chosen, polyline, stations, count, progress, horizon_s, window_m, out):
    """Into ``out`` (K, count - 1, 2), for each vehicle ``chosen`` (-1: none, left 0): the seconds
    until its straight path at its speed meets the ego's route between ``progress`` and ``window_m``
    of route further, and the ego's distance along the route to that point; the first crossing
    along its path. ``horizon_s`` and ``window_m`` where it meets none within ``horizon_s``. The
    window does not wrap past a circuit's lap end."""
    for k in range(chosen.shape[0]):
        for r in range(chosen.shape[1]):
            j = chosen[k, r]
            if j < 0:
                break
            px, py = vehicles[k, j, 0], vehicles[k, j, 1]
            ux, uy = np.cos(vehicles[k, j, 2]), np.sin(vehicles[k, j, 2])
            speed = max(vehicles[k, j, 3], 0.0)
            reach = speed * horizon_s
            best, where = np.inf, window_m
            for i in range(count[k] - 1):
                start, end = stations[k, i], stations[k, i + 1]
                if end < progress[k] or start > progress[k] + window_m or end <= start:
                    continue
                ax, ay = polyline[k, i, 0], polyline[k, i, 1]
                ex, ey = polyline[k, i + 1, 0] - ax, polyline[k, i + 1, 1] - ay
                denominator = ux * ey - uy * ex
                if abs(denominator) < 1e-12:
                    continue  # parallel to this segment
                wx, wy = ax - px, ay - py
                along = (wx * ey - wy * ex) / denominator  # metres along the vehicle's heading
                fraction = (wx * uy - wy * ux) / denominator  # of the segment
                station = start + fraction * (end - start)
                if not (0.0 <= fraction <= 1.0 and 0.0 <= along <= reach and along < best):
                    continue
                if progress[k] <= station <= progress[k] + window_m:
                    best, where = along, station - progress[k]
            if best == np.inf:
                out[k, r, 0], out[k, r, 1] = horizon_s, window_m
            else:
                out[k, r, 0] = best / speed if best > 0.0 else 0.0
                out[k, r, 1] = where


def feature_names(features) -> tuple[str, ...]:
    """The feature names of ``features`` (names joined by ``+``, or a sequence of names), each one
    of ``ALL_FEATURES`` and none twice; a UsageError otherwise."""
    names = features.split("+") if isinstance(features, str) else list(features)
    names = [str(name).strip() for name in names]
    unknown = [name for name in names if name not in ALL_FEATURES]
    if unknown or not names or len(set(names)) != len(names):
        what = f"unknown {unknown}" if unknown else "each at most once"
        raise UsageError(
            f"kinematics features must be names of {', '.join(ALL_FEATURES)} joined by '+', {what}: "
            f"got {features!r}"
        )
    return tuple(names)


@njit(cache=True)
def ego_rows_into(rows, speed_mps, cos_relative, sin_relative, speed_scale, clip, out):
    """Row 0 of every world (the ego: presence 1, speed / scale, cos and sin of its heading
    relative to its lane) into ``rows`` (K, rows, 7), then every value, clipped to [-1, 1] when
    ``clip`` (nan kept, as np.clip keeps it), into ``out`` (K, rows · 7) in ``out``'s float type."""
    for k in range(rows.shape[0]):
        row = rows[k, 0]
        row[0], row[3] = 1.0, speed_mps[k] / speed_scale
        row[5], row[6] = cos_relative[k], sin_relative[k]
        flat = rows[k].ravel()
        for i in range(flat.size):
            value = flat[i]
            if not clip:
                pass
            elif value < -1.0:
                value = -1.0
            elif value > 1.0:
                value = 1.0
            out[k, i] = value


@njit(cache=True)
def nearest_rows(vehicles, valid, position, heading, cos_h, sin_h, reach, scale, rows):
    """Presence and position of rows 1… of every world: its nearest seen vehicles, nearest first
    (on ties highway-env's order, as a stable sort gives), relative to the ego in the ego frame
    (``ego_frame``'s arithmetic). The nearest are selected by insertion into the few rows wanted
    (a strict comparison keeps the earlier vehicle first on ties), not by sorting every slot.
    Positions are divided by ``scale``. Returns the chosen slots (K, rows - 1), -1 for none, and
    their headings relative to the ego's (0 for none)."""
    num_worlds, slots = valid.shape
    wanted = min(rows.shape[1] - 1, slots)
    chosen = np.full((num_worlds, rows.shape[1] - 1), -1, dtype=np.int64)
    relative = np.zeros((num_worlds, rows.shape[1] - 1))
    key = np.empty(slots)
    x, y = np.empty(slots), np.empty(slots)
    for k in range(num_worlds):
        found, pick = 0, chosen[k]
        for j in range(slots):
            if not valid[k, j]:
                continue
            dx, dy = vehicles[k, j, 0] - position[k, 0], vehicles[k, j, 1] - position[k, 1]
            x[j] = dx * cos_h[k] + dy * sin_h[k]
            y[j] = -dx * sin_h[k] + dy * cos_h[k]
            distance = np.hypot(x[j], y[j])
            if not distance <= reach:
                continue
            key[j] = distance
            if found == wanted and not distance < key[pick[wanted - 1]]:
                continue
            rank = min(found, wanted - 1)
            while rank > 0 and distance < key[pick[rank - 1]]:
                pick[rank] = pick[rank - 1]
                rank -= 1
            pick[rank] = j
            found = min(found + 1, wanted)
        for r in range(found):
            j = pick[r]
            row = rows[k, 1 + r]
            row[0] = 1.0
            row[1], row[2] = x[j] / scale, y[j] / scale
            relative[k, r] = vehicles[k, j, 2] - heading[k]
    return chosen, relative


@njit(cache=True)
def motion_rows(vehicles, chosen, speed_mps, cos_other, sin_other, speed_scale, rows):
    """Velocity and heading of the rows ``nearest_rows`` chose: relative to the ego's velocity
    in the ego frame, and the heading relative to the ego's (its cosine and sine given)."""
    for k in range(chosen.shape[0]):
        for r in range(chosen.shape[1]):
            j = chosen[k, r]
            if j < 0:
                break
            speed, row = vehicles[k, j, 3], rows[k, 1 + r]
            row[3] = (speed * cos_other[k, r] - speed_mps[k]) / speed_scale
            row[4] = speed * sin_other[k, r] / speed_scale
            row[5], row[6] = cos_other[k, r], sin_other[k, r]


def _world_frame(x, y, heading, speed, position_scale, speed_scale) -> np.ndarray:
    """Vehicles' (…, 6) columns x, y, vx, vy, cos h, sin h in the world frame, positions divided by
    ``position_scale`` and velocities by ``speed_scale``."""
    cos_h, sin_h = np.cos(heading), np.sin(heading)
    return np.stack(
        [x / position_scale, y / position_scale, speed * cos_h / speed_scale, speed * sin_h / speed_scale,
         cos_h, sin_h],
        axis=-1,
    )  # fmt: skip
