"""WorldBatch: K worlds as arrays — the one thing every sensor, reward term, rule and metric reads.

Shapes (K worlds, N vehicle slots, P pedestrian slots, L light slots, R route points): ``ego`` an
:class:`EgoBatch` of ``(K,)`` arrays; ``vehicles`` ``(K, N, 6)`` with ``vehicle_valid`` ``(K, N)``,
``pedestrians`` ``(K, P, 6)`` and ``traffic_lights`` ``(K, L, 4)`` likewise (rows past a world's
count are zeros); ``route`` a :class:`RouteBatch` of polylines ``(K, R, 2)`` padded by repeating
the last point; ``events`` an :class:`EventsBatch`; ``vehicle_destinations`` ``(K, N, 2)`` where
each vehicle is headed (the end of its planned route; its own position when it has none) and
``vehicle_accelerations`` ``(K, N)`` its acceleration in the last simulation frame (m/s²); the
distinct :class:`RoadMap` objects in ``roads`` and each world's in ``road_index`` ``(K,)``.

A WorldBatch is a value: simulators hand out a new one per step and nothing mutates it.
``batch[k]`` is world k as a :class:`~drivelab.world.state.WorldState`, and
``WorldBatch.stack(worlds)`` builds a batch from WorldStates.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np
from numba import njit

from drivelab.world.state import Ego, Events, RoadMap, Route, WorldState, stations_of

# ``EventsBatch.collision_kind`` codes, and the names WorldState's Events use for them
COLLISION_NONE, COLLISION_VEHICLE, COLLISION_PEDESTRIAN, COLLISION_OBJECT = range(4)
COLLISION_NAMES = ("", "vehicle", "pedestrian", "object")

EGO_FLOAT_FIELDS = (
    "heading", "speed_mps", "steering", "acceleration_mps2", "length_m", "width_m", "lane_width_m",
    "lateral_offset_m", "lane_heading", "lane_curvature",
)  # fmt: skip
EGO_INT_FIELDS = ("lane_id", "lane_count", "target_lane_id")
EGO_BOOL_FIELDS = ("on_road", "in_intersection")
EVENT_FLAGS = ("collided", "off_road", "arrived", "red_light_crossed", "blocked", "off_route")


@dataclass(frozen=True)
class EgoBatch:
    """The K controlled vehicles: :class:`~drivelab.world.state.Ego`'s fields as ``(K,)`` arrays."""

    position: np.ndarray  # (K, 2)
    heading: np.ndarray
    speed_mps: np.ndarray
    steering: np.ndarray
    acceleration_mps2: np.ndarray
    length_m: np.ndarray
    width_m: np.ndarray
    lane_id: np.ndarray
    lane_count: np.ndarray
    target_lane_id: np.ndarray
    lane_width_m: np.ndarray
    lateral_offset_m: np.ndarray
    lane_heading: np.ndarray
    lane_curvature: np.ndarray
    on_road: np.ndarray
    in_intersection: np.ndarray

    @property
    def forward_speed_mps(self) -> np.ndarray:
        """(K,) speed projected on the lane direction."""
        return self.speed_mps * np.cos(self.heading - self.lane_heading)

    @staticmethod
    def stack(egos: list[Ego]) -> EgoBatch:
        values = {"position": np.array([ego.position for ego in egos], dtype=float).reshape(-1, 2)}
        for names, dtype in ((EGO_FLOAT_FIELDS, float), (EGO_INT_FIELDS, np.int64), (EGO_BOOL_FIELDS, bool)):
            for name in names:
                values[name] = np.array([getattr(ego, name) for ego in egos], dtype=dtype)
        return EgoBatch(**values)

    def __getitem__(self, k: int) -> Ego:
        values = {"position": self.position[k].copy()}
        for names, cast in ((EGO_FLOAT_FIELDS, float), (EGO_INT_FIELDS, int), (EGO_BOOL_FIELDS, bool)):
            for name in names:
                values[name] = cast(getattr(self, name)[k])
        return Ego(**values)


