"""The ``blocks`` scenario (procedural maps, issue 18) on the compiled core: map sets, K worlds on
different maps batched, MetaDrive's episode rules, traffic along every block type, the
``metadrive`` reward, the sensors and the command line."""

import numpy as np
import pytest
from typer.testing import CliRunner

from drivelab.cli import app
from drivelab.envs.vector import VectorDriveEnv
from drivelab.errors import UsageError
from drivelab.perception.sensors import make_sensor
from drivelab.rewards.shapers import RewardShaper
from drivelab.scenarios import get_scenario
from drivelab.scenarios.blocks.pg_map import generate_map
from drivelab.scenarios.blocks.spawn import (
    EGO_SPAWN_S_M,
    ROUTE_PACE_MPS,
    ROUTE_START_S,
    SPAWN_CLEARANCE_M,
    MapSet,
)
from drivelab.sim.core import lanes as L
from drivelab.sim.core import traffic as T
from drivelab.sim.core.backend import FastBackend, fast_simulator
from drivelab.sim.reference.highway import HighwayBackend
from drivelab.world.batch import WorldBatch
from drivelab.world.state import Events
from tests.perception.test_batched_sensors import SPECS, _run
from tests.worlds import world

BLOCKS = get_scenario("blocks")
MAPS = {"map": "OSX", "num_scenarios": 4}  # seeds 0..3: four different OSX maps


def _simulator(worlds: int, control: str = "continuous", traffic: str = "regular", **options):
    return fast_simulator(BLOCKS, traffic, control, worlds, {**MAPS, **options})


def _sequence(worlds: int = 4, steps: int = 7, control: str = "continuous"):
    """K one-world backends on the map set, world k restarting every 3 + k % 2 steps with the
    next seed (the map follows the seed): per step, the worlds and the mask of those started."""
    backends = [FastBackend(BLOCKS, "regular", control, MAPS) for _ in range(worlds)]
    rng = np.random.default_rng(0)
    states, sequence, seeds = [None] * worlds, [], list(range(worlds))
    for t in range(steps):
        started = np.zeros(worlds, dtype=bool)
        for k, backend in enumerate(backends):
            if t % (3 + k % 2) == 0:
                states[k] = backend.reset(seeds[k])
                seeds[k] += worlds
                started[k] = True
            else:
                action = (
                    [rng.uniform(0.2, 1.0), rng.uniform(-0.1, 0.1)] if control != "meta" else rng.integers(5)
                )
                states[k] = backend.step(np.array(action))
        sequence.append((tuple(states), started))
    return sequence


# --- the scenario and its map set --------------------------------------------------------------
def test_blocks_runs_on_the_compiled_core_only():
    assert BLOCKS.procedural_maps and not BLOCKS.reference_backend
    with pytest.raises(UsageError, match="compiled core only"):
        HighwayBackend(BLOCKS, "regular", "continuous")
    with pytest.raises(UsageError, match="compiled core only"):
        VectorDriveEnv(1, scenario="blocks", backend="highway")


@pytest.mark.parametrize(
    ("options", "message"),
    [
        ({"map": "OSQ"}, "unknown block letter"),
        ({"map": 0}, "at least 1 block"),
        ({"map": 2.5}, "'map' of scenario 'blocks' must be a block string such as 'OSX' or a block count"),
        ({"num_scenarios": 0}, "'num_scenarios' of scenario 'blocks' must be an integer >= 1"),
        ({"start_seed": -1}, "'start_seed' of scenario 'blocks' must be an integer >= 0"),
        ({"lane_count": 9}, "'lane_count' of scenario 'blocks' must be an integer in \\[1, 5\\] or null"),
        ({"traffic_density": 2}, "'traffic_density' of scenario 'blocks' must be a number in \\[0, 1\\]"),
        ({"lane_width": "wide"}, "'lane_width' of scenario 'blocks' must be a number in \\[2, 6\\] or null"),
    ],
)
def test_bad_map_options_are_usage_errors(options, message):
    with pytest.raises(UsageError, match=message):
        VectorDriveEnv(1, scenario="blocks", backend_options=options).reset(seed=0)


