"""Batched sensors = single-world sensors: K worlds observed in one call give, world by world,
exactly what K one-world sensors give, on random worlds of every scenario.

The vectorised code does the same elementwise arithmetic per world as the one-world path (its
only reductions, minima and argmins, do not depend on order), so the outputs must match bit for
bit: every comparison here is exact.
"""

import dataclasses

import numpy as np
import pytest

from drivelab.perception.affordances import Affordances
from drivelab.perception.lidar import Lidar
from drivelab.perception.sensors import FrameStack, make_sensor
from drivelab.world.batch import WorldBatch
from drivelab.world.geometry import box_corners
from drivelab.world.state import LIGHT_GREEN, LIGHT_RED, RoadMap, Route
from tests.batch_worlds import ALL_SCENARIOS, world_sequences
from tests.perception.rays import cast_rays
from tests.worlds import world

SPECS = (
    "kinematics",
    "kinematics:absolute=true:vehicles_count=4",
    "kinematics:vehicles_count=6:features=presence+x+cos_d+sin_d+accel+t_cross+s_cross",  # the extras
    "lidar",  # 240 beams
    "lidar:beams=7:range_m=20.3:noise_std=0.05",
    "waypoints",
    "measurements",
    "ego_state",
    "ego_state:features=10",
    "ttc_grid",
    "affordances",
    "waypoints:stack=3",
    "lidar:beams=16:stack=3",
    "clock:horizon_s=4",
)


def _generator(step: int, k: int) -> np.random.Generator:
    """World k's episode generator when it starts at ``step`` (a fresh one per caller)."""
    return np.random.default_rng([step, k])


def _run(spec: str, sequence) -> tuple[np.ndarray, np.ndarray]:
    """The batched sensor's (T, K, …) observations, and those of K one-world sensors, each reset
    when its world starts an episode."""
    batched = make_sensor(spec)
    singles = [make_sensor(spec) for _ in sequence[0][0]]
    got, expected = [], []
    for step, (worlds, started) in enumerate(sequence):
        batch = WorldBatch.stack(list(worlds))
        batched.reset(batch, [_generator(step, k) for k in range(len(worlds))], mask=started)
        out = batched.empty(len(worlds))
        assert batched.observe(batch, out) is out
        got.append(out)
        for k in np.flatnonzero(started):
            singles[k].reset(worlds[k], _generator(step, k))
        expected.append(np.stack([single.observe(w) for single, w in zip(singles, worlds, strict=True)]))
    return np.stack(got), np.stack(expected)


@pytest.mark.parametrize("scenario", ALL_SCENARIOS)
def test_batched_observations_equal_single_world_ones(scenario):
    sequence = world_sequences(scenario)  # K = 8 worlds, 10 steps, resetting at different steps
    assert sequence[0][1].all() and not all(started.all() for _, started in sequence[1:])
    for spec in SPECS:
        got, expected = _run(spec, sequence)
        sensor = make_sensor(spec)
        assert got.shape == (len(sequence), 8, *sensor.space.shape), spec
        assert got.dtype == expected.dtype == sensor.space.dtype, spec
        np.testing.assert_array_equal(got, expected, err_msg=f"{spec} on {scenario}")
        assert all(sensor.space.contains(obs) for obs in got.reshape(-1, *sensor.space.shape)), spec
        if spec != "ttc_grid":  # the worlds differ, so must their readings (ttc_grid is coarse)
            assert np.ptp(got, axis=1).any(), spec


def test_frame_stack_fills_and_shifts_per_world():
    sequence = world_sequences("highway")
    got, _ = _run("measurements:stack=3", sequence)  # (T, K, 6): three frames of 2 numbers
    frames, _ = _run("measurements", sequence)  # (T, K, 2)
    for step in range(len(sequence)):
        for k in range(8):
            first = max(s for s in range(step + 1) if sequence[s][1][k])  # this episode's start
            # frame i of the stack is the observation at step - 2 + i, clamped to the episode
            wanted = [frames[max(step - 2 + i, first), k] for i in range(3)]
            np.testing.assert_array_equal(got[step, k], np.concatenate(wanted))
    assert isinstance(make_sensor("measurements:stack=3"), FrameStack)


@pytest.mark.parametrize("scenario", ["highway", "town", "follow-lane"])
def test_lidar_on_one_shared_map(scenario):
    # the usual batch: every world drives the same RoadMap object (the fast path of Lidar)
    worlds, _ = world_sequences(scenario)[4]
    shared = [dataclasses.replace(w, road=worlds[0].road) for w in worlds]
    batch = WorldBatch.stack(shared)
    assert len(batch.roads) == 1
    sensor = Lidar()
    sensor.reset(batch, [None] * 8)
    got = sensor.observe(batch)
    np.testing.assert_array_equal(got, np.stack([sensor.observe(w) for w in shared]))
    assert (got < 1).any(axis=1).all()  # every world sees something


