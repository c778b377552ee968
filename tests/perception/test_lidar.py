"""LiDAR on hand-built worlds with known answers."""

import dataclasses

import numpy as np
import pytest

from drivelab.perception.lidar import Lidar
from drivelab.world.state import RoadMap
from tests.perception.rays import cast_rays
from tests.worlds import world

CAR = (5.0, 2.0)  # length, width
STEP = 2 * np.pi / 240  # angle between beams


def _observe(sensor, w, seed=0):
    sensor.reset(w, np.random.default_rng(seed))
    return sensor.observe(w)


def _with_edges(w, *segments):
    edges = np.array(segments, dtype=float).reshape(-1, 2, 2)
    road = RoadMap((), (), np.zeros(0), np.zeros((0, 2, 2)), np.zeros(0, dtype=int), edges)
    return dataclasses.replace(w, road=road)


def test_nothing_around_reads_one_everywhere():
    sensor = Lidar()
    reading = _observe(sensor, world())
    assert reading.shape == sensor.space.shape == (240,) and reading.dtype == np.float32
    assert np.all(reading == 1.0)


def test_vehicle_10m_ahead_hits_the_forward_beams():
    reading = _observe(Lidar(), world(vehicles=[[12.5, 0.0, 0.0, 20.0, *CAR]])) * 50  # rear at 10 m
    assert reading[0] == pytest.approx(10.0, abs=1e-4)
    # neighbouring beams meet the same 2 m wide rear bumper obliquely: 10 / cos(angle)
    for beam in (1, 2, 3):
        assert reading[beam] == pytest.approx(10.0 / np.cos(beam * STEP), abs=1e-4)
        assert reading[240 - beam] == pytest.approx(10.0 / np.cos(beam * STEP), abs=1e-4)
    # beam 4 (6°) is already 1.05 m to the side at 10 m, past the 1 m half width: a miss
    assert reading[4] == 50.0 and reading[236] == 50.0
    assert reading[120] == 50.0  # nothing behind


def test_vehicle_behind_and_beside():
    behind = _observe(Lidar(beams=8), world(vehicles=[[-20.5, 0.0, 0.0, 20.0, *CAR]])) * 50
    assert behind[4] == pytest.approx(18.0, abs=1e-4) and behind[0] == 50.0
    beside = _observe(Lidar(beams=4), world(vehicles=[[0.0, 5.0, 0.0, 20.0, *CAR]])) * 50
    np.testing.assert_allclose(beside, [50.0, 4.0, 50.0, 50.0], atol=1e-4)  # its left side is 4 m right


def test_nearer_vehicle_hides_the_farther_one():
    vehicles = [[32.5, 0.0, 0.0, 20.0, *CAR], [12.5, 0.0, 0.0, 20.0, *CAR]]
    assert _observe(Lidar(), world(vehicles=vehicles))[0] * 50 == pytest.approx(10.0, abs=1e-4)


def test_ego_inside_a_vehicle_sees_its_sides():
    # a crash: the ego's centre lies inside another box, which then blocks every beam
    reading = _observe(Lidar(beams=4), world(vehicles=[[0.0, 0.0, 0.0, 0.0, *CAR]])) * 50
    np.testing.assert_allclose(reading, [2.5, 1.0, 2.5, 1.0], atol=1e-4)


def test_out_of_range_vehicle_is_not_seen():
    assert np.all(_observe(Lidar(), world(vehicles=[[62.5, 0.0, 0.0, 20.0, *CAR]])) == 1.0)


def test_road_edge_3m_left():
    # heading +x with y to the right: the left side is y < 0
    reading = _observe(Lidar(), _with_edges(world(), [[-100.0, -3.0], [100.0, -3.0]])) * 50
    assert reading[180] == pytest.approx(3.0, abs=1e-4)  # 3·240/4: the left beam
    for beam in (130, 150, 170, 175, 190, 210, 230):  # 3 / cos(angle off the left beam)
        off_left = beam * STEP - 1.5 * np.pi
        assert reading[beam] == pytest.approx(3.0 / np.cos(off_left), abs=1e-4)
    assert reading[122] == 50.0 and reading[238] == 50.0  # 3 / cos(87°) = 57 m: out of range
    assert np.all(reading[:121] == 50.0)  # the right half (and straight ahead) sees nothing


def test_rotated_ego_reads_the_same():
    ahead = _with_edges(world(vehicles=[[12.5, 0.0, 0.0, 20.0, *CAR]]), [[-100.0, -3.0], [100.0, -3.0]])
    # heading +y: ahead is +y and the left is +x
    turned = _with_edges(
        world(heading=np.pi / 2, vehicles=[[0.0, 12.5, np.pi / 2, 20.0, *CAR]]), [[3.0, -100.0], [3.0, 100.0]]
    )
    np.testing.assert_allclose(_observe(Lidar(), turned), _observe(Lidar(), ahead), atol=1e-6)


def test_ten_km_edge_is_hit_far_from_its_ends():
    w = _with_edges(world(position=np.array([2500.0, 0.0])), [[-5000.0, -3.0], [5000.0, -3.0]])
    reading = _observe(Lidar(), w) * 50
    assert reading[180] == pytest.approx(3.0, abs=1e-4)
    assert reading[150] == pytest.approx(3.0 / np.cos(np.pi / 4), abs=1e-4)


def test_range_is_configurable():
    reading = _observe(Lidar(range_m=20.0, beams=4), world(vehicles=[[12.5, 0.0, 0.0, 20.0, *CAR]]))
    np.testing.assert_allclose(reading, [0.5, 1.0, 1.0, 1.0], atol=1e-6)