def test_the_episode_seed_picks_the_map_of_the_set():
    maps = MapSet.from_config({"map": "OSX", "start_seed": 10, "num_scenarios": 3})
    assert [maps.seed_of(seed) for seed in (0, 1, 2, 3, 2**31 + 5)] == [10, 11, 12, 10, 11]
    simulator = _simulator(4)
    batch = simulator.reset_where(np.ones(4, dtype=bool), np.array([0, 1, 2, 5]))
    np.testing.assert_array_equal(simulator.world_map, [0, 1, 2, 1])  # map seeds 0, 1, 2, 1 → slots
    assert [simulator.map_of(k).pg.seed for k in range(4)] == [0, 1, 2, 1]
    assert len(batch.roads) == 3 and all(m.pg.letters == "IOSX" for m in simulator.maps)
    np.testing.assert_array_equal(batch.road_index, [0, 1, 2, 1])
    for k in range(4):  # each world's road map, lanes and route are its map's
        bmap = simulator.map_of(k)
        assert batch.road_of(k) is bmap.road.road_map
        rows = simulator.lanes[simulator.lane_start[k] : simulator.lane_stop[k]]
        np.testing.assert_array_equal(rows, bmap.table.rows)
        ego_lane = int(simulator.vehicles[k, simulator.ego[k], T.LANE])
        assert batch.route.length_m[k] == bmap.routes[ego_lane].length_m
    # a batch holds the maps its worlds drive, not every map loaded
    batch = simulator.reset_where(np.array([True, False, True, True]), np.array([1, 0, 1, 1]))
    assert len(simulator.maps) == 3 and len(batch.roads) == 1 and (batch.road_index == 0).all()
    assert batch.road_of(0) is simulator.maps[1].road.road_map
    # the same map seed gives the same map, a different one another map
    assert np.array_equal(simulator.map_of(1).table.rows, simulator.map_of(3).table.rows)
    assert not np.array_equal(
        simulator.maps[0].pg.description.start, simulator.maps[1].pg.description.start, equal_nan=True
    )


def test_ego_spawns_on_the_spawn_road_with_a_route_to_the_last_block():
    simulator = _simulator(6, traffic="empty")
    batch = simulator.reset_where(np.ones(6, dtype=bool), np.arange(6))
    assert (simulator.count == 1).all()  # no traffic
    lanes_used = set()
    for k in range(6):
        bmap, ego = simulator.map_of(k), simulator.vehicles[k, simulator.ego[k]]
        lane = int(ego[T.LANE])
        assert lane in bmap.spawn_lanes
        lanes_used.add(lane)
        s, lateral = L.local_coordinates(bmap.table.rows, lane, ego[T.X], ego[T.Y])
        assert s == pytest.approx(EGO_SPAWN_S_M) and lateral == pytest.approx(0.0, abs=1e-9)
        assert ego[T.SPEED] == 0.0
        # the route ends at the end of the destination road (a road of the last block)
        destination = bmap.pg.destination_lanes
        end = bmap.pg.description.lane(
            int(destination[min(int(bmap.table.rows[lane, L.LANE_ID]), len(destination) - 1)])
        )
        np.testing.assert_allclose(
            batch.route.polyline[k, batch.route.count[k] - 1], end.position(end.length, 0.0)
        )
        assert bmap.pg.lane_block[destination[0]] == len(bmap.pg.blocks) - 1
        assert batch.route.progress_m[k] == pytest.approx(EGO_SPAWN_S_M)
        assert simulator.route_time_limit_s[k] == ROUTE_START_S + batch.route.length_m[k] / ROUTE_PACE_MPS
    assert len(lanes_used) > 1  # a random lane of the spawn road


