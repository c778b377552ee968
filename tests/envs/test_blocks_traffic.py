"""Traffic rules of the ``blocks`` scenario (issue 18): the town's traffic lights at signalised
intersections (cycle, NPCs stopping at red, the ego's red-light runs, the exported lights) and
MOBIL lane changes where a road's lanes run side by side."""

import numpy as np
import pytest

from drivelab.envs.vector import VectorDriveEnv
from drivelab.scenarios import get_scenario
from drivelab.scenarios.blocks.spawn import TRAFFIC_SPEED_MPS, _traffic_rows
from drivelab.sim.core import lanes as L
from drivelab.sim.core import traffic as T
from drivelab.sim.core.backend import FastBackend, fast_simulator
from drivelab.sim.junctions.rules import LightTimings, light_state
from drivelab.world.batch import WorldBatch
from drivelab.world.state import LIGHT_GREEN, LIGHT_RED, LIGHT_YELLOW

BLOCKS = get_scenario("blocks")
SIGNALISED = {"map": "XT", "num_scenarios": 3, "lane_count": 2, "signalised": True}


def _approach(bmap) -> int:
    """The lane row of the right-hand lane ending at intersection 0's arm 0 (its light's lane)."""
    desc = bmap.pg.description
    rows = np.flatnonzero((desc.end_junction == 0) & (desc.end_arm == 0) & (desc.light >= 0))
    return int(rows[-1])


def _add_npc(simulator, k: int, lane: int, s: float) -> int:
    """An IDM vehicle at ``s`` on ``lane`` of world k's map at the traffic's cruising speed, its
    route the first continuation of every lane; returns its row."""
    bmap = simulator.map_of(k)
    row = np.zeros((1, T.VEHICLE_COLUMNS))
    _traffic_rows(
        bmap.table.rows, np.array([lane]), np.array([s]), np.array([4.0]), np.zeros((1, T.MAX_ROUTE - 1)),
        bmap.successor_start, bmap.successors, TRAFFIC_SPEED_MPS, 5.0, 2.0, 1.0, row,
    )  # fmt: skip
    n = simulator.count[k]
    simulator._fit(n + 1)
    simulator.vehicles[k, n] = row[0]
    simulator.count[k] = n + 1
    return n


def _offset_for(phase_s: float, cycle_s: float) -> float:
    """The cycle offset at which a junction is ``phase_s`` into its cycle at time 0."""
    return (-phase_s) % cycle_s


# --- lights --------------------------------------------------------------------------------------
def test_signalised_maps_run_the_towns_light_cycle():
    """``signalised: true`` (refused before lights ran on blocks) puts a light at every arm of the
    X and T intersections; each light follows the town's cycle (10 s green, 3 s yellow, 1 s all
    red, arms 0/2 then 1/3) from its junction's random offset, and the batch exports it at the
    stop point of each lane of its arm."""
    simulator = fast_simulator(BLOCKS, "empty", "continuous", 3, SIGNALISED)
    batch = simulator.reset_where(np.ones(3, dtype=bool), np.arange(3))
    timings = LightTimings()
    assert list(simulator.timings) == [timings.green_s, timings.yellow_s, timings.all_red_s]
    seen = set()
    for _ in range(300):  # 30 s: more than a cycle (28 s)
        for k in range(3):
            bmap = simulator.map_of(k)
            m = len(bmap.light_arm)
            assert m == 7 and bmap.junction_count == 2  # X: 4 arms, T: 3
            offsets = simulator.offsets[k]
            assert ((offsets >= 0) & (offsets < timings.cycle_s)).all()
            expected = [
                light_state(timings, arm, batch.time_s[k], offsets[j])
                for j, arm in zip(bmap.light_junction, bmap.light_arm, strict=True)
            ]
            np.testing.assert_array_equal(simulator.light_state[k, :m], expected)
            lanes = len(bmap.signal_light)
            assert lanes == 2 * m  # two lanes per arm
            np.testing.assert_array_equal(
                batch.traffic_lights[k, :lanes, 3], np.array(expected)[bmap.signal_light]
            )
            np.testing.assert_array_equal(batch.traffic_lights[k, :lanes, :3], bmap.signal_xyh)
            assert batch.light_valid[k, :lanes].all() and not batch.light_valid[k, lanes:].any()
            seen |= set(expected)
        batch = simulator.step(np.zeros((3, 2)))
    assert seen == {LIGHT_GREEN, LIGHT_YELLOW, LIGHT_RED}
    # three maps of one set, three different sets of offsets
    assert len({tuple(o) for o in simulator.offsets}) == 3


