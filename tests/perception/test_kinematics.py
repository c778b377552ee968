"""Kinematics rows: ordering, ego-frame values and normalisation with known answers."""

import numpy as np
import pytest

from drivelab.perception.kinematics import FEATURES, Kinematics
from tests.worlds import world


def _observe(sensor, w):
    sensor.reset(w, np.random.default_rng(0))
    return sensor.observe(w).reshape(sensor.vehicles_count, len(FEATURES))


def test_rows_sorted_by_distance_and_normalised():
    w = world(
        speed_mps=20.0,
        vehicles=[
            [30.0, 0.0, 0.0, 25.0, 5, 2],
            [10.0, 4.0, 0.0, 25.0, 5, 2],
            [150.0, 0.0, 0.0, 25.0, 5, 2],  # beyond the 100 m perception distance
            [-8.0, 0.0, 0.0, 15.0, 5, 2],  # behind, but the nearest
        ],
    )
    rows = _observe(Kinematics(), w)
    # presence, x / 100 m, y / 100 m, vx / 80 m/s, vy / 80 m/s, cos, sin of the relative heading
    np.testing.assert_allclose(rows[0], [1, 0, 0, 0.25, 0, 1, 0], atol=1e-7)
    np.testing.assert_allclose(rows[1], [1, -0.08, 0.0, -0.0625, 0, 1, 0], atol=1e-7)
    np.testing.assert_allclose(rows[2], [1, 0.1, 0.04, 0.0625, 0, 1, 0], atol=1e-7)
    np.testing.assert_allclose(rows[3], [1, 0.3, 0.0, 0.0625, 0, 1, 0], atol=1e-7)
    assert np.all(rows[4] == 0)


def test_ego_frame_and_heading():
    w = world(heading=np.pi / 2, speed_mps=10.0, vehicles=[[0.0, 20.0, np.pi, 10.0, 5, 2]])
    rows = _observe(Kinematics(vehicles_count=2), w)
    # 20 m ahead of an ego heading +y; its heading is π/2 relative to the ego: it drives to the
    # ego's right at 10 m/s while the ego drives forward at 10 m/s
    assert rows[1, 1] == pytest.approx(0.2) and rows[1, 2] == pytest.approx(0.0, abs=1e-7)
    assert rows[1, 3] == pytest.approx(-0.125) and rows[1, 4] == pytest.approx(0.125)
    assert rows[1, 5] == pytest.approx(0.0, abs=1e-7) and rows[1, 6] == pytest.approx(1.0)


def test_ego_heading_is_relative_to_its_lane():
    rows = _observe(Kinematics(vehicles_count=1), world(heading=0.3, lane_heading=0.1, speed_mps=40.0))
    np.testing.assert_allclose(rows[0], [1, 0, 0, 0.5, 0, np.cos(0.2), np.sin(0.2)], atol=1e-7)


def test_values_are_clipped():
    w = world(speed_mps=0.0, vehicles=[[60.0, -90.0, 0.0, 200.0, 5, 2]])
    rows = _observe(Kinematics(vehicles_count=2, perception_distance_m=110.0, speed_scale_mps=100.0), w)
    np.testing.assert_allclose(rows[1], [1, 60 / 110, -90 / 110, 1.0, 0, 1, 0], atol=1e-7)


def test_shape_matches_space():
    sensor = Kinematics(vehicles_count=3)
    obs = sensor.observe(world(vehicles=[[10.0, 0.0, 0.0, 20.0, 5, 2]]))
    assert obs.shape == sensor.space.shape == (21,) and obs.dtype == np.float32
    assert sensor.space.contains(obs)
    assert np.all(obs[14:] == 0)  # the third row is absent
    with pytest.raises(ValueError):
        Kinematics(vehicles_count=0)