def test_traffic_density_sets_the_number_of_vehicles_per_block():
    pg = generate_map("OSX", 0)
    counts = {}
    for density in (0.0, 0.1, 0.2):
        simulator = _simulator(1, traffic_density=density, num_scenarios=1)
        simulator.reset_where(np.ones(1, dtype=bool), np.array([7]))
        bmap = simulator.maps[0]
        expected = np.floor(bmap.block_spots * density).sum()  # MetaDrive's per-block count
        vehicles = simulator.vehicles[0, 1 : simulator.count[0]]
        counts[density] = len(vehicles)
        assert expected - 1 <= len(vehicles) <= expected  # a placed vehicle too near another is dropped
        blocks = pg.lane_block[vehicles[:, T.LANE].astype(int)]
        assert (blocks > 0).all()  # none on the spawn road
        gaps = vehicles[:, None, :2] - vehicles[None, :, :2]  # (M, M, 2), in each one's frame:
        along = np.abs(
            gaps[..., 0] * np.cos(vehicles[:, None, T.HEADING])
            + gaps[..., 1] * np.sin(vehicles[:, None, T.HEADING])
        )
        across = np.abs(
            gaps[..., 1] * np.cos(vehicles[:, None, T.HEADING])
            - gaps[..., 0] * np.sin(vehicles[:, None, T.HEADING])
        )
        overlap = (along < SPAWN_CLEARANCE_M[0]) & (across < SPAWN_CLEARANCE_M[1])
        assert not overlap[~np.eye(len(vehicles), dtype=bool)].any()
        # each on a route through the roads after its own (none after a dead end)
        dead_end = bmap.dead_end[vehicles[:, T.LANE].astype(int)]
        assert (vehicles[:, T.ROUTED] == 1).all() and ((vehicles[:, T.ROUTE_END] >= 2) | dead_end).all()
    assert counts[0.0] == 0 < counts[0.1] < counts[0.2]


# --- batched = one world ---------------------------------------------------------------------------
@pytest.mark.parametrize("control", ["continuous", "meta"])
def test_k_worlds_on_different_maps_step_as_k_single_worlds(control):
    sequence = _sequence(control=control)
    worlds = len(sequence[0][0])
    simulator = _simulator(worlds, control=control)
    backends = [FastBackend(BLOCKS, "regular", control, MAPS) for _ in range(worlds)]
    rng = np.random.default_rng(3)
    seeds = np.arange(worlds)
    batch = simulator.reset_where(np.ones(worlds, dtype=bool), seeds)
    singles = [backend.reset(int(seed)) for backend, seed in zip(backends, seeds, strict=True)]
    for t in range(12):
        restart = np.arange(worlds) == t % worlds if t % 3 == 2 else np.zeros(worlds, dtype=bool)
        seeds = seeds + worlds * restart
        controls = rng.integers(5, size=worlds) if control == "meta" else rng.uniform(-1, 1, (worlds, 2))
        batch = simulator.step(controls, restart, seeds)
        for k in range(worlds):
            if restart[k]:
                singles[k] = backends[k].reset(int(seeds[k]))
            else:
                singles[k] = backends[k].step(controls[k])
            n = simulator.count[k]
            np.testing.assert_array_equal(simulator.vehicles[k, :n], backends[k].vehicles)
        stacked = WorldBatch.stack(singles)
        np.testing.assert_array_equal(batch.ego.position, stacked.ego.position)
        np.testing.assert_array_equal(batch.route.progress_m, stacked.route.progress_m)
        np.testing.assert_array_equal(batch.events.off_road, stacked.events.off_road)
    assert len(set(simulator.world_map)) > 1


# --- episode rules ---------------------------------------------------------------------------------
def _place_ego(simulator, k: int, lane: int, s: float, lateral: float, speed: float = 0.0) -> None:
    rows = simulator.map_of(k).table.rows
    ego = simulator.vehicles[k, simulator.ego[k]]
    ego[T.X], ego[T.Y] = L.position(rows, lane, s, lateral)
    ego[T.HEADING], ego[T.SPEED] = L.heading_at(rows, lane, s), speed
    ego[T.LANE] = lane
    mask = np.arange(simulator.num_worlds) == k
    simulator._project(fresh=mask, update=mask)


def test_routes_met_one_at_a_time_fill_spare_rows_as_padding_them_all_again_would():
    """Each map brings new routes; ``_route`` writes a new one into a spare row of the padded
    arrays instead of padding every route again. The rows equal a whole padding of the routes."""
    simulator = _simulator(2, num_scenarios=12)
    tables = []  # the padded arrays' buffers seen (kept alive): fewer than the routes, most found room
    for seed in range(0, 24, 2):
        simulator.reset_where(np.ones(2, dtype=bool), np.array([seed, seed + 1]))
        if not any(table is simulator.r_polyline for table in tables):
            tables.append(simulator.r_polyline)
    names = ("r_polyline", "r_stations", "r_starts", "r_segments", "r_lengths2", "r_segment_m", "r_count",
             "r_length", "r_closed")  # fmt: skip
    routes = len(simulator._trackers)
    assert routes >= 12 and len(tables) < 6
    grown = {name: getattr(simulator, name).copy() for name in names}
    simulator._pad_routes()  # every route, exactly as many rows
    for name in names:
        np.testing.assert_array_equal(grown[name][:routes], getattr(simulator, name), err_msg=name)


