"""K worlds of the signalised town on the compiled core: lights, pedestrians and town traffic.

``TownSimulator`` is ``FastSimulator``'s town, with per world what the reference (``HighwayBackend``
on ``TownEnv``) keeps as objects: vehicle rows (the ego and KIND ``TOWN`` traffic) and pedestrian
rows in the reference's list orders, the light offsets, the world's PCG64 words (every draw of the
frames and retargets, in the reference's order), and the ego's planned route, which grows when a
training episode retargets on arrival.

One policy step of a world (``_simulate_town``): the light states at the step's end time, then per
frame: every vehicle acts (``junctions.traffic.town_act``), the pedestrians walk, the vehicles step
and collide, moving vehicles hit pedestrians, wrecks are towed (``pedestrians``). Then the ego's
route progress, its retarget and the events (a red light run judged on the lanes before and after
the step, as the reference judges it).
"""

from __future__ import annotations

import dataclasses

import numba
import numpy as np
from numba import njit, prange

from drivelab.scenarios.town.spawn import TownSetup, route_tracker
from drivelab.sim.core import traffic as T
from drivelab.sim.core.borrow import borrowed
from drivelab.sim.core.simulator import FastSimulator
from drivelab.sim.junctions import rows as R
from drivelab.sim.junctions.pedestrians import (
    clear_wrecks,
    hit_pedestrians,
    light_states_worlds,
    walk_pedestrians,
)
from drivelab.sim.junctions.rules import PEDESTRIAN_SIZE_M, LightTimings
from drivelab.sim.junctions.traffic import (
    random_goal,
    red_light_runs,
    road_arrays_tuple,
    town_act,
    town_frame_cache,
    town_step,
)
from drivelab.sim.route import RouteTracker
from drivelab.world.batch import COLLISION_NONE, COLLISION_PEDESTRIAN, COLLISION_VEHICLE, WorldBatch


@njit(cache=True)
def _simulate_town(
    v, count, ego, peds, pcount, lanes, p, coords, done, trig, junction, from_arm, to_arm, turn,
    end_junction, end_arm, light, street_lanes, routes, route_length, search, search_offset, search_size,
    discs, states, rng, frames, dt,
):  # fmt: skip
    """One policy step (``frames`` frames of ``dt``) of one world; returns (count, ego)."""
    v, peds, lanes, p, coords, done, trig, states, rng = borrowed(
        (v, peds, lanes, p, coords, done, trig, states, rng)
    )  # its arrays without reference counts (``borrow``)
    junction, from_arm, to_arm, turn, end_junction, end_arm, light = borrowed(
        (junction, from_arm, to_arm, turn, end_junction, end_arm, light)
    )
    street_lanes, routes, route_length, search, search_offset, search_size, discs = borrowed(
        (street_lanes, routes, route_length, search, search_offset, search_size, discs)
    )
    for _ in range(frames):
        town_act(
            v, count, peds, pcount, lanes, p, coords, done, trig, junction, from_arm, to_arm, turn,
            end_junction, end_arm, light, street_lanes, routes, route_length, search, search_offset,
            search_size, discs, states, rng,
        )  # fmt: skip
        walk_pedestrians(peds, pcount, v, count, dt, rng)
        town_step(v, count, lanes, dt)
        T.handle_collisions(v[:count], dt)
        hit_pedestrians(peds, pcount, v, count, ego)
        count, ego = clear_wrecks(v, count, ego, dt)
    return count, ego


def _town_kernel(parallel: bool):
    def body(
        v, count, ego, peds, pcount, lanes, p, coords, done, trig, junction, from_arm, to_arm, turn,
        end_junction, end_arm, light, street_lanes, routes, route_length, search, search_offset, search_size,
        discs, states, rng, frames, dt, active,
    ):  # fmt: skip
        for k in prange(v.shape[0]):
            if active[k]:
                count[k], ego[k] = _simulate_town(
                    v[k], count[k], ego[k], peds[k], pcount[k], lanes, p, coords[k], done[k], trig[k],
                    junction, from_arm, to_arm, turn, end_junction, end_arm, light, street_lanes, routes,
                    route_length, search, search_offset, search_size, discs, states[k], rng[k], frames, dt,
                )  # fmt: skip

    # numba keys its cache on the function's name and code, not on ``parallel``: one name per variant
    body.__qualname__ += "_parallel" if parallel else "_serial"
    return njit(cache=True, parallel=parallel)(body)


_SERIAL, _PARALLEL = _town_kernel(False), _town_kernel(True)


