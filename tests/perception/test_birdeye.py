import numpy as np

from drivelab.envs.world import Events
from drivelab.perception import birdeye
from drivelab.perception.birdeye import BirdEye, render_birdeye
from tests.worlds import world


def test_shape_colours_and_collision():
    sensor = BirdEye()
    w = world(vehicles=[[12.5, 0.0, 0.0, 20.0, 5.0, 2.0]])
    image = sensor.observe(w)
    assert image.shape == (128, 128, 3) == sensor.space.shape and image.dtype == np.uint8
    assert tuple(image[64, 64]) == birdeye.EGO
    assert tuple(image[64 - 38, 64]) == birdeye.VEHICLE  # 12.5 m ahead at 3 px/m
    assert tuple(image[5, 5]) == birdeye.GRASS
    crashed = render_birdeye(world(events=Events(collided=True)))
    assert tuple(crashed[64, 64]) == birdeye.EGO_CRASHED


def test_custom_size():
    assert render_birdeye(world(), size_hw=(60, 100), pixels_per_meter=2.0).shape == (60, 100, 3)