def test_arrival_within_five_metres_of_the_destination_road_end():
    simulator = _simulator(2, traffic="empty")
    simulator.reset_where(np.ones(2, dtype=bool), np.array([0, 1]))
    for k, before_end in ((0, 4.0), (1, 8.0)):
        bmap = simulator.map_of(k)
        lane = int(
            bmap.pg.destination_lanes[
                int(bmap.table.rows[simulator.vehicles[k, 0, T.LANE].astype(int), L.LANE_ID])
            ]
        )
        _place_ego(simulator, k, lane, bmap.table.rows[lane, L.LENGTH] - before_end, 0.0)
    batch = simulator.step(np.zeros((2, 2)))
    np.testing.assert_array_equal(batch.events.arrived, [True, False])
    np.testing.assert_array_equal(batch.events.off_road, [False, False])


def test_out_of_road_off_every_lane_or_across_a_solid_line():
    simulator = _simulator(4, traffic="empty", num_scenarios=1)
    simulator.reset_where(np.ones(4, dtype=bool), np.zeros(4, dtype=int))
    spawn = simulator.maps[0].spawn_lanes  # 3 lanes: 0 has the centre line left, 2 the edge right
    # lane 0, 0.5 m left: its body (2 m) stays inside; 1 m left it crosses the solid centre line;
    # lane 1, 1 m left: across a dashed line only; lane 2, 1 m right: across the road's edge
    for k, (lane, lateral) in enumerate(((0, -0.5), (0, -1.0), (1, -1.0), (2, 1.0))):
        _place_ego(simulator, k, int(spawn[lane]), EGO_SPAWN_S_M, lateral)
    batch = simulator.step(np.zeros((4, 2)))
    np.testing.assert_array_equal(batch.events.off_road, [False, True, False, True])
    _place_ego(simulator, 0, int(spawn[0]), EGO_SPAWN_S_M, -14.0)  # beyond the 3 reverse lanes
    assert simulator.step(np.zeros((4, 2))).events.off_road[0]


def test_crash_with_traffic_ends_the_episode():
    env = VectorDriveEnv(1, scenario="blocks", obs="kinematics", backend_options={"map": "S"})
    env.reset(seed=0)
    simulator = env.simulator
    n = simulator.count[0]
    assert n > 1
    ego = simulator.vehicles[0, 0]
    simulator.vehicles[0, 1, [T.X, T.Y, T.HEADING]] = ego[T.X] + 3.0, ego[T.Y], ego[T.HEADING]
    simulator.vehicles[0, 1, T.SPEED] = 0.0
    _, reward, terminated, _, info = env.step(np.array([[0.0, 1.0]]))
    assert info["crashed"][0] and terminated[0]
    assert reward[0] == -5.0  # MetaDrive's crash penalty replaces the step reward


def test_the_route_time_limit_truncates():
    env = VectorDriveEnv(
        1, scenario="blocks", obs="kinematics", traffic="empty", backend_options={"map": "S"}
    )
    env.reset(seed=0)
    limit = env.rules.time_limit_s[0]
    assert limit == env.simulator.route_time_limit_s[0] < env.duration_s
    steps = int(round(limit * env.simulator.policy_frequency_hz))
    for step in range(steps):
        _, _, terminated, truncated, _ = env.step(np.zeros((1, 2)))  # standing still
        assert not terminated[0] and truncated[0] == (step == steps - 1)