@njit(cache=True)
def export_pedestrians(peds, pcount, pedestrians, pedestrian_valid, hit_ego) -> None:
    """The pedestrians not crashed (spawn order) of K worlds into zeroed ``pedestrians`` (K, P, 6)
    (x, y, heading, speed, length, width) with ``pedestrian_valid``; ``hit_ego`` (K,): one of them
    was hit by the ego (the collision's kind)."""
    for k in range(peds.shape[0]):
        n = 0
        for i in range(pcount[k]):
            if peds[k, i, R.P_HIT_EGO] > 0:
                hit_ego[k] = True
            if peds[k, i, R.P_CRASHED] > 0:
                continue
            pedestrians[k, n, 0], pedestrians[k, n, 1] = peds[k, i, R.P_X], peds[k, i, R.P_Y]
            pedestrians[k, n, 2], pedestrians[k, n, 3] = peds[k, i, R.P_HEADING], peds[k, i, R.P_SPEED]
            pedestrians[k, n, 4] = pedestrians[k, n, 5] = PEDESTRIAN_SIZE_M
            pedestrian_valid[k, n] = True
            n += 1


class TownSimulator(FastSimulator):
    """K worlds of the town on the compiled kernels; FastSimulator's parameters (``overrides``:
    TownEnv's keys, "layout", "fixed_routes", "retarget", …)."""

    def __init__(self, scenario, traffic: str, control: str, num_worlds: int, overrides: dict | None = None):
        super().__init__(scenario, traffic, control, num_worlds, overrides)
        road, k = self._road, num_worlds
        self.setup = TownSetup.of(road)
        arrays = self.arrays = self.setup.arrays
        self.road_args = road_arrays_tuple(arrays, self.lanes)
        self.road = dataclasses.replace(self.road, crossings=arrays.crossings)
        self.roads = (self.road,)
        self.retarget = bool(road.config.get("retarget"))
        timings = LightTimings(**road.config["light_timings"])
        self.timings = np.array([timings.green_s, timings.yellow_s, timings.all_red_s])
        self.in_junction = arrays.in_junction
        n_max = 1 + self.setup.vehicles_count
        p_max = max(self.setup.pedestrians_count, 1)
        self.vehicles = np.zeros((k, n_max, T.TOWN_VEHICLE_COLUMNS))
        self.peds = np.zeros((k, p_max, R.PEDESTRIAN_COLUMNS))
        self.pcount = np.zeros(k, dtype=np.int64)
        self.offsets = np.zeros((k, arrays.junction_count))
        self.rng_words = np.zeros((k, 6), dtype=np.uint64)
        self.light_state = np.zeros((k, len(arrays.light_junction)), dtype=np.int64)
        self._light_rows = np.zeros(k, dtype=np.int64), np.full(k, len(arrays.light_junction), dtype=np.int64)
        self.route_time_limit_s = np.full(k, np.inf)
        self.ego_routes: list[list[int]] = [[] for _ in range(k)]
        self.trackers: list[RouteTracker | None] = [None] * k
        self.route_index = np.arange(k)
        cache = [town_frame_cache(n_max, p_max, len(self.lanes)) for _ in range(k)]
        self.coords, self.done, self.trig = (np.stack(parts) for parts in zip(*cache, strict=True))
        self._light_valid = np.ones((k, len(arrays.light_junction)), dtype=bool)
        self._light_valid.setflags(write=False)

    # --- episodes -------------------------------------------------------------------------------
    def _start_episodes(self, worlds: np.ndarray, seeds: np.ndarray) -> None:
        """New town episodes in ``worlds`` from ``seeds[k]`` (the town's set-up, one per world)."""
        for k in worlds:
            rows, ego, _, episode = self.scenario.spawn(int(seeds[k]), self._road, self.control)
            self._put_rows(k, rows, ego)
            self.peds[k] = 0.0
            self.peds[k, : len(episode.pedestrians)] = episode.pedestrians
            self.pcount[k] = len(episode.pedestrians)
            self.offsets[k] = episode.light_offsets_s
            self.rng_words[k] = episode.rng_state
            self.route_time_limit_s[k] = episode.route_time_limit_s
            self.ego_routes[k] = [int(lane) for lane in episode.ego_route]
            self._set_route(k)
        self.time_s[worlds] = 0.0
        if worlds.size:
            self._pad_world_routes(worlds)  # once for all the worlds that started
            self._update_lights(np.isin(np.arange(self.num_worlds), worlds))

    def _set_route(self, k: int) -> None:
        """World k's route polyline from its planned lanes (``HighwayBackend.route_for``); the
        padded arrays follow with ``_pad_world_routes``."""
        self.trackers[k] = route_tracker(self.setup, self.ego_routes[k])
        self._route_version += 1

    def _pad_world_routes(self, changed) -> None:
        """Every world's route as padded (K, S) arrays, last point repeated (``_pad_routes``): only
        the rows of the worlds ``changed`` are rewritten while their routes fit the arrays' width
        (a route's values do not depend on the width: readers stop at its point count)."""
        width = self.r_polyline.shape[1] if self._trackers else 0  # no arrays before the first episodes
        started = next(t for t in self.trackers if t is not None)  # stands in for worlds not yet reset
        self._trackers = [t if t is not None else started for t in self.trackers]
        if all(len(self._trackers[k].polyline) <= width for k in changed):
            for k in changed:
                self._pad_route(k)
            return
        self._pad_routes()

    def _routes_stale(self, route_index: np.ndarray) -> bool:
        """Every world keeps its own route row (route_index is constant): stale on any change."""
        return self._route_cache is None or self._route_cache[2] != self._route_version

    def _update_lights(self, active: np.ndarray) -> None:
        aj, aa, (start, stop) = self.arrays.light_junction, self.arrays.light_arm, self._light_rows
        light_states_worlds(
            aj, aa, start, stop, self.offsets, self.timings, self.time_s, active, self.light_state
        )

    # --- stepping (``FastSimulator.step``'s hooks) --------------------------------------------------
    _whole_step_kernel = False

    def _before_frames(self) -> np.ndarray:
        return self.vehicles[np.arange(self.num_worlds), self.ego, T.LANE].astype(np.int64)

    def _simulate(self, frames: int, active: np.ndarray) -> None:
        kernel = _PARALLEL if self.num_worlds > 1 and numba.get_num_threads() > 1 else _SERIAL
        kernel(
            self.vehicles, self.count, self.ego, self.peds, self.pcount, self.lanes, self.idm,
            self.coords, self.done, self.trig, *self.road_args, self.light_state, self.rng_words,
            frames, self.dt_s, active,
        )  # fmt: skip

    def _after_frames(self, active: np.ndarray, previous_lane: np.ndarray) -> None:
        """The red lights the egos ran, the progress of the worlds that stepped and, where
        ``retarget`` is set, a route on for the egos that arrived."""
        lane = self._before_frames()
        light = self.arrays.light[previous_lane]
        self._red_light = red_light_runs(self.lanes, previous_lane, lane, light, self.light_state, active)
        self._project(fresh=np.zeros(self.num_worlds, dtype=bool), update=active)
        if self.retarget:
            self._retarget(active)

    def _projected(self, restart: np.ndarray) -> np.ndarray:
        return restart  # the others were projected before their routes grew (``_after_frames``)

    def _retarget(self, active: np.ndarray) -> None:
        """TownEnv.extend_route in every world that arrived: a random route on from the end of
        the ego's, drawn from the world's generator after its frames; the meta-action ego's
        planned lanes grow by it; the progress is projected on the longer route."""
        arrays = self.arrays
        for k in np.flatnonzero(active & self._route_ended()):
            start = self.ego_routes[k][-1]
            goal = random_goal(self.lanes, start, arrays.street_lanes, arrays.route_length, self.rng_words[k])
            more = arrays.routes[start, goal, 1 : arrays.route_length[start, goal]] if goal >= 0 else []
            self.ego_routes[k] = self.ego_routes[k] + [int(lane) for lane in more]
            row = self.vehicles[k, self.ego[k]]
            if row[T.KIND] == T.CONTROLLED:
                _append_route(row, more)
            self._set_route(k)
            self._pad_world_routes([k])
            self._project(fresh=np.zeros(self.num_worlds, dtype=bool), update=np.arange(self.num_worlds) == k)

    # --- export ---------------------------------------------------------------------------------
    def _export(self) -> WorldBatch:
        """FastSimulator's export (the arrival at the route's end is judged there), then the
        pedestrians and the lights."""
        k = self.num_worlds
        batch = super()._export()
        pedestrians = np.zeros((k, self.peds.shape[1], 6))
        pedestrian_valid = np.zeros((k, self.peds.shape[1]), dtype=bool)
        hit_ego = np.zeros(k, dtype=bool)
        export_pedestrians(self.peds, self.pcount, pedestrians, pedestrian_valid, hit_ego)
        kind = np.where(hit_ego, COLLISION_PEDESTRIAN, COLLISION_VEHICLE)
        events = batch.events.replaced(  # a pedestrian hit is its own kind; the lights' red runs
            collision_kind=np.where(batch.events.collided, kind, COLLISION_NONE).astype(np.int8),
            red_light_crossed=self._red_light.copy(),
        )
        lights = np.empty((k, len(self.arrays.light_xyh), 4))  # every world's lights and their states
        lights[..., :3] = self.arrays.light_xyh
        lights[..., 3] = self.light_state
        return batch.replaced(
            events=events, traffic_lights=lights, light_valid=self._light_valid, pedestrians=pedestrians,
            pedestrian_valid=pedestrian_valid,
        )  # fmt: skip


def _append_route(row: np.ndarray, lanes) -> None:
    """Append lane rows to a vehicle row's planned route (roads of one lane: road = lane row),
    closing up the entries already driven when the row would overflow."""
    start, end = int(row[T.ROUTE_START]), int(row[T.ROUTE_END])
    capacity = (row.size - T.ROUTE) // 2
    if end + len(lanes) > capacity:
        kept = row[T.ROUTE + 2 * start : T.ROUTE + 2 * end].copy()
        row[T.ROUTE : T.ROUTE + kept.size] = kept
        start, end = 0, end - start
        row[T.ROUTE_START] = 0.0
    if end + len(lanes) > capacity:
        raise NotImplementedError(f"the town's vehicle rows keep routes of at most {capacity} roads")
    for lane in lanes:
        row[T.ROUTE + 2 * end], row[T.ROUTE + 2 * end + 1] = lane, 0.0
        end += 1
    row[T.ROUTE_END], row[T.ROUTED] = end, 1.0
