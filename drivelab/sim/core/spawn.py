"""Episode set-up without highway-env objects, drawing the same random numbers in the same order.

The scenarios' spawners (``spawn_merge``, ``spawn_roundabout``, ``spawn_racetrack``,
``spawn_intersection``) share these helpers: highway-env's lane formulas in numpy call for call
(``LaneGeometry``), its vehicle constructors as rows (``vehicle_row``), its route planning
(``shortest_path``, ``plan_route``) and drivelab's traffic levels (``arrange_traffic``). A spawner
is ``spawner(seed, road, control) -> (rows, ego_row, regulation, rng)``: ``road`` the simulator's
converted road, ``rows`` (N, VEHICLE_COLUMNS) the vehicles then the road's obstacles (as
``vehicles_to_array`` lays them out), ``regulation`` (2,) the RegulatedRoad state, ``rng`` the
episode's generator where draws go on between steps (else None).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from drivelab.sim.core import lanes as L
from drivelab.sim.core import traffic as T

DELTA_RANGE = (3.5, 4.5)  # IDMVehicle.DELTA_RANGE


# --- highway-env's lane formulas, call for call -----------------------------------------------


class LaneGeometry:
    """highway-env's lane geometry (``road/lane.py``) over a LaneTable's rows, with numpy's own
    calls in highway-env's order (``np.sin``, ``np.dot``, ``np.linalg.norm``, ...), so a set-up
    gets the very bits highway-env gets on the same CPU (numba's libm and multiply-adds may
    differ by an ULP where numpy dispatches SIMD kernels). Set-up only: a few calls per vehicle.

    :param table: the road's LaneTable.
    """

    def __init__(self, table: L.LaneTable) -> None:
        self.lanes, self.row_of = table.rows, table.row_of
        rows = table.rows
        self._start = [np.array([r[L.START_X], r[L.START_Y]]) for r in rows]
        self._direction = [np.array([r[L.DIR_X], r[L.DIR_Y]]) for r in rows]
        self._lateral = [np.array([-r[L.DIR_Y], r[L.DIR_X]]) for r in rows]
        self._center = [np.array([r[L.CENTER_X], r[L.CENTER_Y]]) for r in rows]
        self._kind = [int(r[L.KIND]) for r in rows]
        self._direction_sign = [int(r[L.SENSE]) for r in rows]  # CircularLane.direction, an int

    def length(self, lane: int) -> float:
        return float(self.lanes[lane, L.LENGTH])

    def speed_limit(self, lane: int) -> float | None:
        limit = self.lanes[lane, L.SPEED_LIMIT]
        return None if np.isnan(limit) else float(limit)

    def position(self, lane: int, longitudinal: float, lateral: float) -> np.ndarray:
        """AbstractLane.position: (2,) world point."""
        row, kind = self.lanes[lane], self._kind[lane]
        if kind == L.CIRCLE:
            direction = self._direction_sign[lane]
            phi = direction * longitudinal / row[L.RADIUS] + row[L.START_PHASE]
            unit = np.array([np.cos(phi), np.sin(phi)])
            return self._center[lane] + (row[L.RADIUS] - lateral * direction) * unit
        if kind == L.SINE:
            lateral = lateral + row[L.AMPLITUDE] * np.sin(row[L.PULSATION] * longitudinal + row[L.PHASE])
        return self._start[lane] + longitudinal * self._direction[lane] + lateral * self._lateral[lane]

    def heading_at(self, lane: int, longitudinal: float) -> float:
        """AbstractLane.heading_at."""
        row, kind = self.lanes[lane], self._kind[lane]
        if kind == L.CIRCLE:
            direction = self._direction_sign[lane]
            phi = direction * longitudinal / row[L.RADIUS] + row[L.START_PHASE]
            return phi + np.pi / 2 * direction
        if kind == L.SINE:
            pulsation = row[L.PULSATION]
            slope = row[L.AMPLITUDE] * pulsation * np.cos(pulsation * longitudinal + row[L.PHASE])
            return row[L.HEADING] + np.arctan(slope)
        return row[L.HEADING]

    def local_coordinates(self, lane: int, position: np.ndarray) -> tuple[float, float]:
        """AbstractLane.local_coordinates of a (2,) world point."""
        row, kind = self.lanes[lane], self._kind[lane]
        if kind == L.CIRCLE:
            direction = self._direction_sign[lane]
            delta = position - self._center[lane]
            phi = np.arctan2(delta[1], delta[0])
            phi = row[L.START_PHASE] + _wrap_to_pi(phi - row[L.START_PHASE])
            r = np.linalg.norm(delta)
            return direction * (phi - row[L.START_PHASE]) * row[L.RADIUS], direction * (row[L.RADIUS] - r)
        delta = position - self._start[lane]
        longitudinal = float(np.dot(delta, self._direction[lane]))
        lateral = float(np.dot(delta, self._lateral[lane]))
        if kind == L.SINE:
            lateral = lateral - row[L.AMPLITUDE] * np.sin(row[L.PULSATION] * longitudinal + row[L.PHASE])
        return longitudinal, lateral

    def distance_with_heading(self, lane: int, position: np.ndarray, heading: float) -> float:
        """AbstractLane.distance_with_heading (heading weight 1)."""
        s, r = self.local_coordinates(lane, position)
        angle = np.abs(_wrap_to_pi(heading - self.heading_at(lane, s)))
        return abs(r) + max(s - self.lanes[lane, L.LENGTH], 0) + max(0 - s, 0) + 1.0 * angle

    def closest_lane(self, position: np.ndarray, heading: float) -> int:
        """RoadNetwork.get_closest_lane_index: the first lane of least distance_with_heading. The
        compiled distances pick the candidates (within 1e-6 of the least: they differ from
        numpy's by ULPs at most), numpy's decide among them, as highway-env would."""
        x, y, heading = float(position[0]), float(position[1]), float(heading)
        best, ties = nearest_lane(self.lanes, x, y, heading)
        if not ties:
            return best
        distances = lane_distances(self.lanes, x, y, heading)
        near = np.flatnonzero(distances <= distances.min() + 1e-6)
        exact = [self.distance_with_heading(int(lane), position, heading) for lane in near]
        return int(near[int(np.argmin(exact))])


def _wrap_to_pi(x: float) -> float:
    """highway_env.utils.wrap_to_pi."""
    return ((x + np.pi) % (2 * np.pi)) - np.pi


@njit(cache=True)
def lane_distances(lanes: np.ndarray, x: float, y: float, heading: float) -> np.ndarray:
    """(L,) every lane's distance_with_heading to (x, y, heading), compiled: it shortlists the closest
    lanes; where two are within 1e-6, numpy's distances decide (``LaneGeometry.closest_lane``)."""
    out = np.empty(lanes.shape[0])
    for lane in range(lanes.shape[0]):
        s, r = L.local_coordinates(lanes, lane, x, y)
        angle = np.abs(L.wrap_to_pi(heading - L.heading_at(lanes, lane, s)))
        out[lane] = np.abs(r) + max(s - lanes[lane, L.LENGTH], 0.0) + max(0.0 - s, 0.0) + angle
    return out


@njit(cache=True)
def nearest_lane(lanes: np.ndarray, x: float, y: float, heading: float) -> tuple[int, bool]:
    """``lane_distances``' first least lane, and whether another lies within 1e-6 of it (then
    ``LaneGeometry.closest_lane`` lets numpy's distances decide)."""
    distances = lane_distances(lanes, x, y, heading)
    best = int(np.argmin(distances))
    ties = np.count_nonzero(distances <= distances[best] + 1e-6) > 1
    return best, ties


# --- routes -------------------------------------------------------------------------------------


def shortest_path(graph_keys: dict, start: str, goal: str) -> list[str]:
    """RoadNetwork.shortest_path: the first path ``bfs_paths`` yields (breadth first, successors
    in sorted order, no node twice), [] when there is none.

    :param graph_keys: ``{from: [to, ...]}`` of the road network.
    """
    queue = [(start, [start])]
    while queue:
        node, path = queue.pop(0)
        if node not in graph_keys:
            return []
        for successor in sorted(key for key in graph_keys[node] if key not in path):
            if successor == goal:
                return path + [successor]
            if successor in graph_keys:
                queue.append((successor, path + [successor]))
    return []


def all_shortest_paths(graph_keys: dict) -> dict[tuple[str, str], list[str]]:
    """``shortest_path`` between every pair of nodes, computed once per road."""
    nodes = list(dict.fromkeys([*graph_keys, *(t for tos in graph_keys.values() for t in tos)]))
    return {(a, b): shortest_path(graph_keys, a, b) for a in nodes for b in nodes}


def plan_route(row: np.ndarray, road, destination: str) -> None:
    """ControlledVehicle.plan_route_to on a vehicle row, in place: its lane, then the shortest
    path from that lane's end to ``destination`` (just its lane where there is none)."""
    table = road.table
    lane = int(row[T.LANE])
    start = table.indices[lane]
    path = road.paths.get((start[1], str(destination)), [])
    route = [(int(table.rows[lane, L.FIRST_OF_ROAD]), start[2])]
    route += [(road.geometry.row_of[(path[k], path[k + 1], 0)], -1) for k in range(len(path) - 1)]
    if len(route) > T.MAX_ROUTE:
        raise NotImplementedError(f"the fast backend keeps routes of at most {T.MAX_ROUTE} roads")
    row[T.ROUTED], row[T.ROUTE_START], row[T.ROUTE_END] = 1.0, 0.0, len(route)
    for k, (road_row, lane_id) in enumerate(route):
        row[T.ROUTE + 2 * k], row[T.ROUTE + 2 * k + 1] = road_row, lane_id


def compact_routes(rows: np.ndarray) -> None:
    """Routes as highway-env keeps them after driving: the roads already driven dropped (the
    kernel counts them off with ROUTE_START, highway-env pops them), in place."""
    for row in rows:
        start, end = int(row[T.ROUTE_START]), int(row[T.ROUTE_END])
        if start:
            remaining = row[T.ROUTE + 2 * start : T.ROUTE + 2 * end].copy()
            row[T.ROUTE :] = 0.0
            row[T.ROUTE : T.ROUTE + remaining.size] = remaining
            row[T.ROUTE_START], row[T.ROUTE_END] = 0.0, end - start


# --- vehicles -----------------------------------------------------------------------------------


def mdp_target_speed(speed: float, speeds: np.ndarray) -> float:
    """MDPVehicle's target speed for a vehicle created at ``speed``: the nearest allowed one
    (``speed_to_index`` then ``index_to_speed``)."""
    x = (speed - speeds[0]) / (speeds[-1] - speeds[0])
    return speeds[np.int64(np.clip(np.round(x * (speeds.size - 1)), 0, speeds.size - 1))]


def vehicle_row(road, position: np.ndarray, heading: float, speed: float, kind: int) -> np.ndarray:
    """A vehicle highway-env just built at ``position`` (its lane the closest one), as the row
    ``vehicles_to_array`` makes of it: IDM traffic (the road's traffic class: its size, initial
    lane-change timer and default DELTA), a CONTROLLED ego (an MDPVehicle: target speed snapped to
    the allowed ones) or a PLAIN ego (a kinematic Vehicle, continuous control)."""
    position = np.array(position, dtype=np.float64)
    row = np.zeros(T.VEHICLE_COLUMNS)
    row[T.X], row[T.Y] = position
    row[T.HEADING], row[T.SPEED] = heading, speed
    row[T.LANE] = row[T.TARGET_LANE] = road.geometry.closest_lane(position, heading)
    row[T.DELTA] = road.idm_delta
    row[T.CHECK_COLLISIONS], row[T.KIND] = 1.0, kind
    if kind == T.IDM:
        row[T.TARGET_SPEED] = speed
        row[T.TIMER] = (np.sum(position) * np.pi) % road.lane_change_delay
        row[T.LEN], row[T.WID] = road.npc_length, road.npc_width
    else:
        if kind == T.CONTROLLED:
            row[T.TARGET_SPEED] = mdp_target_speed(speed, road.target_speeds)
        row[T.LEN], row[T.WID] = road.ego_length, road.ego_width
    return row


def ego_kind(control: str) -> int:
    """The ego's row kind: an MDPVehicle under meta-actions, a plain Vehicle under continuous."""
    return T.CONTROLLED if control == "meta" else T.PLAIN


def make_on_lane(road, lane: int, longitudinal: float, speed: float | None, kind: int = T.IDM) -> np.ndarray:
    """RoadObject.make_on_lane: a vehicle on ``lane`` at ``longitudinal``, heading along it, at
    ``speed`` (None: the lane's speed limit)."""
    geometry = road.geometry
    if speed is None:
        speed = geometry.speed_limit(lane)
    return vehicle_row(
        road, geometry.position(lane, longitudinal, 0), geometry.heading_at(lane, longitudinal), speed, kind
    )


def randomize_behavior(row: np.ndarray, rng: np.random.Generator) -> None:
    """IDMVehicle.randomize_behavior: a random DELTA."""
    row[T.DELTA] = rng.uniform(low=DELTA_RANGE[0], high=DELTA_RANGE[1])


def random_lane_index(road, rng: np.random.Generator) -> int:
    """RoadNetwork.random_lane_index as a lane row: the same three draws (``Generator.choice``
    of a list draws ``integers(0, len)``, the same number, without building an array)."""
    graph = road.graph_keys
    froms = road.cache.get("froms")
    if froms is None:
        froms = road.cache["froms"] = list(graph)
    _from = froms[rng.integers(0, len(froms))]
    tos = graph[_from]
    first = road.geometry.row_of[(_from, tos[rng.integers(0, len(tos))], 0)]
    return first + int(rng.integers(int(road.table.rows[first, L.LANE_COUNT])))


def too_close(rows, row: np.ndarray, distance_m: float) -> bool:
    """Whether ``row`` is nearer than ``distance_m`` to any of ``rows`` (a list or an (N,
    VEHICLE_COLUMNS) array), centre to centre, decided as highway-env decides it with
    ``np.linalg.norm`` of each difference: a vectorised distance settles every vehicle farther
    than 1e-9 m from the threshold (the two differ by ULPs), the exact norm the others."""
    if not len(rows):
        return False
    points = np.asarray(rows).reshape(-1, T.VEHICLE_COLUMNS)[:, T.X : T.Y + 1]
    position = row[T.X : T.Y + 1]
    verdict = _nearer_than(points, float(position[0]), float(position[1]), distance_m)
    if verdict >= 0:
        return bool(verdict)
    distances = np.sqrt(((points - position) ** 2).sum(axis=1))
    borderline = points[np.abs(distances - distance_m) <= 1e-9]
    return any(np.linalg.norm(point - position) < distance_m for point in borderline)


@njit(cache=True)
def _nearer_than(points: np.ndarray, x: float, y: float, distance_m: float) -> int:
    """``too_close``'s vectorised test, compiled: 1 when a point is nearer than ``distance_m`` by
    more than 1e-9 m, 0 when none is within 1e-9 m of it either, -1 when only numpy's norms can
    decide (a point on the threshold's ULP band)."""
    borderline = False
    for k in range(points.shape[0]):
        distance = np.sqrt((points[k, 0] - x) ** 2 + (points[k, 1] - y) ** 2)
        if distance < distance_m - 1e-9:
            return 1
        borderline |= abs(distance - distance_m) <= 1e-9
    return -1 if borderline else 0


def arrange_traffic(road, vehicles: list[np.ndarray], ego: int, rng: np.random.Generator) -> tuple[list, int]:
    """HighwayBackend.arrange_traffic on rows: drop every NPC (``keep_npcs`` False), then add
    ``extra_vehicles`` on random lanes at 0.8 x their speed limit, 15 m from any other vehicle
    (at most 10 tries each), routed to the scenario's destination if it has one.

    :returns: the vehicles and the ego's index among them.
    """
    if not road.keep_npcs:
        vehicles, ego = [vehicles[ego]], 0
    wanted = len(vehicles) + road.extra_vehicles
    for _ in range(road.extra_vehicles * 10):
        if len(vehicles) >= wanted:
            break
        lane = random_lane_index(road, rng)
        longitudinal = float(rng.uniform(0, road.geometry.length(lane)))
        limit = road.geometry.speed_limit(lane)
        row = make_on_lane(road, lane, longitudinal, float(limit or 20.0) * 0.8)
        if too_close(vehicles, row, 15):
            continue
        if road.destination:
            plan_route(row, road, road.destination)
        vehicles.append(row)
    return vehicles, ego


def finish(road, vehicles: list[np.ndarray]) -> np.ndarray:
    """The vehicles, then the road's static obstacles, as one (N, VEHICLE_COLUMNS) array."""
    return np.concatenate([np.array(vehicles).reshape(-1, T.VEHICLE_COLUMNS), road.objects])