# --- traffic along every block type ------------------------------------------------------------
@pytest.mark.parametrize("spec", ["SCrR", "OXyYT"])
def test_traffic_drives_every_block_without_leaving_the_road(spec):
    """Scripted: dense traffic on two maps that hold every block type, 200 steps (20 s): every
    vehicle stays within half its lane's width plus 0.5 m of the lane it is on, none crashes,
    the traffic is seen moving on every block of the map, and it changes lanes (MOBIL)."""
    simulator = fast_simulator(
        BLOCKS, "dense", "continuous", 2, {"map": spec, "lane_count": 2, "num_scenarios": 2}
    )
    simulator.reset_where(np.ones(2, dtype=bool), np.array([0, 1]))
    visited = [set(), set()]
    changes = 0
    for _ in range(200):
        simulator.step(np.zeros((2, 2)))  # the egos stand on the spawn road
        for k in range(2):
            bmap = simulator.map_of(k)
            rows, v = bmap.table.rows, simulator.vehicles[k, 1 : simulator.count[k]]
            lanes = v[:, T.LANE].astype(int)
            target = v[:, T.TARGET_LANE].astype(int)
            # a lane change: targeting a lane beside its own (a taper's lane drifting nearer its
            # neighbour also reads so, on lanes not ``changeable``)
            changing = (lanes != target) & (rows[lanes, L.FIRST_OF_ROAD] == rows[target, L.FIRST_OF_ROAD])
            changes += int((changing & bmap.changeable[target]).sum())
            for row, lane in zip(v, lanes, strict=True):
                s, lateral = L.local_coordinates(rows, lane, row[T.X], row[T.Y])
                assert abs(lateral) <= rows[lane, L.WIDTH] / 2 + 0.5
                assert -L.VEHICLE_LENGTH <= s <= rows[lane, L.LENGTH] + L.VEHICLE_LENGTH
            assert (v[:, T.CRASHED] == 0).all()
            visited[k] |= set(bmap.pg.lane_block[lanes[v[:, T.SPEED] > 1.0]].tolist())
    for k in range(2):
        assert visited[k] >= set(range(1, len(simulator.map_of(k).pg.blocks)))
    assert changes > 0


# --- rewards -----------------------------------------------------------------------------------
def test_metadrive_reward_values():
    shaper = RewardShaper("metadrive")
    before = world(progress_m=10.0)
    reward, terms = shaper(before, world(progress_m=12.5, speed_mps=40 / 3.6), None)
    assert terms == pytest.approx({
        "metadrive_progress": 2.5, "metadrive_speed": 0.05, "metadrive_success": 0.0,
        "metadrive_out_of_road": 0.0, "metadrive_crash": 0.0,
    })  # fmt: skip
    assert reward == pytest.approx(2.55)
    for events, expected in (
        (Events(arrived=True, collided=True), 10.0),
        (Events(off_road=True, collided=True), -5.0),
        (Events(collided=True), -5.0),
        (Events(off_road=True), -5.0),
    ):
        reward, _ = shaper(before, world(progress_m=12.5, events=events), None)
        assert reward == expected


@pytest.mark.parametrize("preset", ["metadrive", "metadrive_course", "safety_dqn"])
def test_seed_003_presets_run_on_blocks(preset):
    env = VectorDriveEnv(2, scenario="blocks", obs="lidar", reward=preset, backend_options=MAPS)
    env.reset(seed=0)
    total = np.zeros(2)
    for _ in range(20):
        _, reward, _, _, info = env.step(np.tile([0.0, 0.5], (2, 1)))
        assert np.isfinite(reward).all()
        total += reward
        assert set(info["reward_terms"]) == set(env.reward_shaper.spec.weights)
    assert (total != 0).all()


# --- sensors -------------------------------------------------------------------------------------
def test_vector_sensors_on_different_maps_equal_one_world_sensors():
    sequence = _sequence()
    assert len({id(w.road) for w in sequence[0][0]}) == 4
    for spec in SPECS:
        got, expected = _run(spec, sequence)
        sensor = make_sensor(spec)
        assert got.shape == (len(sequence), 4, *sensor.space.shape), spec
        assert np.isfinite(got).all(), spec
        np.testing.assert_array_equal(got, expected, err_msg=spec)


def test_lidar_keeps_its_world_edge_pairs_only_while_the_worlds_keep_their_maps():
    """LiDAR pairs each world with its own map's edges once per change of maps; worlds that start
    episodes on other maps read what a fresh sensor reads."""
    env = VectorDriveEnv(4, scenario="blocks", obs="lidar", backend_options=MAPS)
    rng, made = np.random.default_rng(0), []
    for t in range(9):
        if t % 3 == 0:  # new episodes, each world on another map of the set
            observation, _ = env.reset(seed=t)
        else:
            observation, *_ = env.step(rng.uniform([0.2, -0.1], [1.0, 0.1], size=(4, 2)))
        if not any(pairs is env.sensors[0]._pairs for pairs in made):
            made.append(env.sensors[0]._pairs)
        fresh = make_sensor("lidar")
        np.testing.assert_array_equal(observation, fresh.observe(env.simulator.batch, fresh.empty(4)))
    assert len(made) == 3  # one pairing per start of episodes


