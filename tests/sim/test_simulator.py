"""FastSimulator: K worlds in one simulator are exactly K single-world backends, reset by mask."""

import dataclasses

import numpy as np
import pytest
from numba import njit

from drivelab.errors import UsageError
from drivelab.scenarios import SCENARIOS
from drivelab.sim.core import traffic as T
from drivelab.sim.core.backend import FastBackend, fast_simulator
from drivelab.sim.core.simulator import FastSimulator, _command, command_ranges, float_controls
from drivelab.world.batch import COLLISION_VEHICLE, WorldBatch

# (scenario, traffic, control): every scenario the fast backend runs, with traffic
CASES = [
    ("highway", "regular", "meta"),
    ("highway", "dense", "continuous"),
    ("merge", "dense", "meta"),
    ("roundabout", "dense", "meta"),
    ("intersection", "dense", "meta"),
    ("intersection", "regular", "continuous"),
    ("racetrack", "dense", "continuous"),
]


def assert_same(a, b, path: str = "world") -> None:
    """WorldStates (or any of their parts) equal bit for bit, types included."""
    if dataclasses.is_dataclass(a):
        assert type(a) is type(b), path
        for field in dataclasses.fields(a):
            if field.compare:
                assert_same(getattr(a, field.name), getattr(b, field.name), f"{path}.{field.name}")
    elif isinstance(a, np.ndarray):
        assert isinstance(b, np.ndarray) and a.shape == b.shape, path
        np.testing.assert_array_equal(a, b, err_msg=path)
    elif isinstance(a, tuple):
        assert isinstance(b, tuple) and len(a) == len(b), path
        for i, (x, y) in enumerate(zip(a, b, strict=True)):
            assert_same(x, y, f"{path}[{i}]")
    else:
        assert type(a) is type(b) and a == b, f"{path}: {a!r} != {b!r}"


def _controls(control: str, rng: np.random.Generator, worlds: int) -> np.ndarray:
    if control == "meta":
        return rng.integers(5, size=worlds)
    return (rng.uniform(-1, 1, (worlds, 2)) * [1.0, 0.1]).astype(np.float32)


@pytest.mark.parametrize("scenario, traffic, control", CASES)
def test_k_worlds_are_k_single_backends(scenario, traffic, control):
    """World k of one K-world simulator runs exactly the episodes of its own K=1 backend (same
    seeds, same controls), with the worlds starting new episodes at different steps."""
    worlds, steps = 3, 14
    simulator = FastSimulator(SCENARIOS[scenario], traffic, control, worlds)
    singles = [FastBackend(SCENARIOS[scenario], traffic, control) for _ in range(worlds)]
    rng = np.random.default_rng(1)
    seeds = np.arange(worlds) * 11 + 3
    batch = simulator.reset_where(np.ones(worlds, dtype=bool), seeds)
    expected = [single.reset(int(seed)) for single, seed in zip(singles, seeds, strict=True)]
    resets = 0
    for t in range(1, steps):
        mask = np.array([t % (4 + k) == 0 for k in range(worlds)])
        controls = _controls(control, rng, worlds)
        batch = simulator.step(controls)
        expected = [single.step(c) for single, c in zip(singles, controls, strict=True)]
        if mask.any():
            seeds = rng.integers(1000, size=worlds)
            before = batch
            batch = simulator.reset_where(mask, seeds)
            for k in np.flatnonzero(mask):
                expected[k] = singles[k].reset(int(seeds[k]))
            for k in np.flatnonzero(~mask):  # the worlds not reset are what the step left
                assert_same(batch[k], before[k])
            resets += int(mask.sum())
        assert batch.num_worlds == worlds and batch.vehicles.shape[0] == worlds
        for k in range(worlds):
            assert_same(batch[k], expected[k], f"{scenario} world {k} step {t}")
            rows = simulator.vehicles[k, : simulator.count[k]]
            np.testing.assert_array_equal(rows, singles[k].vehicles)
            assert not simulator.vehicles[k, simulator.count[k] :].any()  # padding stays zero
    assert resets >= 5


def _state(simulator: FastSimulator, k: int) -> tuple:
    rng = simulator.rngs[k]
    return (
        simulator.vehicles[k].copy(),
        int(simulator.count[k]),
        int(simulator.ego[k]),
        tuple(simulator.regulation[k]),
        float(simulator.time_s[k]),
        float(simulator.progress_m[k]),
        None if rng is None else str(rng.bit_generator.state),
    )


