"""ego_state: the seed's five-number vector (and the ten-number one) on hand-built worlds."""

import numpy as np
import pytest

from drivelab.errors import UsageError
from drivelab.perception.ego_state import EgoState
from drivelab.perception.sensors import make_sensor
from tests.worlds import world


def test_front_vehicle_in_lane():
    # ego at 20 m/s (max 40), 1 m right of its 4 m lane's centre; a car 20 m ahead at 15 m/s,
    # a nearer one in the next lane (4 m to the left) and one behind, both ignored
    vehicles = [
        [20.0, 0.0, 0.0, 15.0, 5.0, 2.0],
        [8.0, -4.0, 0.0, 30.0, 5.0, 2.0],
        [-6.0, 0.0, 0.0, 10.0, 5.0, 2.0],
    ]
    sensor = EgoState()
    obs = sensor.observe(world(vehicles=vehicles, lateral_offset_m=1.0))
    assert sensor.front_vehicle(world(vehicles=vehicles, lateral_offset_m=1.0)) == (20.0, 15.0)
    assert sensor.front_vehicle(world(vehicles=vehicles[2:])) == (np.inf, 0.0)
    assert obs.shape == (5,) and obs.dtype == np.float32
    np.testing.assert_allclose(obs, [0.5, 0.5, 0.4, -0.125, 1.0], atol=1e-6)


def test_no_front_vehicle_and_heading_error():
    obs = EgoState().observe(world(heading=np.pi / 3))
    np.testing.assert_allclose(obs[2:], [1.0, 0.0, 0.5], atol=1e-6)


def test_ten_features_and_stacking():
    obs = EgoState(features=10).observe(
        world(steering=np.pi / 8, acceleration_mps2=-2.5, lane_id=1, lane_count=3, lane_curvature=0.01)
    )
    np.testing.assert_allclose(obs[5:], [0.0, 0.5, -0.5, 0.5, 0.5], atol=1e-6)
    stacked = make_sensor("ego_state:features=10:stack=3")
    assert stacked.space.shape == (30,)


def test_bad_options():
    with pytest.raises(UsageError):
        make_sensor("ego_state:features=7")