def test_noise_is_seeded_and_clipped():
    w = world(vehicles=[[12.5, 0.0, 0.0, 20.0, *CAR]])
    first, again = _observe(Lidar(noise_std=0.1), w, seed=3), _observe(Lidar(noise_std=0.1), w, seed=3)
    other = _observe(Lidar(noise_std=0.1), w, seed=4)
    np.testing.assert_array_equal(first, again)
    assert not np.array_equal(first, other)
    assert first.min() >= 0.0 and first.max() <= 1.0 and first.dtype == np.float32
    clean = _observe(Lidar(), w)
    assert np.count_nonzero(first != clean) > 100
    expected = np.clip(clean + np.random.default_rng(3).normal(0.0, 0.1, 240), 0.0, 1.0)
    np.testing.assert_allclose(first, expected, atol=1e-6)  # the noise comes from reset's generator


def test_cast_rays_directly():
    segments = np.array([[[5.0, -1.0], [5.0, 1.0]], [[-1.0, 7.0], [1.0, 7.0]], [[10.0, -20.0], [10.0, 20.0]]])
    angles = np.array([0.0, np.pi / 2, np.pi, np.pi / 4, -np.pi / 4])
    distances = cast_rays(np.zeros(2), angles, segments, 30.0)
    np.testing.assert_allclose(distances, [5.0, 7.0, 30.0, 10 * np.sqrt(2), 10 * np.sqrt(2)], atol=1e-4)
    # the same scene seen from elsewhere: only relative positions matter
    moved = cast_rays(np.array([100.0, -50.0]), angles, segments + [100.0, -50.0], 30.0)
    np.testing.assert_allclose(moved, distances, atol=1e-4)
    assert np.all(cast_rays(np.zeros(2), angles, np.zeros((0, 2, 2)), 30.0) == 30.0)


def test_bad_options_raise():
    with pytest.raises(ValueError):
        Lidar(beams=0)
    with pytest.raises(ValueError):
        Lidar(noise_std=-1.0)


def test_worlds_on_several_block_maps_see_their_own_road_edges():
    """The bounding-box prefilter keeps every edge a beam can reach: each world's distances equal
    brute-force rays against all of its map's edges and the other vehicles' sides."""
    from drivelab.envs.vector import VectorDriveEnv
    from drivelab.world.geometry import box_corners

    vector = VectorDriveEnv(4, "blocks", obs="kinematics", backend_options={"map": 4, "num_scenarios": 4})
    vector.action_space.seed(3)
    vector.reset(seed=5)
    for _ in range(15):
        vector.step(vector.action_space.sample())
    batch = vector.batch
    assert len(batch.roads) > 1
    lidar = Lidar(beams=90)
    distances = lidar.distances_m(batch)
    assert (distances < lidar.range_m).mean() > 0.2  # road edges and cars are in view
    for k in range(batch.num_worlds):
        world = batch[k]
        corners = (
            box_corners(world.vehicles[:, :6][:, [0, 1, 2, 4, 5]])
            if len(world.vehicles)
            else np.zeros((0, 4, 2))
        )
        sides = np.stack([corners, np.roll(corners, -1, axis=1)], axis=2).reshape(-1, 2, 2)
        segments = np.concatenate([np.asarray(world.road.edges).reshape(-1, 2, 2), sides])
        angles = world.ego.heading + lidar.beam_step * np.arange(lidar.beams)
        expected = cast_rays(world.ego.position, angles, segments, lidar.range_m)
        np.testing.assert_allclose(distances[k], expected, atol=1e-4 * lidar.range_m)  # float32 inside


def _numpy_distances(lidar: Lidar, batch) -> np.ndarray:
    """The vectorised numpy formulation the compiled pass replaced (every (part, beam) pair of each
    part's angular span as arrays), as an independent reference for exact equality."""
    from tests.perception.rays import _hit_distances, _near_parts, _part_terms

    beams, step = lidar.beams, lidar.beam_step
    *segments, worlds = lidar._segments(batch)
    start_x, start_y, end_x, end_y, near, closest = _near_parts(*segments, lidar.range_m)
    worlds = worlds[near]
    angle_start = np.arctan2(start_y, start_x)
    turn = (np.arctan2(end_y, end_x) - angle_start + np.pi) % (2 * np.pi) - np.pi
    spans = (np.abs(turn) // step).astype(np.intp) + 4
    first = (np.minimum(angle_start, angle_start + turn) // step).astype(np.intp) - 1
    every = (spans >= beams) | (closest < lidar.close_m)
    spans[every], first[every] = beams, 0
    pair_part = np.repeat(np.arange(len(spans)), spans)
    offset = np.arange(len(pair_part)) - np.repeat(np.cumsum(spans) - spans, spans)
    pair_beam = (first[pair_part] + offset) % beams
    terms = [term[pair_part] for term in _part_terms(start_x, start_y, end_x, end_y)]
    along_ray = _hit_distances(lidar.direction_x[pair_beam], lidar.direction_y[pair_beam], *terms)
    nearest = np.full(batch.num_worlds * beams, np.inf, dtype=np.float32)
    np.minimum.at(nearest, worlds[pair_part] * beams + pair_beam, along_ray)
    return np.minimum(nearest.reshape(batch.num_worlds, beams).astype(float), lidar.range_m)


@pytest.mark.parametrize("scenario", ["highway", "town", "roundabout"])
def test_compiled_beams_equal_the_numpy_formulation(scenario):
    from drivelab.envs.vector import VectorDriveEnv

    vector = VectorDriveEnv(4, scenario, obs="kinematics")
    vector.action_space.seed(2)
    vector.reset(seed=9)
    lidar = Lidar()
    for _ in range(12):
        vector.step(vector.action_space.sample())
        # the same float64 / float32 operations on both sides: equal bits
        np.testing.assert_array_equal(lidar.distances_m(vector.batch), _numpy_distances(lidar, vector.batch))
