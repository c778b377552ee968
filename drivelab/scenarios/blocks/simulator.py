"""K worlds of procedural block maps on the compiled core, each world on its own map.

``BlocksSimulator`` is ``FastSimulator`` for a scenario whose maps come from seeds
(``Scenario.procedural_maps``): an episode's seed picks its map from the scenario's set
(``MapSet.seed_of``). Every map is converted once (``BlocksMap``: a LaneTable with lane rows local
to it) and the tables of the maps loaded so far are stacked; world k reads the rows
``[lane_start[k], lane_stop[k])`` of its map, a view in which its lane indices are the map's own,
so that one compiled call steps all K worlds. ``WorldBatch.roads`` holds the maps the K worlds
drive and ``road_index`` each world's.

Signalised maps run the town's lights: the maps' light rows are stacked like the lanes, each world
draws its intersections' cycle offsets at its episode's start, and the batch exports the states
at the step's end time (one row per lane ending at a light) and the ego's red-light runs.

Episode rules (MetaDrive's, ``metadrive/envs/metadrive_env.py``): arrival within 5 m of the
route's end, out of road when not on a lane or when the ego's body crosses a solid line
(``on_continuous_line_done``), crash on any collision; the time limit is the route's
(``blocks_spawn.route_time_limit_s``).
"""

from __future__ import annotations

import numba
import numpy as np
from numba import njit, prange

from drivelab.errors import UsageError
from drivelab.scenarios.blocks.spawn import (
    TRAFFIC_SPEED_MPS,
    BlocksMap,
    MapSet,
    blocks_map,
    route_time_limit_s,
)
from drivelab.scenarios.blocks.traffic import blocks_simulate
from drivelab.sim.core import lanes as L
from drivelab.sim.core import traffic as T
from drivelab.sim.core.simulator import (
    ARRIVE_NEVER,
    EX_LANE_WIDTH,
    EX_LATERAL,
    EX_ON_ROAD,
    EX_WID,
    FastSimulator,
    export_world,
    meta_action,
)
from drivelab.sim.junctions.pedestrians import light_states_worlds
from drivelab.sim.junctions.traffic import red_light_runs
from drivelab.world.batch import WorldBatch
from drivelab.world.state import RoadMap

ARRIVAL_WINDOW_M = 5.0  # MetaDrive's arrive_dest: within 5 m of the final road's end
# MetaDrive's ego tops out at 80 km/h (metadrive/component/vehicle/vehicle_type.py, max_speed_km_h;
# its default reward's speed term divides by it too)
EGO_MAX_SPEED_MPS = 80.0 / 3.6
# the BlocksMap arrays the simulator stacks over the loaded maps under the same names
_STACKED = ("in_junction", "dead_end", "solid", "light_junction", "light_arm", "signal_xyh", "signal_light")


def _world_kernel(parallel: bool):
    """The worlds' loop: ``blocks_simulate`` of world k's vehicles ``v[k, :count[k]]`` on its map's
    rows ``start[k]:stop[k]`` of the stacked lane tables (``BlocksSimulator.road_arrays``) and its
    lights' states ``light_states[k]``, for the worlds of ``active`` (K,); a thread per world when
    ``parallel``, as ``traffic.simulate_worlds``."""

    def body(
        v, count, lanes, start, stop, p, frames, dt, regulation, active, cap, junction, from_arm, to_arm,
        turn, end_junction, end_arm, light, changeable, ending, successor_start, successors, light_start,
        light_stop, light_states, ego_max_speed_mps,
    ):  # fmt: skip
        for k in prange(v.shape[0]):
            if active[k]:
                a, b = start[k], stop[k]
                blocks_simulate(
                    v[k, : count[k]], lanes[a:b], p, frames, dt, regulation[k], cap, junction[a:b],
                    from_arm[a:b], to_arm[a:b], turn[a:b], end_junction[a:b], end_arm[a:b], light[a:b],
                    changeable[a:b], ending[a:b], successor_start[a : b + 1], successors,
                    light_states[k, : light_stop[k] - light_start[k]], ego_max_speed_mps,
                )  # fmt: skip

    # numba keys its cache on the function's name and code, not on ``parallel``: one name per variant
    body.__qualname__ += "_parallel" if parallel else "_serial"
    return njit(cache=True, parallel=parallel)(body)


_SERIAL, _PARALLEL = _world_kernel(False), _world_kernel(True)


@njit(cache=True)
def apply_meta_map_worlds(v, count, ego, lanes, start, stop, actions, speeds) -> None:
    """``meta_action`` of each world's ego on its map's lane rows."""
    for k in range(v.shape[0]):
        meta_action(v[k, : count[k]], ego[k], lanes[start[k] : stop[k]], actions[k], speeds)


