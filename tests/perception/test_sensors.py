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