def test_unsignalised_maps_have_no_lights():
    simulator = fast_simulator(BLOCKS, "regular", "continuous", 2, {"map": "XT", "num_scenarios": 2})
    batch = simulator.reset_where(np.ones(2, dtype=bool), np.arange(2))
    assert batch.traffic_lights.shape == (2, 0, 4) and simulator.light_state.shape[1] == 0


@pytest.mark.parametrize(("phase_s", "stops"), [(13.5, True), (0.0, False)])
def test_npcs_stop_at_a_red_light_on_a_block_map(phase_s, stops):
    """Scripted: an NPC 30 m before intersection 0's arm-0 stop line at 30 km/h. With arm 0 red
    for the next 14.5 s it never passes the line (front bumper behind it) and comes to a crawl
    within 3 m of it; with 10 s of green ahead it drives into the intersection."""
    simulator = fast_simulator(BLOCKS, "empty", "continuous", 1, SIGNALISED)
    simulator.reset_where(np.ones(1, dtype=bool), np.array([0]))
    bmap = simulator.map_of(0)
    lane = _approach(bmap)
    rows = bmap.table.rows
    simulator.offsets[0, 0] = _offset_for(phase_s, LightTimings().cycle_s)
    simulator._update_lights(np.ones(1, dtype=bool))
    npc = _add_npc(simulator, 0, lane, rows[lane, L.LENGTH] - 30.0 - 2.5)
    entered = False
    for _ in range(100):  # 10 s
        simulator.step(np.zeros((1, 2)))
        row = simulator.vehicles[0, npc]
        here = int(row[T.LANE])
        entered |= bmap.pg.description.junction[here] == 0
        if here == lane and stops:
            s, _ = L.local_coordinates(rows, lane, row[T.X], row[T.Y])
            assert s + row[T.LEN] / 2 <= rows[lane, L.LENGTH]  # never past the stop line on red
    assert entered != stops
    if stops:
        assert int(row[T.LANE]) == lane and abs(row[T.SPEED]) < 0.5
        assert rows[lane, L.LENGTH] - (s + row[T.LEN] / 2) < 3.0


@pytest.mark.parametrize(("phase_s", "red"), [(13.5, True), (0.0, False)])
def test_the_ego_running_a_red_light_is_an_event(phase_s, red):
    """The ego crossing intersection 0's arm-0 stop line: a red-light event on red only; the light
    ahead is reported (``info["traffic_light"]``) before the line."""
    env = VectorDriveEnv(1, scenario="blocks", obs="kinematics", traffic="empty", backend_options=SIGNALISED)
    env.reset(seed=0)
    simulator = env.simulator
    bmap = simulator.map_of(0)
    lane = _approach(bmap)
    rows = bmap.table.rows
    simulator.offsets[0, 0] = _offset_for(phase_s, LightTimings().cycle_s)
    simulator._update_lights(np.ones(1, dtype=bool))
    ego = simulator.vehicles[0, simulator.ego[0]]
    s = rows[lane, L.LENGTH] - 10.0
    ego[T.X], ego[T.Y] = L.position(rows, lane, s, 0.0)
    ego[T.HEADING], ego[T.SPEED], ego[T.LANE] = L.heading_at(rows, lane, s), 10.0, lane
    events, labels = [], []
    for _ in range(15):  # 1.5 s at 10 m/s: across the line (a red run ends the episode)
        _, _, terminated, _, info = env.step(np.zeros((1, 2)))
        events.append(bool(simulator.batch.events.red_light_crossed[0]))
        labels.append(info["traffic_light"][0])
        if terminated[0]:
            break
    assert labels[0] == ("red_or_yellow" if red else "green")
    assert events == [False] * (len(events) - 1) + [red] and (terminated[0] == red)