@njit(cache=True)
def export_map_worlds(
    v, count, ego, lanes, start, stop, in_junction, dead_end, solid, floats, ints, flags, vehicles, valid,
    destinations, accelerations,
) -> None:  # fmt: skip
    """``export_world`` of each world on its map's lane rows (arrival is judged on the route),
    then MetaDrive's out of road: off every lane, or the ego's body across a solid line of its
    lane (``solid`` (L_total, 2): left, right; lateral offsets grow to the right)."""
    for k in range(v.shape[0]):
        a, b = start[k], stop[k]
        export_world(
            v[k, : count[k]], ego[k], lanes[a:b], in_junction[a:b], dead_end[a:b], ARRIVE_NEVER, 0.0,
            floats[k], ints[k], flags[k], vehicles[k], valid[k], destinations[k], accelerations[k],
        )  # fmt: skip
        lane = a + int(v[k, ego[k], T.LANE])
        half_body, half_lane = floats[k, EX_WID] / 2, floats[k, EX_LANE_WIDTH] / 2
        lateral = floats[k, EX_LATERAL]
        if (solid[lane, 0] and lateral - half_body < -half_lane) or (
            solid[lane, 1] and lateral + half_body > half_lane
        ):
            flags[k, EX_ON_ROAD] = False


@njit(cache=True)
def clear_dead_ends(v, count, ego, lanes, start, stop, dead_end) -> None:
    """Drop, in every world, the traffic vehicles within a vehicle length of the end of a lane that
    leads nowhere (they leave the map; MetaDrive recycles them too); the kept rows close up in
    order, the freed rows become zeros, ``count`` and ``ego`` follow."""
    for k in range(v.shape[0]):
        lanes_k, dead_k = lanes[start[k] : stop[k]], dead_end[start[k] : stop[k]]
        kept, new_ego = 0, ego[k]
        for j in range(count[k]):
            row = v[k, j]
            lane = int(row[T.LANE])
            leaving = False
            if j != ego[k] and dead_k[lane]:
                s, _ = L.local_coordinates(lanes_k, lane, row[T.X], row[T.Y])
                leaving = s > lanes_k[lane, L.LENGTH] - row[T.LEN]
            if not leaving:
                if j == ego[k]:
                    new_ego = kept
                if kept != j:
                    v[k, kept] = v[k, j]
                kept += 1
        v[k, kept : count[k]] = 0.0
        count[k], ego[k] = kept, new_ego


