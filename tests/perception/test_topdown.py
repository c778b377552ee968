"""Top-down channels: known pixels for each of the five, and the pixel mapping.

At 84 px and 2 px/m the ego sits at OpenCV coordinate (41.5, 41.5): a point x m ahead and y m
right is at row 41.5 − 2x, column 41.5 + 2y. Rectangles cover exactly the pixels whose centres
they contain, so a 5 m × 2 m car covers 10 × 4 pixels.
"""

import dataclasses

import numpy as np

from drivelab.perception.topdown import TopDown, _clip_rows_counts, to_pixels
from drivelab.world.state import RoadMap
from tests.worlds import world

CAR = (5.0, 2.0)
ROAD, ROUTE, PAST, NOW, BEFORE = range(5)


def _road_world(*polygons, **kwargs):
    polygons = tuple(np.array(p, dtype=float) for p in polygons)
    no_segments = np.zeros((0, 2, 2))
    road = RoadMap(polygons, (), np.zeros(len(polygons)), no_segments, np.zeros(0, dtype=int), no_segments)
    return dataclasses.replace(world(**kwargs), road=road)


def _rectangle(x_min, x_max, y_min, y_max):
    return [[x_min, y_min], [x_max, y_min], [x_max, y_max], [x_min, y_max]]


def _first(sensor, w):
    sensor.reset(w, np.random.default_rng(0))
    return sensor.observe(w)


def _bounds(channel):
    rows, columns = np.nonzero(channel)
    return rows.min(), rows.max(), columns.min(), columns.max()


def test_shape_and_space():
    sensor = TopDown()
    image = _first(sensor, _road_world(_rectangle(-10, 30, -10, 10), vehicles=[[12.5, 0.0, 0.0, 20.0, *CAR]]))
    assert image.shape == (5, 84, 84) == sensor.space.shape
    assert image.dtype == np.uint8 and sensor.space.contains(image)
    assert set(np.unique(image)) == {0, 255}
    assert TopDown(size=64, pixels_per_meter=1.0).space.shape == (5, 64, 64)


def test_pixel_mapping():
    # 10 m ahead, 3 m right at 2 px/m: column 41.5 + 6, row 41.5 − 20
    np.testing.assert_allclose(
        to_pixels(np.array([10.0, 3.0]), np.zeros(2), 0.0, (84, 84), 2.0), [47.5, 21.5]
    )
    # heading +y: ahead is +y, the right is −x; any leading shape; a non-square image (H=60, W=100)
    points = np.array([[[5.0, 20.0], [2.0, 10.0]]])
    pixels = to_pixels(points, np.array([5.0, 10.0]), np.pi / 2, (60, 100), 2.0)
    assert pixels.shape == (1, 2, 2)
    np.testing.assert_allclose(pixels, [[[49.5, 9.5], [55.5, 29.5]]], atol=1e-9)


def test_road_channel():
    image = _first(TopDown(), _road_world(_rectangle(-10, 30, -10, 10)))
    assert image[ROAD, 41, 41] == 255 and image[ROAD, 42, 42] == 255
    assert image[ROAD, 0, 0] == 0  # 20.75 m ahead, 20.75 m left: off the 10 m half-width road
    assert image[ROAD, 83, 41] == 0  # 21 m behind: the road starts 10 m behind


def test_ten_km_lane_is_drawn_to_the_pixel():
    # 4 m wide (columns 37.5 … 45.5), far longer than the view: cut to the image before filling
    image = _first(TopDown(), _road_world(_rectangle(-5000, 5000, -2, 2), position=np.array([1234.0, 0.0])))
    for row in (0, 41, 83):
        assert np.all(image[ROAD, row, 38:46] == 255)
        assert image[ROAD, row, 36] == 0 and image[ROAD, row, 47] == 0