@dataclass(frozen=True)
class RouteBatch:
    """K routes: polylines padded to a common length by repeating their last point.

    :param polyline: (K, R, 2) points; world k's real points are ``polyline[k, :count[k]]``.
    :param stations_m: (K, R) arc length of each point (padding repeats the last).
    :param count: (K,) number of real points (≥ 2).
    :param progress_m: (K,) arc length travelled along the route.
    :param length_m: (K,) total arc length; ``inf`` where the road does not end.
    :param closed: (K,) the route is a circuit (arc lengths wrap round the lap).
    """

    polyline: np.ndarray
    stations_m: np.ndarray
    count: np.ndarray
    progress_m: np.ndarray
    length_m: np.ndarray
    closed: np.ndarray
    # values derived from these arrays by their readers, made once per batch
    cache: dict = field(init=False, default_factory=dict, compare=False, repr=False)

    def pose(self) -> tuple[np.ndarray, np.ndarray]:
        """(K, 2) point and (K,) heading of each route at its progress (``poses_at``), made once."""
        if "pose" not in self.cache:
            self.cache["pose"] = self.poses_at(self.progress_m)
        return self.cache["pose"]

    @property
    def remaining_m(self) -> np.ndarray:
        return np.maximum(self.length_m - self.progress_m, 0.0)

    @staticmethod
    def stack(routes: list[Route]) -> RouteBatch:
        polylines = [np.asarray(route.polyline, dtype=float).reshape(-1, 2) for route in routes]
        stations = [
            stations_of(route.polyline) if route.stations_m is None else route.stations_m for route in routes
        ]
        size = max(max(len(p) for p in polylines), 2)
        return RouteBatch(
            polyline=np.stack([pad_edge(p, size) for p in polylines]),
            stations_m=np.stack([pad_edge(np.asarray(s, dtype=float), size) for s in stations]),
            count=np.array([len(p) for p in polylines], dtype=np.int64),
            progress_m=np.array([route.progress_m for route in routes], dtype=float),
            length_m=np.array([route.length_m for route in routes], dtype=float),
            closed=np.array([route.closed for route in routes], dtype=bool),
        )

    def __getitem__(self, k: int) -> Route:
        n = int(self.count[k])
        return Route(
            self.polyline[k, :n],
            float(self.progress_m[k]),
            float(self.length_m[k]),
            self.stations_m[k, :n],
            bool(self.closed[k]),
        )

    def poses_at(self, distances_m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Points (K, D, 2) and headings (K, D) at arc lengths ``distances_m`` (K, D) — or (K,),
        giving (K, 2) and (K,) — along each world's route: clamped to its ends, wrapped round the
        lap on a circuit (as :meth:`Route.poses_at`)."""
        distances = np.asarray(distances_m, dtype=float)
        single = distances.ndim == 1
        distances = distances.reshape(len(self.count), -1)
        points, delta = np.empty(distances.shape + (2,)), np.empty(distances.shape + (2,))
        _route_poses(self.polyline, self.stations_m, self.count, self.closed, distances, points, delta)
        headings = np.arctan2(delta[..., 1], delta[..., 0])  # numpy's, whichever kernel it dispatches
        return (points[:, 0], headings[:, 0]) if single else (points, headings)


@njit(cache=True)
def _route_poses(polyline, stations, count, closed, distances, points, delta) -> None:
    """``RouteBatch.poses_at``'s points into ``points`` (K, D, 2) and the segments' directions into
    ``delta`` (K, D, 2): a distance wrapped round the lap (np.mod), clamped to the route, found among
    the stations shifted by k · (the longest route + 1) (that shift's rounding can decide a segment,
    so it is kept), then interpolated on its segment."""
    worlds, width = stations.shape
    longest = 0.0
    for k in range(worlds):
        longest = max(longest, stations[k, count[k] - 1])
    for k in range(worlds):
        last = stations[k, count[k] - 1]
        shift = k * (longest + 1.0)
        for j in range(distances.shape[1]):
            d = distances[k, j]
            if closed[k] and last > 0:
                d = d % last  # Python's and np.mod's modulo of floats
            if d < 0.0:  # np.clip's order; nan stays nan
                d = 0.0
            elif d > last:
                d = last
            # np.searchsorted(side="right") among the shifted stations: how many are <= the key
            key, low, high = d + shift, 0, width
            while low < high:
                middle = (low + high) // 2
                if stations[k, middle] + shift <= key:
                    low = middle + 1
                else:
                    high = middle
            if key != key:  # nan sorts after every station
                low = width
            segment = min(max(low - 1, 0), count[k] - 2)
            span = max(stations[k, segment + 1] - stations[k, segment], 1e-12)
            fraction = (d - stations[k, segment]) / span
            for axis in range(2):
                step = polyline[k, segment + 1, axis] - polyline[k, segment, axis]
                delta[k, j, axis] = step
                points[k, j, axis] = polyline[k, segment, axis] + fraction * step


@njit(cache=True)
def _nearest_lights(lights, valid, position, heading, cos_h, sin_h, lane_width, state, distance) -> None:
    """Per world, the state (-1: none) and distance ahead (inf: none) of the nearest light whose
    stop line is ahead (its x in the ego frame > 0), within half a lane of the ego's axis and
    facing the ego's way (headings within 45°, wrapped as ``wrap_to_pi``): the first of equals."""
    for k in range(lights.shape[0]):
        state[k], distance[k] = -1, np.inf
        for i in range(lights.shape[1]):
            dx, dy = lights[k, i, 0] - position[k, 0], lights[k, i, 1] - position[k, 1]
            ahead = dx * cos_h[k] + dy * sin_h[k]
            beside = -dx * sin_h[k] + dy * cos_h[k]
            turn = (lights[k, i, 2] - heading[k] + np.pi) % (2 * np.pi) - np.pi
            mine = valid[k, i] and abs(turn) < np.pi / 4 and ahead > 0 and abs(beside) < lane_width[k] / 2
            if mine and ahead < distance[k]:
                state[k], distance[k] = np.int64(lights[k, i, 3]), ahead


@dataclass(frozen=True)
class EventsBatch:
    """What happened during the last step, per world: ``(K,)`` booleans and a collision code
    (``COLLISION_*``)."""

    collided: np.ndarray
    collision_kind: np.ndarray
    off_road: np.ndarray
    arrived: np.ndarray
    red_light_crossed: np.ndarray
    blocked: np.ndarray
    off_route: np.ndarray

    @staticmethod
    def stack(events: list[Events]) -> EventsBatch:
        flags = {name: np.array([getattr(e, name) for e in events], dtype=bool) for name in EVENT_FLAGS}
        kinds = np.array([COLLISION_NAMES.index(e.collision_with) for e in events], dtype=np.int8)
        return EventsBatch(collision_kind=kinds, **flags)

    def replaced(self, **flags: np.ndarray) -> EventsBatch:
        """``dataclasses.replace(self, **flags)`` without the frozen ``__init__`` (``assemble``)."""
        return assemble(EventsBatch, **{**self.__dict__, **flags})

    def __getitem__(self, k: int) -> Events:
        flags = {name: bool(getattr(self, name)[k]) for name in EVENT_FLAGS}
        return Events(collision_with=COLLISION_NAMES[int(self.collision_kind[k])], **flags)


@dataclass(frozen=True)
class WorldBatch:
    """K worlds of one scenario, as arrays (see the module docstring for every shape)."""

    time_s: np.ndarray
    dt_s: float
    ego: EgoBatch
    vehicles: np.ndarray
    vehicle_valid: np.ndarray
    vehicle_destinations: np.ndarray
    vehicle_accelerations: np.ndarray
    roads: tuple[RoadMap, ...]
    road_index: np.ndarray
    route: RouteBatch
    events: EventsBatch
    traffic_lights: np.ndarray
    light_valid: np.ndarray
    pedestrians: np.ndarray
    pedestrian_valid: np.ndarray
    max_speed_mps: np.ndarray
    speed_limit_mps: np.ndarray
    # for a sub-batch (``select``): each row's slot among the K worlds (None: row k is slot k)
    slots: np.ndarray | None = None
    # values derived by readers, made once per batch (a replaced batch starts an empty cache)
    cache: dict = field(init=False, default_factory=dict, compare=False, repr=False)

    @property
    def num_worlds(self) -> int:
        return len(self.time_s)

    def __len__(self) -> int:
        return len(self.time_s)

    @property
    def road(self) -> RoadMap:
        """The road map every world shares (an error when the worlds drive different maps)."""
        if len(self.roads) != 1:
            raise ValueError(f"the worlds of this batch drive {len(self.roads)} different road maps")
        return self.roads[0]

    def road_of(self, k: int) -> RoadMap:
        return self.roads[int(self.road_index[k])]

    @staticmethod
    def stack(worlds: list[WorldState]) -> WorldBatch:
        """The batch of ``worlds`` (at least one), in order."""
        if not worlds:
            raise ValueError("a WorldBatch needs at least one world")
        roads: list[RoadMap] = []
        road_index = [_road_slot(roads, world.road) for world in worlds]
        vehicles, vehicle_valid = _stack_rows([w.vehicles for w in worlds], 6)
        destinations, _ = _stack_rows([w.destinations() for w in worlds], 2)
        accelerations = _stack_rows([w.accelerations() for w in worlds], 1)[0][..., 0]
        pedestrians, pedestrian_valid = _stack_rows([w.pedestrians for w in worlds], 6)
        lights, light_valid = _stack_rows([w.traffic_lights for w in worlds], 4)
        return WorldBatch(
            time_s=np.array([w.time_s for w in worlds], dtype=float),
            dt_s=float(worlds[0].dt_s),
            ego=EgoBatch.stack([w.ego for w in worlds]),
            vehicles=vehicles,
            vehicle_valid=vehicle_valid,
            vehicle_destinations=destinations,
            vehicle_accelerations=accelerations,
            roads=tuple(roads),
            road_index=np.array(road_index, dtype=np.int64),
            route=RouteBatch.stack([w.route for w in worlds]),
            events=EventsBatch.stack([w.events for w in worlds]),
            traffic_lights=lights,
            light_valid=light_valid,
            pedestrians=pedestrians,
            pedestrian_valid=pedestrian_valid,
            max_speed_mps=np.array([w.max_speed_mps for w in worlds], dtype=float),
            speed_limit_mps=np.array([w.speed_limit_mps for w in worlds], dtype=float),
        )

    def __getitem__(self, k: int) -> WorldState:
        """World ``k`` as a WorldState (copies of its rows; the padding left out)."""
        return WorldState(
            time_s=float(self.time_s[k]),
            dt_s=self.dt_s,
            ego=self.ego[k],
            vehicles=self.vehicles[k, self.vehicle_valid[k]],
            road=self.road_of(k),
            route=self.route[k],
            events=self.events[k],
            traffic_lights=self.traffic_lights[k, self.light_valid[k]],
            pedestrians=self.pedestrians[k, self.pedestrian_valid[k]],
            max_speed_mps=float(self.max_speed_mps[k]),
            speed_limit_mps=float(self.speed_limit_mps[k]),
            vehicle_destinations=self.vehicle_destinations[k, self.vehicle_valid[k]],
            vehicle_accelerations=self.vehicle_accelerations[k, self.vehicle_valid[k]],
        )

    def select(self, indices: np.ndarray) -> WorldBatch:
        """The sub-batch of worlds ``indices`` (their ``slots`` say which they are, so that stateful
        sensors advance only those worlds' history)."""
        indices = np.asarray(indices, dtype=np.int64)
        take = lambda a: a[indices]  # noqa: E731
        return WorldBatch(
            dt_s=self.dt_s,
            ego=EgoBatch(**{f.name: take(getattr(self.ego, f.name)) for f in _FIELDS_EGO}),
            roads=self.roads,
            road_index=take(self.road_index),
            route=RouteBatch(**{f.name: take(getattr(self.route, f.name)) for f in _FIELDS_ROUTE}),
            events=EventsBatch(**{f.name: take(getattr(self.events, f.name)) for f in _FIELDS_EVENTS}),
            slots=indices if self.slots is None else self.slots[indices],
            **{name: take(getattr(self, name)) for name in _WORLD_ARRAYS},
        )

    @property
    def rows(self) -> np.ndarray | slice:
        """Index of this batch's worlds into per-world state arrays of K rows (``state[batch.rows]``)."""
        return slice(None) if self.slots is None else self.slots

    def with_events(self, **flags: np.ndarray) -> WorldBatch:
        """The same batch with some event arrays replaced (``blocked=…``, ``off_route=…``)."""
        return self.replaced(events=self.events.replaced(**flags))

    def replaced(self, **fields) -> WorldBatch:
        """``dataclasses.replace(self, **fields)`` (a fresh cache) without re-running ``__init__``
        over all its fields (there is no ``__post_init__`` to run): the per-step exports' way."""
        unknown = fields.keys() - self.__dataclass_fields__.keys()
        if unknown or "cache" in fields:
            raise TypeError(f"WorldBatch has no field to replace named {sorted(unknown) or ['cache']}")
        batch = object.__new__(WorldBatch)
        batch.__dict__.update(self.__dict__, **fields, cache={})
        return batch

    def where(self, mask: np.ndarray, other: WorldBatch) -> WorldBatch:
        """World k from ``other`` where ``mask[k]``, else from this batch (e.g. reset worlds
        merged into a stepped batch). Slot counts are padded to the larger of the two."""
        mask = np.asarray(mask, dtype=bool)
        roads = list(self.roads)
        remap = [_road_slot(roads, road) for road in other.roads]

        def pick(part, other_part, name: str) -> np.ndarray:
            return _where_rows(mask, getattr(part, name), getattr(other_part, name), name in _EDGE_PADDED)

        return WorldBatch(
            dt_s=self.dt_s,
            ego=EgoBatch(**{f.name: pick(self.ego, other.ego, f.name) for f in _FIELDS_EGO}),
            roads=tuple(roads),
            road_index=np.where(mask, np.asarray(remap, dtype=np.int64)[other.road_index], self.road_index),
            route=RouteBatch(**{f.name: pick(self.route, other.route, f.name) for f in _FIELDS_ROUTE}),
            events=EventsBatch(**{f.name: pick(self.events, other.events, f.name) for f in _FIELDS_EVENTS}),
            **{name: pick(self, other, name) for name in _WORLD_ARRAYS},
        )

    def road_users(self) -> tuple[np.ndarray, np.ndarray]:
        """(K, N + P, 6) every body on the road besides the ego — vehicles, then pedestrians — and
        its (K, N + P) valid mask."""
        if self.pedestrians.shape[1] == 0:
            return self.vehicles, self.vehicle_valid
        users = np.concatenate([self.vehicles, self.pedestrians], axis=1)
        return users, np.concatenate([self.vehicle_valid, self.pedestrian_valid], axis=1)

    def heading_cos_sin(self) -> tuple[np.ndarray, np.ndarray]:
        """(K,) cosines and (K,) sines of the egos' headings (numpy's), made once per batch for
        every reader that turns world points into the ego frame."""
        made = self.cache.get("heading_cos_sin")
        if made is None:
            heading = self.ego.heading
            made = self.cache["heading_cos_sin"] = (np.cos(heading), np.sin(heading))
        return made

    def light_ahead(self, max_distance_m: float) -> tuple[np.ndarray, np.ndarray]:
        """Per world, the LIGHT_* state (``-1``: none) and distance (m, ``inf``: none) of the nearest
        traffic light whose stop line is ahead within ``max_distance_m``, in the ego's lane and
        facing its way (approach heading within 45°) — :meth:`WorldState.light_ahead` for K. The
        nearest at any distance is found once per batch; a nearer limit only filters it."""
        if not self.traffic_lights.shape[1]:  # no lights in any world: nothing to search or filter
            return np.full(self.num_worlds, -1, dtype=np.int64), np.full(self.num_worlds, np.inf)
        if "light_ahead" not in self.cache:
            ego, (cos_h, sin_h) = self.ego, self.heading_cos_sin()
            state, distance = np.empty(self.num_worlds, dtype=np.int64), np.empty(self.num_worlds)
            _nearest_lights(
                self.traffic_lights, self.light_valid, ego.position, ego.heading, cos_h, sin_h,
                ego.lane_width_m, state, distance,
            )  # fmt: skip
            self.cache["light_ahead"] = state, distance
        state, distance = self.cache["light_ahead"]
        within = distance <= max_distance_m
        return np.where(within, state, -1), np.where(within, distance, np.inf)


_FIELDS_EGO = dataclasses.fields(EgoBatch)
_FIELDS_EVENTS = dataclasses.fields(EventsBatch)
_FIELDS_ROUTE = [f for f in dataclasses.fields(RouteBatch) if f.init]
# WorldBatch's (K, ...) arrays besides ego, route, events and road_index
_WORLD_ARRAYS = (
    "time_s", "vehicles", "vehicle_valid", "vehicle_destinations", "vehicle_accelerations", "traffic_lights",
    "light_valid", "pedestrians", "pedestrian_valid", "max_speed_mps", "speed_limit_mps",
)  # fmt: skip
_EDGE_PADDED = ("polyline", "stations_m")  # RouteBatch's arrays padded by repeating their last point
# per batch class: its init fields' names, and the defaults of those that have one
_INIT_NAMES = {
    cls: frozenset(f.name for f in dataclasses.fields(cls) if f.init)
    for cls in (EgoBatch, RouteBatch, EventsBatch, WorldBatch)
}
_DEFAULTS = {
    cls: {
        f.name: f.default for f in dataclasses.fields(cls) if f.init and f.default is not dataclasses.MISSING
    }
    for cls in _INIT_NAMES
}


def assemble(cls, /, **fields):
    """``cls(**fields)`` for :class:`EgoBatch`, :class:`RouteBatch`, :class:`EventsBatch` or
    :class:`WorldBatch` (``cache`` empty), without the frozen ``__init__``'s ``object.__setattr__``
    per field (a simulator's per-step export). The same fields are required."""
    defaults = _DEFAULTS[cls]
    if defaults:
        fields = defaults | fields
    if fields.keys() != _INIT_NAMES[cls]:
        wrong = sorted(fields.keys() ^ _INIT_NAMES[cls])
        raise TypeError(f"{cls.__name__} needs exactly its fields: {wrong} missing or unknown")
    if "cache" in cls.__dataclass_fields__:
        fields["cache"] = {}
    made = object.__new__(cls)
    object.__setattr__(made, "__dict__", fields)  # **fields is this call's own dict
    return made


def _road_slot(roads: list[RoadMap], road: RoadMap) -> int:
    """The index of ``road`` (the same object) in ``roads``, appended when it is not there."""
    found = next((i for i, known in enumerate(roads) if known is road), None)
    if found is None:
        roads.append(road)
        found = len(roads) - 1
    return found


def pad_edge(array: np.ndarray, size: int) -> np.ndarray:
    """``array`` (R, ...) extended to ``size`` rows by repeating its last row."""
    return np.pad(array, [(0, max(size - len(array), 0))] + [(0, 0)] * (array.ndim - 1), "edge")


def _stack_rows(arrays: list[np.ndarray], columns: int) -> tuple[np.ndarray, np.ndarray]:
    """Row arrays of different lengths → zero-padded (K, N, columns) and the (K, N) valid mask."""
    arrays = [np.asarray(a, dtype=float).reshape(-1, columns) for a in arrays]
    size = max(len(a) for a in arrays)
    out = np.zeros((len(arrays), size, columns))
    valid = np.zeros((len(arrays), size), dtype=bool)
    for k, rows in enumerate(arrays):
        out[k, : len(rows)] = rows
        valid[k, : len(rows)] = True
    return out, valid


def _where_rows(mask: np.ndarray, a: np.ndarray, b: np.ndarray, edge: bool = False) -> np.ndarray:
    """Rows of ``b`` where ``mask`` else of ``a``; a slot axis (axis 1) is padded to the larger size
    (with zeros, or by repeating the last slot when ``edge``)."""
    if a.ndim > 1 and a.shape[1] != b.shape[1]:
        size = max(a.shape[1], b.shape[1])
        a, b = (pad_slots(x, size, edge) for x in (a, b))
    return np.where(mask.reshape((-1,) + (1,) * (a.ndim - 1)), b, a)


def pad_slots(array: np.ndarray, size: int, edge: bool = False) -> np.ndarray:
    """``array`` (K, N, ...) padded to ``size`` slots on axis 1: zeros, or its last slot when ``edge``."""
    missing = size - array.shape[1]
    if missing <= 0:
        return array
    return np.pad(array, [(0, 0), (0, missing)] + [(0, 0)] * (array.ndim - 2), "edge" if edge else "constant")