@pytest.mark.parametrize("scenario", ["highway", "intersection"])
def test_reset_where_leaves_the_other_worlds_bit_identical(scenario):
    worlds = 4
    simulator = FastSimulator(SCENARIOS[scenario], "dense", "meta", worlds)
    simulator.reset_where(np.ones(worlds, dtype=bool), np.arange(worlds))
    for _ in range(6):
        stepped = simulator.step(np.full(worlds, 3))
    mask = np.array([False, True, False, True])
    kept = {k: _state(simulator, k) for k in (0, 2)}
    batch = simulator.reset_where(mask, np.array([0, 50, 0, 51]))
    for k in (0, 2):
        capacity = kept[k][0].shape[0]
        after = _state(simulator, k)
        np.testing.assert_array_equal(after[0][:capacity], kept[k][0])
        assert after[1:] == kept[k][1:]
        assert_same(batch[k], stepped[k])
    for k in (1, 3):
        assert batch.time_s[k] == 0.0 and stepped.time_s[k] > 0.0
    assert batch.ego.position[1, 0] != stepped.ego.position[1, 0]


def test_batch_shapes_and_events():
    """The exported arrays have the documented (K, ...) shapes, a fixed vehicle slot count for a
    fixed buffer, and a vehicle collision reported with its code."""
    worlds = 5
    simulator = FastSimulator(SCENARIOS["highway"], "dense", "meta", worlds)
    batch = simulator.reset_where(np.ones(worlds, dtype=bool), np.arange(worlds))
    slots = simulator.vehicles.shape[1] - 1
    assert isinstance(batch, WorldBatch) and batch.road is simulator.road
    assert batch.vehicles.shape == (worlds, slots, 6) and batch.vehicle_valid.shape == (worlds, slots)
    assert batch.ego.position.shape == (worlds, 2) and batch.route.polyline.shape[0] == worlds
    np.testing.assert_array_equal(batch.vehicle_valid.sum(axis=1), simulator.count - 1)
    # drive every ego into its neighbour: collisions are reported per world, with the vehicle code
    ego = simulator.vehicles[np.arange(worlds), simulator.ego]
    others = simulator.vehicles[:, 1]
    simulator.vehicles[:, 1, [T.X, T.Y]] = ego[:, [T.X, T.Y]] + [3.0, 0.0]
    simulator.vehicles[:, 1, T.SPEED] = others[:, T.SPEED] * 0
    batch = simulator.step(np.ones(worlds, dtype=int))
    assert batch.events.collided.all()
    assert (batch.events.collision_kind == COLLISION_VEHICLE).all()


def test_refuses_bad_arguments():
    with pytest.raises(UsageError, match="num_worlds must be >= 1"):
        FastSimulator(SCENARIOS["highway"], "regular", "meta", 0)
    simulator = FastSimulator(SCENARIOS["highway"], "regular", "meta", 2)
    with pytest.raises(UsageError, match="before reset_where"):
        simulator.step(np.zeros(2, dtype=int))


def test_a_scenario_runs_on_the_simulator_it_names():
    """The town names its TownSimulator (``Scenario.simulator``): the plain core refuses it, and
    ``fast_simulator`` builds the named class; a subclass of the named class is accepted."""
    with pytest.raises(UsageError, match="'town' runs on drivelab.scenarios.town.simulator.TownSimulator"):
        FastSimulator(SCENARIOS["town"], "empty", "meta", 1)
    assert type(fast_simulator(SCENARIOS["town"], "empty", "meta", 1)).__name__ == "TownSimulator"
    assert type(fast_simulator(SCENARIOS["blocks"], "empty", "meta", 1)).__name__ == "BlocksSimulator"

    class Recording(FastSimulator):
        pass

    assert Recording(SCENARIOS["merge"], "empty", "meta", 1).scenario.name == "merge"


@pytest.mark.parametrize("scenario, traffic, control", CASES)
def test_restart_in_step_is_a_step_then_reset_where(scenario, traffic, control):
    """``step(controls, restart, seeds)`` (NEXT_STEP autoreset: the restarting worlds are set up
    instead of simulated) gives the batch and state of a step followed by ``reset_where``."""
    worlds = 4
    a = FastSimulator(SCENARIOS[scenario], traffic, control, worlds)
    b = FastSimulator(SCENARIOS[scenario], traffic, control, worlds)
    rng = np.random.default_rng(7)
    for simulator in (a, b):
        simulator.reset_where(np.ones(worlds, dtype=bool), np.arange(worlds) + 20)
    for t in range(8):
        controls = _controls(control, rng, worlds)
        restart = np.array([(t + k) % 3 == 0 for k in range(worlds)])
        seeds = rng.integers(1000, size=worlds)
        a.step(controls)
        expected = a.reset_where(restart, seeds)
        got = b.step(controls, restart, seeds)
        for k in range(worlds):
            assert_same(got[k], expected[k], f"{scenario} world {k} step {t}")
            assert _state(b, k)[1:] == _state(a, k)[1:]
            np.testing.assert_array_equal(b.vehicles[k], a.vehicles[k])


