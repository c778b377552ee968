import numpy as np
import pytest

from drivelab.perception.kinematics import Kinematics
from tests.worlds import world


def _observe(sensor, w):
    sensor.reset(w, np.random.default_rng(0))
    return sensor.observe(w).reshape(sensor.vehicles_count, 7)


def test_rows_sorted_by_distance_and_normalised():
    w = world(
        speed_mps=20.0,
        vehicles=[[30.0, 0.0, 0.0, 25.0, 5, 2], [10.0, 4.0, 0.0, 25.0, 5, 2], [150.0, 0.0, 0.0, 25.0, 5, 2]],
    )
    rows = _observe(Kinematics(), w)
    np.testing.assert_allclose(rows[0], [1, 0, 0, 0.5, 0, 1, 0])
    np.testing.assert_allclose(rows[1], [1, 0.1, 0.04, 0.125, 0, 1, 0], atol=1e-7)
    np.testing.assert_allclose(rows[2], [1, 0.3, 0.0, 0.125, 0, 1, 0], atol=1e-7)
    assert np.all(rows[3:] == 0)  # the vehicle 150 m away is beyond perception


def test_ego_frame_and_heading():
    w = world(heading=np.pi / 2, speed_mps=10.0, vehicles=[[0.0, 20.0, np.pi, 10.0, 5, 2]])
    rows = _observe(Kinematics(vehicles_count=2), w)
    assert rows[1, 1] == pytest.approx(0.2) and rows[1, 2] == pytest.approx(0.0, abs=1e-9)
    # heading π/2 relative to the ego: it moves to the ego's right at 10 m/s
    assert rows[1, 3] == pytest.approx(-0.25) and rows[1, 4] == pytest.approx(0.25)
    assert rows[1, 5] == pytest.approx(0.0, abs=1e-9) and rows[1, 6] == pytest.approx(1.0)


def test_shape_matches_space():
    sensor = Kinematics(vehicles_count=3)
    obs = sensor.observe(world())
    assert obs.shape == sensor.space.shape == (21,) and sensor.space.contains(obs)