@pytest.mark.parametrize("spec", ["topdown", "birdeye", "camera"])
def test_raster_sensors_on_different_maps_equal_one_world_sensors(spec):
    sequence = _sequence(steps=4)
    batched, singles = make_sensor(spec), [make_sensor(spec) for _ in range(4)]
    out = batched.empty(4)
    for t, (worlds, started) in enumerate(sequence):
        batch = WorldBatch.stack(list(worlds))
        batched.reset(batch, [np.random.default_rng(k) for k in range(4)], None if t == 0 else started)
        for k in np.flatnonzero(started):
            singles[k].reset(worlds[k], np.random.default_rng(int(k)))
        batched.observe(batch, out)
        assert out.shape == (4, *batched.space.shape) and batched.space.contains(out[0])
        single = np.stack([np.asarray(s.observe(w)) for s, w in zip(singles, worlds, strict=True)])
        np.testing.assert_array_equal(out, single)
    assert np.ptp(out.reshape(4, -1), axis=0).any()  # the worlds' images differ


def test_topdown_is_five_channels_of_84_by_84():
    assert make_sensor("topdown").space.shape[-2:] == (84, 84)


# --- command line --------------------------------------------------------------------------------
def test_envs_lists_blocks_and_the_metadrive_preset():
    result = CliRunner().invoke(app, ["envs"])
    assert result.exit_code == 0
    lines = result.output.splitlines()
    assert any(line.split()[:2] == ["scenario", "blocks"] for line in lines)
    assert any(line.split()[:2] == ["reward", "metadrive"] for line in lines)


def test_train_on_blocks_with_lidar(tmp_path):
    result = CliRunner().invoke(
        app,
        ["train", "--algo", "ppo", "--env", "blocks", "--obs", "lidar", "--steps", "256", "-H", "n_steps=128",
         "--eval-every", "256", "--eval-episodes", "1", "--runs-dir", str(tmp_path), "--name", "blocks"],
    )  # fmt: skip
    assert result.exit_code == 0, result.output
    assert (tmp_path / "blocks" / "config.yaml").exists() or any((tmp_path / "blocks").iterdir())


def test_scenario_config_is_kept_whole():
    # the preset's map defaults are MetaDrive's
    assert {k: BLOCKS.config[k] for k in ("map", "start_seed", "num_scenarios", "lane_count")} == {
        "map": 3, "start_seed": 0, "num_scenarios": 1, "lane_count": 3,
    }  # fmt: skip
    assert BLOCKS.road({"map": "OSX"}).lane_count == generate_map("OSX", 0).description.lane_count


def test_maps_draws_a_gallery_of_the_map_set(tmp_path):
    out = tmp_path / "gallery.png"
    result = CliRunner().invoke(app, ["maps", "--map", "OSX", "--seeds", "3:2", "--out", str(out)])
    assert result.exit_code == 0, result.output
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    for args, message in ((["--seeds", "3"], "start:count"), (["--map", "OSQ"], "unknown block letter")):
        result = CliRunner().invoke(app, ["maps", *args, "--out", str(out)])
        assert result.exit_code == 2 and message in result.output


def test_eval_maps_evaluate_on_another_map_set():
    from drivelab.config import build_config
    from drivelab.envs.core import DriveEnv

    training = {"map": 3, "num_scenarios": 4, "start_seed": 0}
    config = build_config(
        {"algo": "ppo", "env": "blocks", "action": "continuous", "eval_maps": "1000:2",
         "env_options": {"backend_options": training}}
    )  # fmt: skip
    assert config.env_kwargs()["backend_options"] == training
    evaluation = config.eval_env_kwargs()["backend_options"]
    assert evaluation == {"map": 3, "num_scenarios": 2, "start_seed": 1000}
    env = DriveEnv(**config.eval_env_kwargs())
    env.reset(options={"episode_seed": 7})
    assert env.vector.simulator.map_of(0).pg.seed in (1000, 1001)
    assert (
        build_config({"algo": "ppo", "env": "blocks"}).identity()
        == build_config({"algo": "ppo", "env": "blocks", "eval_maps": None}).identity()
    )  # runs without the field keep their identity
