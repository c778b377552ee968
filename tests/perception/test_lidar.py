"""LiDAR on hand-built worlds with known answers."""

import numpy as np
import pytest

from drivelab.envs.world import RoadMap
from drivelab.perception.lidar import Lidar, cast_rays
from tests.worlds import world

CAR = (5.0, 2.0)  # length, width


def _observe(sensor, w, seed=0):
    sensor.reset(w, np.random.default_rng(seed))
    return sensor.observe(w)


def _with_edges(w, *segments):
    edges = np.array(segments, dtype=float).reshape(-1, 2, 2)
    road = RoadMap((), (), np.zeros(0), np.zeros((0, 2, 2)), np.zeros(0, dtype=int), edges)
    return type(w)(**{**w.__dict__, "road": road})


def test_nothing_around_reads_one_everywhere():
    assert np.all(_observe(Lidar(), world()) == 1.0)


def test_vehicle_10m_ahead_hits_forward_beam():
    reading = _observe(Lidar(), world(vehicles=[[12.5, 0.0, 0.0, 20.0, *CAR]]))  # rear bumper at 10 m
    assert reading[0] * 50 == pytest.approx(10.0, abs=1e-4)
    assert reading[120] == 1.0  # nothing behind
    cell = 2 * np.pi / 240 * 10.0  # arc between beams at 10 m
    assert abs(reading[0] * 50 - 10.0) < cell


def test_rotated_ego_reads_the_same():
    ahead = _observe(Lidar(), world(vehicles=[[12.5, 0.0, 0.0, 20.0, *CAR]]))
    turned = _observe(Lidar(), world(heading=np.pi / 2, vehicles=[[0.0, 12.5, np.pi / 2, 20.0, *CAR]]))
    np.testing.assert_allclose(turned, ahead, atol=1e-6)


def test_vehicle_behind_hits_backward_beam():
    reading = _observe(Lidar(beams=8), world(vehicles=[[-20.5, 0.0, 0.0, 20.0, *CAR]]))
    assert reading[4] * 50 == pytest.approx(18.0)
    assert reading[0] == 1.0


def test_road_edge_3m_left():
    # heading +x, y to the right: the left side is y < 0
    w = _with_edges(world(), [[-100.0, -3.0], [100.0, -3.0]])
    reading = _observe(Lidar(), w) * 50
    assert reading[180] == pytest.approx(3.0)  # 3·240/4: the left beam
    for beam in (150, 170, 190, 210):  # left-forward and left-backward beams: 3 / cos(angle off left)
        off_left = 2 * np.pi * beam / 240 - 1.5 * np.pi
        assert reading[beam] == pytest.approx(3.0 / np.cos(off_left))
    assert np.all(reading[1:119] == 50.0)  # the right half sees nothing


def test_ten_km_edge_is_hit_far_from_its_ends():
    w = _with_edges(world(position=np.array([2500.0, 0.0])), [[-5000.0, -3.0], [5000.0, -3.0]])
    assert _observe(Lidar(), w)[180] * 50 == pytest.approx(3.0)


def test_range_is_configurable():
    reading = _observe(Lidar(range_m=20.0, beams=4), world(vehicles=[[12.5, 0.0, 0.0, 20.0, *CAR]]))
    assert reading[0] == pytest.approx(0.5)


def test_noise_is_seeded_and_clipped():
    w = world(vehicles=[[12.5, 0.0, 0.0, 20.0, *CAR]])
    first, again = _observe(Lidar(noise_std=0.1), w, seed=3), _observe(Lidar(noise_std=0.1), w, seed=3)
    other = _observe(Lidar(noise_std=0.1), w, seed=4)
    np.testing.assert_array_equal(first, again)
    assert not np.array_equal(first, other)
    assert first.min() >= 0.0 and first.max() <= 1.0
    assert not np.all(first == _observe(Lidar(), w))


def test_cast_rays_directly():
    segments = np.array([[[5.0, -1.0], [5.0, 1.0]], [[-1.0, 7.0], [1.0, 7.0]]])
    distances = cast_rays(np.zeros(2), np.array([0.0, np.pi / 2, np.pi, np.pi / 4]), segments, 30.0)
    np.testing.assert_allclose(distances, [5.0, 7.0, 30.0, 30.0])


def test_bad_options_raise():
    with pytest.raises(ValueError):
        Lidar(beams=0)
