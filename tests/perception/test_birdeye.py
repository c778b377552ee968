"""Bird's-eye RGB: known colours at known pixels (128 px at 3 px/m: the ego at 63.5, 63.5)."""

import dataclasses

import numpy as np

from drivelab.perception import birdeye
from drivelab.perception.birdeye import BirdEye, render_birdeye
from drivelab.world.state import MARKING_DASHED, MARKING_SOLID, Events, RoadMap
from tests.worlds import world


def _with_road(w, polygons=(), markings=(), kinds=()):
    road = RoadMap(
        tuple(np.array(p, dtype=float) for p in polygons),
        (),
        np.zeros(len(polygons)),
        np.array(markings, dtype=float).reshape(-1, 2, 2),
        np.array(kinds, dtype=int),
        np.zeros((0, 2, 2)),
    )
    return dataclasses.replace(w, road=road)


def _close(pixel, colour, tolerance=16):  # anti-aliased 1 px lines are a little lighter
    return np.abs(pixel.astype(int) - colour).max() <= tolerance


def test_shape_colours_and_collision():
    sensor = BirdEye()
    w = world(vehicles=[[12.5, 0.0, 0.0, 20.0, 5.0, 2.0]])
    sensor.reset(w, np.random.default_rng(0))
    image = sensor.observe(w)
    assert image.shape == (128, 128, 3) == sensor.space.shape and image.dtype == np.uint8
    assert sensor.space.contains(image)
    assert tuple(image[64, 64]) == birdeye.EGO and tuple(image[57, 62]) == birdeye.EGO
    assert tuple(image[64 - 38, 64]) == birdeye.VEHICLE  # 12.5 m ahead at 3 px/m: row 63.5 − 37.5
    assert tuple(image[5, 5]) == birdeye.GRASS
    assert tuple(image[100, 64]) == birdeye.GRASS  # behind the ego: no road, no route
    crashed = render_birdeye(world(events=Events(collided=True)))
    assert tuple(crashed[64, 64]) == birdeye.EGO_CRASHED


def test_heading_up():
    ahead = render_birdeye(world(vehicles=[[0.0, 12.5, np.pi / 2, 20.0, 5.0, 2.0]], heading=np.pi / 2))
    assert tuple(ahead[26, 64]) == birdeye.VEHICLE
    right = render_birdeye(world(vehicles=[[0.0, 6.0, 0.0, 20.0, 5.0, 2.0]]))
    assert tuple(right[64, 64 + 18]) == birdeye.VEHICLE  # 6 m to the right: column 63.5 + 18


def test_road_route_and_crossing_lanes():
    lanes = ([[-40, -2], [40, -2], [40, 2], [-40, 2]], [[-2, -40], [2, -40], [2, 40], [-2, 40]])
    image = render_birdeye(_with_road(world(), lanes))
    assert tuple(image[64, 10]) == birdeye.ROAD  # the crossing lane, left of the ego
    assert tuple(image[60, 59]) == birdeye.ROAD  # where the lanes overlap, beside the ego: no hole
    assert tuple(image[100, 64]) == birdeye.ROAD and tuple(image[100, 100]) == birdeye.GRASS
    assert tuple(image[10, 64]) == birdeye.ROUTE  # the route runs ahead over the road


def test_markings_solid_and_dashed():
    # a line at 3⅙ m lies on pixel column 63.5 ± 9.5; dashes 3 m long every 8 m from the line's start
    y = 3 + 1 / 6
    dashed = [[[-50.0, y], [0.0, y]], [[0.0, y], [50.0, y]]]  # one line in two touching pieces
    solid = [[[-50.0, -y], [50.0, -y]]]
    w = _with_road(world(), markings=dashed + solid, kinds=[MARKING_DASHED] * 2 + [MARKING_SOLID])
    image = render_birdeye(w)
    # dash at arc [56, 59] m = x in [6, 9]; x = 7.5 m is row 63.5 − 22.5; x = 11.5 m, a gap, row 29
    assert _close(image[41, 73], birdeye.DASHED_LINE) and tuple(image[29, 73]) == birdeye.GRASS
    assert _close(image[41, 54], birdeye.SOLID_LINE) and _close(image[29, 54], birdeye.SOLID_LINE)
    whole = _with_road(world(), markings=[[[-50.0, y], [50.0, y]]], kinds=[MARKING_DASHED])
    # the rhythm runs on across the join (x = 0, row 63.5, where anti-aliasing differs slightly)
    single = render_birdeye(whole)
    rows = np.r_[0:58, 70:128]
    np.testing.assert_array_equal(single[rows, 70:], image[rows, 70:])


def test_custom_size():
    image = render_birdeye(world(), size_hw=(60, 100), pixels_per_meter=2.0)
    assert image.shape == (60, 100, 3)
    assert tuple(image[30, 50]) == birdeye.EGO and tuple(image[30, 90]) == birdeye.GRASS


def test_pedestrians_and_zebra_crossings():
    walker = np.array([[10.0, -6.0, np.pi / 2, 1.2, 0.8, 0.8]])  # 10 m ahead, 6 m to the left
    crossing = np.array([[15.0, 0.0, np.pi / 2, 8.0, 3.0]])  # stripes at y = ±0.5, ±1.5, ...
    w = _with_road(world(), polygons=[[[-50, -4], [50, -4], [50, 4], [-50, 4]]])
    w = dataclasses.replace(w, pedestrians=walker, road=dataclasses.replace(w.road, crossings=crossing))
    image = render_birdeye(w, (400, 400), 10.0)  # fine enough to resolve 0.5 m stripes; ego at 199.5
    assert tuple(image[200 - 100, 200 - 60]) == birdeye.PEDESTRIAN
    assert tuple(image[200 - 150, 200 + 15]) == birdeye.ZEBRA  # a stripe 15 m ahead, 1.5 m right
    assert tuple(image[200 - 150, 200 + 20]) == birdeye.ROAD  # the road between two stripes (y = 2 m)
