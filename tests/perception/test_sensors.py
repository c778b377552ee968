import dataclasses

import numpy as np
import pytest

from drivelab.errors import UsageError
from drivelab.perception.sensors import FrameStack, make_sensor, parse_sensor_spec
from tests.worlds import world


def test_parse_spec_types():
    assert parse_sensor_spec("lidar:beams=120:range_m=40.5") == ("lidar", {"beams": 120, "range_m": 40.5})
    assert parse_sensor_spec({"name": "topdown", "size": 64}) == ("topdown", {"size": 64})


@pytest.mark.parametrize(
    "spec, shape",
    [("lidar:stack=3", (720,)), ("topdown:stack=2", (10, 84, 84)), ("birdeye:stack=2:size=32", (32, 32, 6))],
)
def test_frame_stack_shapes(spec, shape):
    sensor = make_sensor(spec)
    assert isinstance(sensor, FrameStack)
    sensor.reset(world(), np.random.default_rng(0))
    obs = sensor.observe(world())
    assert obs.shape == shape == sensor.space.shape and sensor.space.contains(obs)


def test_frame_stack_order_and_fill():
    sensor = make_sensor("lidar:beams=4:stack=3")
    far, near = world(), world(vehicles=[[12.5, 0.0, 0.0, 20.0, 5.0, 2.0]])
    sensor.reset(far, np.random.default_rng(0))
    np.testing.assert_array_equal(sensor.observe(far), np.ones(12))  # first frame repeated
    stacked = sensor.observe(near)
    np.testing.assert_allclose(stacked[:8], 1.0)
    assert stacked[8] == pytest.approx(0.2)  # newest frame last


def test_unknown_sensor_option():
    with pytest.raises(UsageError, match=r"unknown option 'colour' for sensor 'lidar' \(known: beams, "):
        make_sensor("lidar:colour=red")


def test_clock_reads_elapsed_time_over_its_horizon_clipped():
    sensor = make_sensor("clock:horizon_s=13")
    readings = [sensor.observe(dataclasses.replace(world(), time_s=t)) for t in (0.0, 6.5, 13.0, 20.0)]
    np.testing.assert_allclose(np.concatenate(readings), [0.0, 0.5, 1.0, 1.0])
    assert readings[0].shape == sensor.space.shape == (1,) and readings[0].dtype == np.float32


@pytest.mark.parametrize("horizon", ["0", "-1", "1e9"])
def test_clock_refuses_a_horizon_outside_its_range(horizon):
    with pytest.raises(UsageError, match="horizon_s"):
        make_sensor(f"clock:horizon_s={horizon}")