class BlocksSimulator(FastSimulator):
    """K worlds of a procedural-maps scenario (``procedural_maps``) on the compiled core;
    FastSimulator's parameters (``overrides``: also the map set's keys, MAP_DEFAULTS)."""

    def __init__(self, scenario, traffic: str, control: str, num_worlds: int, overrides: dict | None = None):
        if not scenario.procedural_maps:
            raise UsageError(f"scenario {scenario.name!r} has no procedural maps")
        super().__init__(scenario, traffic, control, num_worlds, overrides)
        k = num_worlds
        self.map_set = MapSet.from_config(self._road.config)
        self.maps: list[BlocksMap] = []
        self._slot_of: dict[int, int] = {}  # map seed → slot in ``maps``
        self.lanes = np.zeros((0, L.LANE_COLUMNS))  # every loaded map's rows, stacked
        self.in_junction = np.zeros(0, dtype=bool)
        self.dead_end = np.zeros(0, dtype=bool)
        self.solid = np.zeros((0, 2), dtype=bool)
        # blocks_traffic's per-lane arrays of every loaded map, stacked: LANE_METADATA, changeable,
        # ending; then the continuations' CSR
        ints, flags = np.zeros(0, dtype=np.int64), np.zeros(0, dtype=bool)
        self.road_arrays = (*[ints] * 7, flags, flags, np.zeros(1, dtype=np.int64), ints)
        self.light_junction = np.zeros(0, dtype=np.int64)  # every loaded map's lights, stacked
        self.light_arm = np.zeros(0, dtype=np.int64)
        self.signal_xyh = np.zeros((0, 3))  # every loaded map's exported lights (one per lane), stacked
        self.signal_light = np.zeros(0, dtype=np.int64)  # their light rows (local to their maps)
        self.lane_bounds = np.zeros(1, dtype=np.int64)  # map m's stacked rows: [bounds[m], bounds[m + 1])
        self.light_bounds = np.zeros(1, dtype=np.int64)  # its stacked lights likewise
        self.signal_bounds = np.zeros(1, dtype=np.int64)  # its stacked exported lights likewise
        self.signal_start = np.zeros(k, dtype=np.int64)  # world k's: [signal_start, signal_stop)
        self.signal_stop = np.zeros(k, dtype=np.int64)
        self.light_start = np.zeros(k, dtype=np.int64)  # world k's lights: [light_start, light_stop)
        self.light_stop = np.zeros(k, dtype=np.int64)
        self.offsets = np.zeros((k, 0))  # (K, J_max) world k's cycle offset of each intersection
        self.light_state = np.zeros((k, 0), dtype=np.int64)  # (K, M_max) LIGHT_* of world k's lights
        self.timings = np.zeros(3)  # the lights' (green, yellow, all red) seconds: the maps' own
        self.map_roads: tuple[RoadMap, ...] = ()  # every loaded map's RoadMap, by slot
        self.roads: tuple[RoadMap, ...] = ()  # the maps the worlds drive now (a batch's roads)
        # the world_map the batch's roads, road index and light gather were made for (``_export``)
        self._maps_of: np.ndarray | None = None
        self.world_map = np.zeros(k, dtype=np.int64)
        self.lane_start = np.zeros(k, dtype=np.int64)
        self.lane_stop = np.zeros(k, dtype=np.int64)
        self.route_time_limit_s = np.full(k, np.inf)
        self.arrival_threshold = ARRIVAL_WINDOW_M
        top_speed = np.full(k, EGO_MAX_SPEED_MPS)  # the sensors' speed scale (ego_state, measurements)
        top_speed.setflags(write=False)
        self._empty = {**self._empty, "max_speed_mps": top_speed}
        self._slot(self.map_set.start_seed)  # the first map: the road the base class converted

    # --- maps -------------------------------------------------------------------------------------
    def _slot(self, seed: int) -> int:
        """The slot of map ``seed`` in ``maps``, converting and stacking it at its first use."""
        slot = self._slot_of.get(seed)
        if slot is not None:
            return slot
        converted = self._road.cache.setdefault("blocks_maps", {})  # shared by this config's simulators
        bmap = converted.get(seed)
        if bmap is None:
            bmap = converted[seed] = blocks_map(self.map_set.generate(seed), self._road)
        slot = self._slot_of[seed] = len(self.maps)
        self.maps.append(bmap)
        self.lanes = np.concatenate([self.lanes, bmap.table.rows])
        for name in _STACKED:
            setattr(self, name, np.concatenate([getattr(self, name), getattr(bmap, name)]))
        self.lane_bounds = np.append(self.lane_bounds, len(self.lanes))
        self.light_bounds = np.append(self.light_bounds, len(self.light_arm))
        self.signal_bounds = np.append(self.signal_bounds, len(self.signal_light))
        *lane_arrays, changeable, ending, successor_start, successors = self.road_arrays
        self.road_arrays = (
            *(np.concatenate([a, b]) for a, b in zip(lane_arrays, bmap.junction_arrays, strict=True)),
            np.concatenate([changeable, bmap.changeable]),
            np.concatenate([ending, bmap.ending]),
            np.concatenate([successor_start[:-1], bmap.successor_start + len(successors)]),
            np.concatenate([successors, bmap.successors]),
        )
        timings = bmap.pg.description.timings
        self.timings = np.array([timings.green_s, timings.yellow_s, timings.all_red_s])
        extra_junctions = bmap.junction_count - self.offsets.shape[1]
        if extra_junctions > 0:
            self.offsets = np.pad(self.offsets, ((0, 0), (0, extra_junctions)))
        extra_lights = len(bmap.light_arm) - self.light_state.shape[1]
        if extra_lights > 0:
            self.light_state = np.pad(self.light_state, ((0, 0), (0, extra_lights)))
        self.map_roads = (*self.map_roads, bmap.road.road_map)
        return slot

    def map_of(self, k: int) -> BlocksMap:
        """World k's map."""
        return self.maps[int(self.world_map[k])]

    # --- episodes -------------------------------------------------------------------------------
    def _start_episodes(self, worlds: np.ndarray, seeds: np.ndarray) -> None:
        """New episodes in ``worlds``: each seed's map, then the scenario's set-up on it (one call
        per world started: the vehicles of each are made by one compiled call)."""
        for k in worlds:
            seed = int(seeds[k])
            slot = self._slot(self.map_set.seed_of(seed))
            bmap = self.maps[slot]
            rows, ego, regulation, offsets = self.scenario.spawn(seed, bmap, self.control)
            self._put_rows(k, rows, ego)
            self.regulation[k] = regulation
            self.world_map[k] = slot
            self.lane_start[k], self.lane_stop[k] = self.lane_bounds[slot : slot + 2]
            lane = int(rows[ego, T.LANE])
            self.route_index[k] = self._route(
                (slot, lane), bmap.routes.get(lane), f"lane {lane} of map {slot}"
            )
            self.route_time_limit_s[k] = route_time_limit_s(self._trackers[self.route_index[k]])
            self.start_lane_id[k] = bmap.table.rows[lane, L.LANE_ID]
            self.light_start[k], self.light_stop[k] = self.light_bounds[slot : slot + 2]
            self.signal_start[k], self.signal_stop[k] = self.signal_bounds[slot : slot + 2]
            self.offsets[k] = 0.0
            self.offsets[k, : len(offsets)] = offsets
            self.light_state[k] = 0
        self.time_s[worlds] = 0.0
        if len(worlds):
            self._update_lights(np.isin(np.arange(self.num_worlds), worlds))

    def _update_lights(self, active: np.ndarray) -> None:
        """The light states of the ``active`` worlds at their time (junctions local to each map)."""
        if self.light_state.shape[1]:
            light_states_worlds(
                self.light_junction, self.light_arm, self.light_start, self.light_stop, self.offsets,
                self.timings, self.time_s, active, self.light_state,
            )  # fmt: skip

    # --- stepping (``FastSimulator.step``'s hooks; the lights as the town's) -----------------------
    _whole_step_kernel = False

    def _before_frames(self) -> np.ndarray:
        return self.lane_start + self.vehicles[np.arange(self.num_worlds), self.ego, T.LANE].astype(np.int64)

    def _simulate(self, frames: int, active: np.ndarray) -> None:
        """A released vehicle cruises on at TRAFFIC_SPEED_MPS, the egos at most at EGO_MAX_SPEED_MPS."""
        kernel = _PARALLEL if self.num_worlds > 1 and numba.get_num_threads() > 1 else _SERIAL
        kernel(
            self.vehicles, self.count, self.lanes, self.lane_start, self.lane_stop, self.idm, frames,
            self.dt_s, self.regulation, active, TRAFFIC_SPEED_MPS, *self.road_arrays, self.light_start,
            self.light_stop, self.light_state, EGO_MAX_SPEED_MPS,
        )  # fmt: skip

    def _after_frames(self, active: np.ndarray, previous_lane: np.ndarray) -> None:
        """Traffic at a dead end leaves; the ego runs a red light when it leaves a lane whose light
        is red for one starting where that lane ends."""
        clear_dead_ends(
            self.vehicles, self.count, self.ego, self.lanes, self.lane_start, self.lane_stop, self.dead_end
        )
        light = self.road_arrays[6][previous_lane]  # the light of the lane the ego was on (local row)
        lane = self._before_frames()
        self._red_light = red_light_runs(self.lanes, previous_lane, lane, light, self.light_state, active)

    def apply_controls(self, controls: np.ndarray) -> None:
        """The egos' meta-actions on their maps' lanes, or continuous controls (as FastSimulator)."""
        if self.control != "meta":
            super().apply_controls(controls)
            return
        actions = np.asarray(controls).reshape(self.num_worlds).astype(np.int64)
        apply_meta_map_worlds(
            self.vehicles, self.count, self.ego, self.lanes, self.lane_start, self.lane_stop, actions,
            self._road.target_speeds,
        )  # fmt: skip

    # --- export ---------------------------------------------------------------------------------
    def _export(self) -> WorldBatch:
        buffers = self._export_buffers()
        export_map_worlds(
            self.vehicles, self.count, self.ego, self.lanes, self.lane_start, self.lane_stop,
            self.in_junction, self.dead_end, self.solid, *buffers,
        )  # fmt: skip
        if self._maps_of is None or not np.array_equal(self._maps_of, self.world_map):
            used, index = np.unique(self.world_map, return_inverse=True)
            self.roads = tuple(self.map_roads[slot] for slot in used)
            count = self.signal_stop - self.signal_start  # the lights each world exports
            column = np.arange(max(int(count.max()), 1))
            light_valid = column[None, :] < count[:, None]
            rows = np.where(light_valid, self.signal_start[:, None] + column[None, :], 0)
            self._road_index, self._light_gather = index.astype(np.int64), (rows, light_valid)
            self._road_index.setflags(write=False)
            light_valid.setflags(write=False)
            self._maps_of = self.world_map.copy()
        self._empty = {**self._empty, "road_index": self._road_index}
        batch = self._export_arrays(*buffers)
        if not self.light_state.shape[1]:
            return batch  # no map of the set has lights
        rows, light_valid = self._light_gather
        state = np.take_along_axis(self.light_state, self.signal_light[rows], axis=1)
        lights = np.concatenate([self.signal_xyh[rows], state[..., None]], axis=2)
        lights[~light_valid] = 0.0
        events = batch.events.replaced(red_light_crossed=self._red_light.copy())
        return batch.replaced(events=events, traffic_lights=lights, light_valid=light_valid)