def test_signalised_k_worlds_step_as_k_single_worlds_and_repeat_with_the_seed():
    """K worlds on different signalised maps, restarting at different steps, equal K one-world
    simulators (vehicles, light states, exported lights, red-light events); the same seeds
    give the same episodes."""
    worlds, options = 3, {**SIGNALISED, "traffic_density": 0.3}
    simulator = fast_simulator(BLOCKS, "regular", "meta", worlds, options)
    again = fast_simulator(BLOCKS, "regular", "meta", worlds, options)
    backends = [FastBackend(BLOCKS, "regular", "meta", options) for _ in range(worlds)]
    rng = np.random.default_rng(5)
    seeds = np.arange(worlds)
    simulator.reset_where(np.ones(worlds, dtype=bool), seeds)
    again.reset_where(np.ones(worlds, dtype=bool), seeds)
    singles = [backend.reset(int(seed)) for backend, seed in zip(backends, seeds, strict=True)]
    for t in range(60):
        restart = np.arange(worlds) == t % worlds if t % 20 == 19 else np.zeros(worlds, dtype=bool)
        seeds = seeds + worlds * restart
        controls = rng.integers(5, size=worlds)
        batch = simulator.step(controls, restart, seeds)
        other = again.step(controls, restart, seeds)
        for k in range(worlds):
            singles[k] = backends[k].reset(int(seeds[k])) if restart[k] else backends[k].step(controls[k])
            n = simulator.count[k]
            np.testing.assert_array_equal(simulator.vehicles[k, :n], backends[k].vehicles)
            np.testing.assert_array_equal(simulator.vehicles[k, :n], again.vehicles[k, :n])
        stacked = WorldBatch.stack(singles)
        np.testing.assert_array_equal(batch.traffic_lights, stacked.traffic_lights)
        np.testing.assert_array_equal(batch.light_valid, stacked.light_valid)
        np.testing.assert_array_equal(batch.events.red_light_crossed, stacked.events.red_light_crossed)
        np.testing.assert_array_equal(batch.traffic_lights, other.traffic_lights)


# --- lane changes --------------------------------------------------------------------------------
def test_traffic_changes_lanes_on_a_multi_lane_straight_map():
    """Dense traffic on three straight blocks of 3 lanes, 30 s: vehicles change lanes (MOBIL),
    only on lanes where that is allowed, stay on the road and do not crash."""
    simulator = fast_simulator(
        BLOCKS, "dense", "continuous", 2, {"map": "SSS", "lane_count": 3, "num_scenarios": 2}
    )
    simulator.reset_where(np.ones(2, dtype=bool), np.array([0, 1]))
    changes = 0
    for _ in range(300):
        simulator.step(np.zeros((2, 2)))
        for k in range(2):
            bmap = simulator.map_of(k)
            rows, v = bmap.table.rows, simulator.vehicles[k, 1 : simulator.count[k]]
            lane, target = v[:, T.LANE].astype(int), v[:, T.TARGET_LANE].astype(int)
            changing = (lane != target) & (rows[lane, L.FIRST_OF_ROAD] == rows[target, L.FIRST_OF_ROAD])
            assert bmap.changeable[lane[changing]].all() and bmap.changeable[target[changing]].all()
            changes += int(changing.sum())
            for row, here in zip(v, lane, strict=True):
                _, lateral = L.local_coordinates(rows, here, row[T.X], row[T.Y])
                assert abs(lateral) <= rows[here, L.WIDTH] / 2 + 0.5
            assert (v[:, T.CRASHED] == 0).all()
    assert changes > 0