def test_lidar_hand_built_corner_cases_batched():
    # different vehicle counts, an ego inside a box, a 10 km edge, no road at all
    car = (5.0, 2.0)
    edge = np.array([[[-5000.0, -3.0], [5000.0, -3.0]]])
    road = RoadMap((), (), np.zeros(0), np.zeros((0, 2, 2)), np.zeros(0, dtype=int), edge)
    worlds = [
        world(),
        world(vehicles=[[12.5, 0.0, 0.0, 20.0, *car]]),
        world(vehicles=[[0.0, 0.0, 0.3, 0.0, *car], [8.0, 3.0, 1.0, 0.0, *car]]),
        dataclasses.replace(world(position=np.array([2500.0, 0.0])), road=road),
        dataclasses.replace(world(heading=2.0, vehicles=[[3.0, 4.0, 0.0, 1.0, 0.8, 0.8]]), road=road),
    ]
    for beams in (4, 240, 1001):
        sensor = Lidar(beams=beams)
        got = sensor.observe(WorldBatch.stack(worlds))
        np.testing.assert_array_equal(got, np.stack([sensor.observe(w) for w in worlds]))
    # every beam of the ego inside a box stops at that box (within its 2.7 m half diagonal)
    assert got[2].max() * 50 < 2.8 and np.all(got[0] == 1.0)


def test_affordances_batched_on_hand_built_worlds():
    # pedestrians, lights and oncoming traffic, which random worlds seldom bring
    left = Route(np.array([[0.0, 0.0], [20.0, 0.0], [20.0, -40.0]]), 0.0, 60.0)
    light = np.array([[14.0, 0.5, 0.0, LIGHT_GREEN]])
    walkers = np.array([[10.0, -2.5, np.pi / 2, 1.2, 0.8, 0.8], [12.0, -6.0, np.pi / 2, 1.2, 0.8, 0.8]])
    turning = dataclasses.replace(world(), route=left, traffic_lights=light)
    worlds = [
        dataclasses.replace(turning, vehicles=np.array([[30.0, -2.0, np.pi, 5.0, 5.0, 2.0]])),
        dataclasses.replace(turning, vehicles=np.array([[30.0, -2.0, np.pi, 0.0, 5.0, 2.0]])),
        dataclasses.replace(turning, vehicles=np.zeros((0, 6)), pedestrians=walkers),
        dataclasses.replace(world(vehicles=[[15.0, 0.3, 0.0, 3.0, 5.0, 2.0]]), pedestrians=walkers[1:]),
        dataclasses.replace(world(speed_mps=3.0), traffic_lights=np.array([[20.0, 0.5, 0.0, LIGHT_RED]])),
        world(),
    ]
    sensor = Affordances()
    got = sensor.observe(WorldBatch.stack(worlds))
    np.testing.assert_array_equal(got, np.stack([sensor.observe(w) for w in worlds]))
    oncoming, pedestrian = got[:, -1], got[:, -2]
    np.testing.assert_allclose(oncoming, [np.hypot(30.0, 2.0), 40, 40, 40, 40, 40], rtol=1e-6)
    np.testing.assert_allclose(pedestrian, [40, 40, 10, 12, 40, 40])


@pytest.mark.parametrize("scenario", ALL_SCENARIOS)
def test_lidar_beam_culling_misses_no_hit(scenario):
    # Lidar tests each segment against the beams of its angular span only; cast_rays tests every
    # beam against every segment (world frame, all four sides of every box): the same distances up
    # to the float32 rounding of the two frames, which grazing road edges stretch to ~0.1 mm (a
    # missed hit would be metres off)
    sensor = Lidar()
    for worlds, _ in world_sequences(scenario)[::3]:
        got = sensor.distances_m(WorldBatch.stack(list(worlds)))
        for k, w in enumerate(worlds):
            users = w.road_users()
            sides = box_corners(users[:, [0, 1, 2, 4, 5]])
            sides = np.stack([sides, np.roll(sides, -1, axis=1)], axis=2).reshape(-1, 2, 2)
            segments = np.concatenate([np.asarray(w.road.edges).reshape(-1, 2, 2), sides])
            angles = w.ego.heading + sensor.beam_step * np.arange(sensor.beams)
            expected = cast_rays(w.ego.position, angles, segments, sensor.range_m)
            np.testing.assert_allclose(got[k], expected, atol=1e-3, err_msg=f"world {k}")