def clip_rows(points: np.ndarray, counts: np.ndarray, top: float, bottom: float) -> list[np.ndarray]:
    """Cut polygons (pixel vertices, one after another) to the rows ``top``..``bottom`` (OpenCV's
    fill costs time per row a polygon spans, in or out of the image): the non-empty ones, (K, 2)."""
    points, counts = _clip_rows_counts(points, counts, top, bottom)
    polygons = np.split(points, np.cumsum(counts)[:-1])
    return [polygon for polygon in polygons if len(polygon) >= 3]


def test_clip_rows():
    # a tall square and a triangle poking out at the bottom, cut to rows 0 … 50
    square = [[10.0, -100.0], [20.0, -100.0], [20.0, 100.0], [10.0, 100.0]]
    triangle = [[30.0, 40.0], [40.0, 60.0], [30.0, 60.0]]
    outside = [[0.0, 70.0], [5.0, 70.0], [5.0, 80.0]]
    points = np.array(square + triangle + outside)
    polygons = clip_rows(points, np.array([4, 3, 3]), 0.0, 50.0)
    assert len(polygons) == 2
    _assert_same_cycle(polygons[0], [[10, 0], [20, 0], [20, 50], [10, 50]])
    _assert_same_cycle(polygons[1], [[30, 40], [35, 50], [30, 50]])


def _assert_same_cycle(polygon, expected):
    """The same vertices in the same order, from any starting vertex."""
    expected = np.array(expected, dtype=float)
    assert polygon.shape == expected.shape
    assert any(np.allclose(np.roll(polygon, k, axis=0), expected) for k in range(len(expected)))


def test_overlapping_lanes_have_no_holes():
    # a crossing: one fillPoly call with both polygons would leave the overlap empty (even-odd)
    image = _first(TopDown(), _road_world(_rectangle(-30, 30, -2, 2), _rectangle(-2, 2, -30, 30)))
    assert image[ROAD, 41, 41] == 255 and image[ROAD, 42, 42] == 255
    assert image[ROAD, 41, 10] == 255 and image[ROAD, 10, 41] == 255
    assert image[ROAD, 10, 10] == 0