@pytest.mark.parametrize("traffic", ["empty", "regular", "dense"])
@pytest.mark.parametrize("control", ["meta", "continuous"])
def test_batched_highway_set_up_is_the_one_world_set_up(traffic, control):
    """The highway's episodes set up for many worlds in one call (the simulator's reset) are the
    scenario's one-world spawner's rows (that one is tested against highway-env's own reset in
    test_fast and test_spawn) in every world, padding zero."""
    seeds = np.array([0, 3, 99, 2**31 - 2, 123456])
    simulator = FastSimulator(SCENARIOS["highway"], traffic, control, len(seeds))
    simulator.reset_where(np.ones(len(seeds), dtype=bool), seeds)
    for k, seed in enumerate(seeds):
        rows, ego, _, _ = SCENARIOS["highway"].spawn(int(seed), simulator._road, control)
        assert simulator.count[k] == len(rows) and simulator.ego[k] == ego == 0
        np.testing.assert_array_equal(simulator.vehicles[k, : len(rows)], rows)
        assert not simulator.vehicles[k, len(rows) :].any()


@njit
def _commands(controls, low, span, constants, out) -> None:
    for k in range(controls.shape[0]):
        for i in range(2):
            out[k, i] = _command(controls[k, i], low[i], span[i], constants)


def continuous_commands(controls, num_worlds: int) -> np.ndarray:
    """(K, 2) [acceleration m/s², steering rad] of normalised controls: ``ContinuousAction.get_action``'s
    clip to [-1, 1] and linear map onto ACCELERATION_RANGE and STEERING_RANGE, in the controls' own
    float type (``float_controls``), as ``set_ego_controls`` computes the egos' commands."""
    controls = float_controls(controls, num_worlds)
    commands = np.empty_like(controls)
    _commands(controls, *command_ranges(controls.dtype), commands)
    return commands


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_continuous_commands_are_highway_envs_bits(dtype):
    """The egos' commands are ContinuousAction.get_action's: clipped to [-1, 1], mapped onto
    ±5 m/s² and ±45° in the controls' own float type, to the last bit (NaN kept)."""
    from highway_env import utils as hw_utils

    from drivelab.sim.core.simulator import ACCELERATION_RANGE, STEERING_RANGE

    controls = np.random.default_rng(0).uniform(-1.5, 1.5, (512, 2)).astype(dtype)
    controls[:4, 0] = [-1.0, 1.0, -0.0, np.nan]
    clipped = np.clip(controls, -1, 1)
    commands = continuous_commands(controls, len(controls))
    assert commands.dtype == dtype and commands.shape == (512, 2)
    np.testing.assert_array_equal(commands[:, 0], hw_utils.lmap(clipped[:, 0], [-1, 1], ACCELERATION_RANGE))
    np.testing.assert_array_equal(commands[:, 1], hw_utils.lmap(clipped[:, 1], [-1, 1], STEERING_RANGE))
    assert commands[0, 0] == -5.0 and commands[1, 0] == 5.0


@pytest.mark.parametrize("dtype", [np.float16, np.int64])
def test_other_control_types_are_taken_as_float64(dtype):
    controls = np.array([[0.5, -1.0], [2.0, 0.0]]).astype(dtype)
    commands = continuous_commands(controls, 2)
    assert commands.dtype == np.float64
    np.testing.assert_array_equal(commands, continuous_commands(controls.astype(np.float64), 2))


def _route_table(trackers):
    """project_routes' padded arrays of ``trackers`` (the simulator's layout, last point repeated)."""
    points = max(len(t.polyline) for t in trackers)
    table = {name: [] for name in ("starts", "segments", "lengths2", "stations")}
    for t in trackers:
        for name, values in (
            ("starts", t._starts),
            ("segments", t._segments),
            ("lengths2", t._lengths2),
            ("stations", t.stations),
        ):
            width = points - (name != "stations")
            table[name].append(np.concatenate([values, np.repeat(values[-1:], width - len(values), axis=0)]))
    table = {name: np.stack(rows) for name, rows in table.items()}
    table["segment_m"] = np.sqrt(table["lengths2"])
    table["count"] = np.array([len(t.polyline) for t in trackers], dtype=np.int64)
    table["closed"] = np.array([t.closed for t in trackers])
    return table