def test_lane_changes_are_allowed_side_by_side_only():
    """Straight and curve roads of several lanes allow changes; intersections, roundabouts and the
    ramps' tapers do not; the in-ramp's acceleration lane is an ending lane."""
    simulator = fast_simulator(BLOCKS, "empty", "continuous", 1, {"map": "CrOX", "lane_count": 2})
    simulator.reset_where(np.ones(1, dtype=bool), np.array([0]))
    bmap = simulator.map_of(0)
    desc, rows = bmap.pg.description, bmap.table.rows
    letters = np.array([bmap.pg.blocks[b].letter for b in bmap.pg.lane_block])
    assert not bmap.changeable[desc.junction >= 0].any()
    assert not bmap.changeable[bmap.in_junction].any()
    assert bmap.changeable[(letters == "C") & (rows[:, L.LANE_COUNT] >= 2)].all()
    kinds = rows[:, L.KIND]
    road = rows[:, L.FIRST_OF_ROAD].astype(int)
    mixed = np.array([len(set(kinds[road == r])) > 1 for r in road])
    assert not bmap.changeable[mixed].any()
    assert bmap.ending.any() and (letters[bmap.ending] == "r").all() and bmap.changeable[bmap.ending].all()


def test_affordances_and_the_topdown_lights_channel_see_block_lights():
    """The affordances sensor reads the red light 10 m ahead in the ego's lane (per-lane light
    rows), and topdown's optional lights channel draws stop bars, only where there are lights."""
    from drivelab.perception.affordances import FIELDS
    from drivelab.perception.sensors import make_sensor

    simulator = fast_simulator(BLOCKS, "empty", "continuous", 2, SIGNALISED)
    simulator.reset_where(np.ones(2, dtype=bool), np.arange(2))
    for k in range(2):
        bmap = simulator.map_of(k)
        lane, rows = _approach(bmap), bmap.table.rows
        simulator.offsets[k, 0] = _offset_for(13.5, LightTimings().cycle_s)
        ego = simulator.vehicles[k, simulator.ego[k]]
        s = rows[lane, L.LENGTH] - 10.0 - ego[T.LEN] / 2 * (k == 1)
        ego[T.X], ego[T.Y] = L.position(rows, lane, s, 0.0)
        ego[T.HEADING], ego[T.LANE] = L.heading_at(rows, lane, s), lane
    simulator._update_lights(np.ones(2, dtype=bool))
    batch = simulator._export()
    state, distance = batch.light_ahead(40.0)
    np.testing.assert_array_equal(state, [LIGHT_RED, LIGHT_RED])
    np.testing.assert_allclose(distance, [10.0, 10.0 + 2.5], atol=1e-9)
    affordances = make_sensor("affordances")
    affordances.reset(batch, [np.random.default_rng(0)] * 2)
    observed = affordances.observe(batch)
    assert (observed[:, FIELDS.index("light_red")] == 1).all()
    topdown = make_sensor("topdown:lights=true")
    topdown.reset(batch, [np.random.default_rng(0)] * 2)
    image = topdown.observe(batch)
    assert image.shape[1] == 6 and (image[:, 5] > 0).any(axis=(1, 2)).all()
    unsignalised = fast_simulator(BLOCKS, "empty", "continuous", 2, {**SIGNALISED, "signalised": False})
    plain = unsignalised.reset_where(np.ones(2, dtype=bool), np.arange(2))
    topdown.reset(plain, [np.random.default_rng(0)] * 2)
    assert (topdown.observe(plain)[:, 5] == 0).all()


def test_the_ego_tops_out_at_metadrives_80_kmh():
    """Full throttle on a straight map for 20 s: the ego reaches 80 km/h and no more (MetaDrive's
    top speed; highway-env's 40 m/s elsewhere), and the sensors' speed scale is it."""
    simulator = fast_simulator(BLOCKS, "empty", "continuous", 1, {"map": "SSS"})
    batch = simulator.reset_where(np.ones(1, dtype=bool), np.array([0]))
    np.testing.assert_allclose(batch.max_speed_mps, [80 / 3.6])
    speeds = []
    for _ in range(200):
        speeds.append(simulator.step(np.array([[1.0, 0.0]])).ego.speed_mps[0])
    assert 80 / 3.6 - 0.5 < max(speeds) <= 80 / 3.6 + 0.3
    highway = fast_simulator(get_scenario("highway"), "empty", "continuous", 1)
    assert (highway.reset_where(np.ones(1, dtype=bool), np.array([0])).max_speed_mps == 40.0).all()