def test_vehicle_ahead_in_traffic_channel():
    image = _first(TopDown(), world(vehicles=[[10.0, 0.0, 0.0, 20.0, *CAR]]))
    assert image[NOW, 84 // 2 - 10 * 2, 84 // 2] == 255  # row H/2 − 10·ppm, column W/2
    offset = _first(TopDown(), world(vehicles=[[10.1, 0.1, 0.0, 20.0, *CAR]]))
    # rows 41.5 − 2·12.6 = 16.3 … 26.3, columns 41.7 ∓ 2 = 39.7 … 43.7: the pixel centres inside
    assert _bounds(offset[NOW]) == (17, 26, 40, 43) and np.count_nonzero(offset[NOW]) == 10 * 4
    assert _bounds(image[NOW]) == (17, 26, 40, 43)  # rows 16.5 … 26.5, columns 39.5 … 43.5
    assert offset[NOW].sum() == offset[BEFORE].sum()  # first frame: previous traffic = now
    assert not image[ROAD].any() and not image[PAST].any()


def test_overlapping_vehicles_have_no_holes():
    image = _first(TopDown(), world(vehicles=[[10.0, 0.0, 0.0, 20.0, *CAR], [12.0, 0.0, 0.0, 20.0, *CAR]]))
    assert image[NOW, 19, 42] == 255 and image[NOW, 20, 41] == 255  # inside both, 11 m ahead


def test_heading_aligned():
    ahead = _first(TopDown(), world(vehicles=[[12.5, 0.0, 0.0, 20.0, *CAR], [0.0, 6.0, 0.5, 20.0, *CAR]]))
    # heading +y: ahead is +y and the right is −x
    turned = _first(
        TopDown(),
        world(
            heading=np.pi / 2,
            vehicles=[[0.0, 12.5, np.pi / 2, 20.0, *CAR], [-6.0, 0.0, np.pi / 2 + 0.5, 20.0, *CAR]],
        ),
    )
    assert ahead[NOW, 16, 41] == 255 and ahead[NOW, 41, 53] == 255
    np.testing.assert_array_equal(turned[NOW], ahead[NOW])


def test_previous_traffic_channel():
    sensor = TopDown()
    _first(sensor, world(vehicles=[[10.0, 0.0, 0.0, 20.0, *CAR]]))
    image = sensor.observe(world(vehicles=[[20.0, 0.0, 0.0, 20.0, *CAR]]))  # moved 10 m on
    assert image[NOW, 2, 42] == 255 and image[NOW, 22, 42] == 0
    assert image[BEFORE, 22, 42] == 255 and image[BEFORE, 2, 42] == 0


def test_past_ego_positions_and_reset():
    sensor = TopDown()
    first = _first(sensor, world(vehicles=[[10.0, 0.0, 0.0, 20.0, *CAR]]))
    assert not first[PAST].any()
    image = sensor.observe(world(position=np.array([5.0, 0.0]), vehicles=[[15.0, 0.0, 0.0, 20.0, *CAR]]))
    # 5 m behind: row 41.5 + 10, a 1 m (2 px) dot
    assert _bounds(image[PAST]) == (51, 52, 41, 42) and image[PAST, 84 // 2 + 5 * 2, 84 // 2] == 255
    assert image[BEFORE].any()
    again = _first(sensor, world(position=np.array([5.0, 0.0])))
    assert not again[PAST].any() and not again[BEFORE].any()  # reset forgets both


def test_history_keeps_the_last_positions_only():
    sensor = TopDown(history=2)
    sensor.reset(world(), np.random.default_rng(0))
    for x in (0.0, 3.0, 6.0):
        sensor.observe(world(position=np.array([x, 0.0])))
    image = sensor.observe(world(position=np.array([9.0, 0.0])))
    # dots 3 m and 6 m behind (rows 47.5 and 53.5); the one 9 m behind has dropped out
    assert image[PAST, 47, 41] == 255 and image[PAST, 53, 42] == 255
    assert image[PAST, 59:62].sum() == 0 and np.count_nonzero(image[PAST]) == 8
    assert not _first(TopDown(history=0), world())[PAST].any()


def test_route_channel():
    image = _first(TopDown(), world())  # route along +x from the ego, 2 m wide: columns 39.5 … 43.5
    assert np.all(image[ROUTE, 30, 40:44] == 255) and np.all(image[ROUTE, 0, 40:44] == 255)
    assert image[ROUTE, 30, 38] == 0 and image[ROUTE, 30, 46] == 0
    assert image[ROUTE, 60, 41] == 0  # the route starts at the ego


def test_lights_channel_draws_stop_bars_by_state():
    import dataclasses

    from drivelab.perception.topdown import TopDown
    from drivelab.world.state import LIGHT_GREEN, LIGHT_RED
    from tests.worlds import world

    # a red light 10 m ahead in the ego's lane, a green one 10 m behind (heading the other way)
    lights = np.array([[10.0, 0.0, 0.0, LIGHT_RED], [-10.0, 0.0, np.pi, LIGHT_GREEN]])
    state = dataclasses.replace(world(), traffic_lights=lights)
    sensor = TopDown(lights=True)
    assert sensor.space.shape == (6, 84, 84)
    sensor.reset(state, np.random.default_rng(0))
    image = sensor.observe(state)[5]
    # 2 px/m, ego at the centre (42, 42): the red bar, 1 m deep and 4 m wide, centred 20 px above
    # covers continuous rows 21..23 and columns 38..46, i.e. pixel rows 21-22, columns 38-45
    assert image[21:23, 38:46].min() == 255 and image[20, 42] == image[23, 42] == image[21, 37] == 0
    assert image[62, 38:46].tolist() == [85] * 8
    assert set(np.unique(image)) == {0, 85, 255}
    assert TopDown().space.shape == (5, 84, 84)
