"""Top-down channels: known pixels for each of the five."""

import numpy as np

from drivelab.envs.world import RoadMap
from drivelab.perception.topdown import TopDown, to_pixels
from tests.worlds import world

CAR = (5.0, 2.0)
ROAD, ROUTE, PAST, NOW, BEFORE = range(5)


def _road_world(**kwargs):
    square = np.array([[-10.0, -10.0], [30.0, -10.0], [30.0, 10.0], [-10.0, 10.0]])
    road = RoadMap(
        (square,), (), np.zeros(1), np.zeros((0, 2, 2)), np.zeros(0, dtype=int), np.zeros((0, 2, 2))
    )
    w = world(**kwargs)
    return type(w)(**{**w.__dict__, "road": road})


def _first(sensor, w):
    sensor.reset(w, np.random.default_rng(0))
    return sensor.observe(w)


def test_shape_and_space():
    sensor = TopDown()
    image = _first(sensor, world())
    assert image.shape == (5, 84, 84) == sensor.space.shape
    assert image.dtype == np.uint8 and sensor.space.contains(image)
    assert set(np.unique(image)) <= {0, 255}


def test_pixel_mapping():
    # 10 m ahead at 2 px/m: row 41.5 − 20; 3 m right: column 41.5 + 6
    np.testing.assert_allclose(
        to_pixels(np.array([10.0, 3.0]), np.zeros(2), 0.0, (84, 84), 2.0), [47.5, 21.5]
    )


def test_road_channel():
    image = _first(TopDown(), _road_world())
    assert image[ROAD, 41, 41] == 255 and image[ROAD, 41, 42] == 255
    assert image[ROAD, 0, 0] == 0  # 20.75 m ahead, 20.75 m left: off the 10 m half-width road
    assert image[ROAD, 83, 41] == 0  # 21 m behind: the road starts 10 m behind


def test_vehicle_ahead_in_traffic_channel():
    image = _first(TopDown(), world(vehicles=[[12.5, 0.0, 0.0, 20.0, *CAR]]))  # x in [10, 15] m
    assert image[NOW, 16, 41] == 255  # 12.5 m ahead
    assert image[NOW, 12, 42] == 255 and image[NOW, 21, 40] == 255
    assert image[NOW, 24, 41] == 0 and image[NOW, 16, 46] == 0
    assert image[NOW].sum() == image[BEFORE].sum()  # first frame: previous traffic = now


def test_heading_aligned():
    ahead = _first(TopDown(), world(vehicles=[[12.5, 0.0, 0.0, 20.0, *CAR]]))
    turned = _first(TopDown(), world(heading=np.pi / 2, vehicles=[[0.0, 12.5, np.pi / 2, 20.0, *CAR]]))
    np.testing.assert_array_equal(turned[NOW], ahead[NOW])


def test_previous_traffic_channel():
    sensor = TopDown()
    _first(sensor, world(vehicles=[[12.5, 0.0, 0.0, 20.0, *CAR]]))
    image = sensor.observe(world(vehicles=[[17.5, 0.0, 0.0, 20.0, *CAR]]))  # moved 5 m on
    assert image[NOW, 6, 41] == 255 and image[NOW, 16, 41] == 0
    assert image[BEFORE, 16, 41] == 255 and image[BEFORE, 6, 41] == 0


def test_past_ego_positions_and_reset():
    sensor = TopDown()
    first = _first(sensor, world())
    assert first[PAST].sum() == 0
    image = sensor.observe(world(position=np.array([5.0, 0.0])))
    assert image[PAST, 51, 41] == 255 and image[PAST, 52, 42] == 255  # 5 m behind: row 41.5 + 10
    assert image[PAST, 41, 41] == 0
    again = _first(sensor, world(position=np.array([5.0, 0.0])))
    assert again[PAST].sum() == 0


def test_route_channel():
    image = _first(TopDown(), world())  # route along +x from the ego
    assert image[ROUTE, 30, 41] == 255 and image[ROUTE, 30, 42] == 255
    assert image[ROUTE, 30, 10] == 0 and image[ROUTE, 60, 41] == 0