def test_windowed_route_projection_is_route_trackers():
    """project_routes searches the window's segments first, yet gives RouteTracker.project's
    progress to the bit: along a circuit whose window wraps round the lap both ways, on an open
    route, far off the road (the whole search), and where the window finds nothing near."""
    from drivelab.sim.core.simulator import project_routes
    from drivelab.sim.route import RouteTracker

    angles = np.linspace(0.0, 2 * np.pi, 181)
    circle = np.stack([80 * np.cos(angles), 80 * np.sin(angles)], axis=1)  # 503 m lap, closed
    zigzag = np.stack([np.arange(60) * 7.0, 5 * np.sin(np.arange(60))], axis=1)  # open, 413 m
    hairpin = np.concatenate([np.stack([np.arange(40) * 5.0, np.zeros(40)], 1),
                              np.stack([np.arange(39, -1, -1) * 5.0, np.full(40, 3.0)], 1)])  # fmt: skip
    trackers = [RouteTracker(p, has_goal=True) for p in (circle, zigzag, hairpin)]
    assert trackers[0].closed and not trackers[1].closed
    table = _route_table(trackers)
    rng = np.random.default_rng(0)
    checked = 0
    for trial in range(600):
        r = trial % 3
        tracker = trackers[r]
        lap = tracker.stations[-1]
        station = rng.uniform(-lap, 3 * lap) if tracker.closed else rng.uniform(-20, lap + 20)
        anchor = tracker.polyline[rng.integers(len(tracker.polyline))]
        scale = rng.choice([0.5, 5.0, 40.0, 2000.0])  # 2 km off: nothing near in the window
        position = anchor + rng.normal(0, scale, 2)
        fresh = bool(trial % 7 == 0)
        expected = tracker.project(position, None if fresh else station)
        vehicles = np.zeros((1, 1, T.VEHICLE_COLUMNS))
        vehicles[0, 0, T.X], vehicles[0, 0, T.Y] = position
        progress = np.array([station])
        project_routes(
            vehicles, np.zeros(1, np.int64), np.array([r]), table["starts"], table["segments"],
            table["lengths2"], table["segment_m"], table["stations"], table["count"], table["closed"],
            np.array([fresh]), np.array([True]), progress,
        )  # fmt: skip
        assert progress[0] == expected, (trial, r, station, position)
        checked += 1
    assert checked == 600
    # exact ties, where the order of the search decides: (3, 3) is 3 m from three sides of a
    # closed 128 x 6 m loop (every projection exact), two at the end of the lap and one at its start,
    # all in the window
    loop = RouteTracker(np.array([[0.0, 0], [128, 0], [128, 6], [0, 6], [0, 0]]), has_goal=True)
    table = _route_table([loop])
    vehicles = np.zeros((1, 1, T.VEHICLE_COLUMNS))
    vehicles[0, 0, T.X], vehicles[0, 0, T.Y] = 3.0, 3.0
    for station in (1.0, loop.stations[-1] - 1.0):  # the window wraps below the start, then above the end
        progress = np.array([station])
        project_routes(
            vehicles, np.zeros(1, np.int64), np.zeros(1, np.int64), table["starts"], table["segments"],
            table["lengths2"], table["segment_m"], table["stations"], table["count"], table["closed"],
            np.array([False]), np.array([True]), progress,
        )  # fmt: skip
        assert progress[0] == loop.project(np.array([3.0, 3.0]), station)


class _OneCall(FastSimulator):
    one_call = True  # every step in one compiled call (advance_worlds), whatever the threads


class _KernelByKernel(FastSimulator):
    one_call = False  # every step's kernels called one by one from Python


@pytest.mark.parametrize(
    "scenario, traffic, control",
    [case for case in CASES if not SCENARIOS[case[0]].traffic_flow]
    + [("follow-line", "empty", "continuous"), ("follow-lane", "empty", "continuous")],
)
def test_one_call_step_is_the_kernel_by_kernel_step(scenario, traffic, control):
    """A step in one compiled call gives the batch and state, bit for bit, of the same kernels
    called one by one, on every scenario that takes it; steps that restart worlds (and the
    intersection's arriving traffic) keep the kernel-by-kernel path."""
    worlds = 3
    one, split = (cls(SCENARIOS[scenario], traffic, control, worlds) for cls in (_OneCall, _KernelByKernel))
    rng = np.random.default_rng(3)
    for simulator in (one, split):
        simulator.reset_where(np.ones(worlds, dtype=bool), np.arange(worlds) + 5)
    for t in range(25):
        controls = _controls(control, rng, worlds)
        restart = np.array([t % 11 == 10 and k == 1 for k in range(worlds)])
        seeds = rng.integers(1000, size=worlds)
        got, expected = one.step(controls, restart, seeds), split.step(controls, restart, seeds)
        assert_same(got, expected, f"{scenario} step {t}")
        for k in range(worlds):
            assert _state(one, k)[1:] == _state(split, k)[1:]
            np.testing.assert_array_equal(one.vehicles[k], split.vehicles[k])
    assert not FastSimulator(SCENARIOS["intersection"], "dense", "meta", 1).one_call  # traffic arrives
