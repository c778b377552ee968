"""Camera: the pinhole projection with known answers, rendered colours at projected pixels, masks
that coincide with the painted markings."""

import dataclasses

import numpy as np
import pytest

from drivelab.perception import camera
from drivelab.perception.camera import Camera, PinholeModel, render_masks
from drivelab.perception.sensors import make_sensor
from drivelab.world.state import (
    LIGHT_GREEN,
    LIGHT_RED,
    LIGHT_YELLOW,
    MARKING_DASHED,
    MARKING_SOLID,
    RoadMap,
    Route,
)
from tests.crossings import lateral_at_distances
from tests.worlds import world

STRAIGHT = np.array([[-50.0, 0.0], [500.0, 0.0]])


def _three_lane_world(
    guide=True, kinds=(MARKING_SOLID, MARKING_DASHED, MARKING_DASHED, MARKING_SOLID), **ego
):
    """Three 4 m lanes centred on y = −4, 0, 4; the ego in the middle one, its route along y = 0."""
    polygons = tuple(
        np.array([[-50, c - 2], [500, c - 2], [500, c + 2], [-50, c + 2]], float) for c in (-4, 0, 4)
    )
    markings = np.array([[[-50.0, y], [500.0, y]] for y in (-6, -2, 2, 6)])
    road = RoadMap(
        polygons, (), np.full(3, 4.0), markings, np.array(kinds), np.zeros((0, 2, 2)),
        guide_lines=(STRAIGHT,) if guide else (),
    )  # fmt: skip
    w = world(**ego)
    return dataclasses.replace(w, road=road, route=Route(STRAIGHT, 0.0, np.inf))


def test_projection_known_points():
    level = PinholeModel(width=84, height=84, fov_deg=90, height_m=1.5, pitch_deg=0, forward_m=0)
    assert level.focal_px == pytest.approx(42.0)
    # 10 m ahead, 2 m right, at the camera's height: u = 41.5 + 42·2/10, v = centre row
    np.testing.assert_allclose(level.project(np.array([10.0, 2.0, 1.5])), [49.9, 41.5])
    # on the ground 10 m ahead: 1.5 m below the axis → v = 41.5 + 42·1.5/10
    np.testing.assert_allclose(level.project_ground(np.array([10.0, 0.0])), [41.5, 47.8])
    assert level.horizon_row == pytest.approx(41.5)
    pitched = PinholeModel(pitch_deg=15.0, forward_m=1.0)
    # a point on the pitched optical axis projects to the image centre
    along_axis = np.array([1.0 + 20 * np.cos(np.radians(15)), 0.0, 1.5 - 20 * np.sin(np.radians(15))])
    np.testing.assert_allclose(pitched.project(along_axis), [41.5, 41.5], atol=1e-9)
    rows = pitched.row_of_distance(np.array([3.0, 8.0, 20.0]))
    np.testing.assert_allclose(pitched.distance_of_row(rows), [3.0, 8.0, 20.0])
    assert np.isinf(pitched.distance_of_row(pitched.horizon_row - 1))


def test_rendered_colours_at_projected_pixels():
    sensor = Camera(width=256, height=256)
    w = _three_lane_world(vehicles=[[15.0, 4.0, 0.0, 10.0, 5.0, 2.0]])
    sensor.reset(w, np.random.default_rng(0))
    image = sensor.observe(w)
    assert image.shape == (256, 256, 3) == sensor.space.shape and sensor.space.contains(image)
    model = sensor.model
    assert tuple(image[0, 40]) == camera.SKY
    pixel = lambda x, y: tuple(np.round(model.project_ground(np.array([x, y]))).astype(int)[::-1])  # noqa: E731
    assert tuple(image[pixel(10.0, 0.0)]) == camera.YELLOW  # the guide line under the ego's axis
    assert tuple(image[pixel(8.0, -6.0)]) == camera.WHITE  # the left road edge
    assert tuple(image[pixel(8.0, -1.0)]) == camera.ROAD
    assert tuple(image[pixel(8.0, -7.0)]) == camera.GRASS
    u, v = np.round(model.project(np.array([15.0 - 2.5, 4.0, 0.75]))).astype(int)  # the car's rear face
    assert tuple(image[v, u]) == camera.FACE_COLOURS[2]


def test_pedestrians_zebra_crossings_and_light_colours():
    sensor = Camera(width=256, height=256)
    w = _three_lane_world(guide=False)
    crossing = np.array([[20.0, 0.0, np.pi / 2, 12.0, 3.0]])  # across all three lanes, 20 m ahead
    walker = np.array([[12.0, -3.0, np.pi / 2, 1.2, 0.8, 0.8]])
    lights = np.array([[30.0, 3.0, 0.0, LIGHT_GREEN], [30.0, -3.0, 0.0, LIGHT_RED]])
    w = dataclasses.replace(
        w, road=dataclasses.replace(w.road, crossings=crossing), pedestrians=walker, traffic_lights=lights
    )
    sensor.reset(w, np.random.default_rng(0))
    image = sensor.observe(w)
    model = sensor.model
    pixel = lambda x, y, z=0.0: tuple(np.round(model.project(np.array([x, y, z]))).astype(int)[::-1])  # noqa: E731
    assert tuple(image[pixel(12.0 - 0.4, -3.0, 0.85)]) in camera.PEDESTRIAN_COLOURS  # its near face
    assert tuple(image[pixel(20.0, 0.5)]) == camera.WHITE  # a stripe every metre, 0.5 m wide ...
    assert tuple(image[pixel(20.0, 1.0)]) == camera.ROAD  # ... with road between
    assert tuple(image[pixel(30.0, 3.0, camera.LIGHT_HEIGHT_M)]) == camera.LIGHT_COLOURS[LIGHT_GREEN]
    assert camera.LIGHT_COLOURS[LIGHT_GREEN][1] > 200 and camera.LIGHT_COLOURS[LIGHT_RED][0] > 200


def test_masks_cover_exactly_the_painted_lines():
    # solid everywhere so that the masks (continuous lines) equal the paint; the guide line drawn
    # separately, since far away it covers the white lines where they converge
    w = _three_lane_world(kinds=(MARKING_SOLID,) * 4, guide=False)
    model = PinholeModel(width=128, height=96)
    image = camera.render_camera(w, model)
    masks = render_masks(w, model)
    assert masks[2].sum() == 0
    guided = _three_lane_world()
    masks[2] = render_masks(guided, model)[2]
    assert masks.shape == (3, 96, 128) and set(np.unique(masks)) == {0, 1}
    white = np.all(image == camera.WHITE, axis=-1)
    # the ego lane's lines are the painted lines at y = ±2; the outer edges (y = ±6) are not in a mask
    left_pixels = masks[0].astype(bool)
    right_pixels = masks[1].astype(bool)
    assert left_pixels.sum() > 50 and right_pixels.sum() > 50
    assert np.all(white[left_pixels]) and np.all(white[right_pixels])
    columns = np.nonzero(left_pixels)[1]
    assert columns.max() < 64 <= np.nonzero(right_pixels)[1].min()  # left of the centre, right of it
    yellow = np.all(camera.render_camera(guided, model) == camera.YELLOW, axis=-1)
    np.testing.assert_array_equal(masks[2].astype(bool), yellow)


def test_masks_follow_the_ego_offset():
    centred, shifted = _three_lane_world(), _three_lane_world(position=np.array([0.0, 1.0]))
    model = PinholeModel()
    row = int(round(float(model.row_of_distance(8.0))))
    # the ego 1 m to the right: its lane's left line moves left in the image, by f·1 m / depth
    left_c, left_s = (np.nonzero(render_masks(w, model)[0][row])[0].mean() for w in (centred, shifted))
    depth = model.to_camera(np.array([8.0, 0.0, 0.0]))[2]
    assert left_c - left_s == pytest.approx(model.focal_px / depth, abs=1.5)


def test_lateral_at_distances():
    w = _three_lane_world(position=np.array([0.0, 0.5]))
    line = np.array([[[-10.0, 2.0], [100.0, 2.0]]])
    np.testing.assert_allclose(lateral_at_distances(w, line, np.array([3.0, 30.0])), [1.5, 1.5])
    assert np.isnan(lateral_at_distances(w, line, np.array([200.0]))[0])


def test_spec_and_stack():
    sensor = make_sensor("camera:width=32:height=24:stack=2")
    w = _three_lane_world()
    sensor.reset(w, np.random.default_rng(0))
    assert sensor.observe(w).shape == (24, 32, 6)
    with pytest.raises(ValueError):
        PinholeModel(fov_deg=180.0)


@pytest.mark.parametrize("state", [LIGHT_GREEN, LIGHT_YELLOW, LIGHT_RED])
def test_traffic_light_lamp_has_its_state_colour(state):
    sensor = Camera(width=160, height=120)
    w = dataclasses.replace(world(), traffic_lights=np.array([[12.0, 0.0, 0.0, state]]))
    lamp = np.round(sensor.model.project(np.array([12.0, 0.0, camera.LIGHT_HEIGHT_M]))).astype(int)
    image = sensor.observe(w)
    assert tuple(image[lamp[1], lamp[0]]) == camera.LIGHT_COLOURS[state]
    assert camera.LIGHT_COLOURS[LIGHT_GREEN][1] > 200 and camera.LIGHT_COLOURS[LIGHT_RED][0] > 200


def test_traffic_light_just_past_the_near_plane_is_skipped_not_overflowing():
    """A lamp 3 m up and just past the ground near plane is behind the pitched image plane: drawing
    it used to overflow OpenCV's int32 pixel coordinates (found by RLAD's benchmark in the town)."""
    model = PinholeModel(width=84, height=84)
    x = model.forward_m + model.near_m + 0.05
    lights = np.array([[x, 100.0, 0.0, LIGHT_GREEN], [model.forward_m + 10.0, 0.0, 0.0, LIGHT_RED]])
    image = camera.render_camera(dataclasses.replace(world(), traffic_lights=lights), model)
    lamp = model.project(np.array([model.forward_m + 10.0, 0.0, camera.LIGHT_HEIGHT_M]))
    u, v = np.round(lamp).astype(int)
    assert tuple(image[v, u]) == camera.LIGHT_COLOURS[LIGHT_RED]  # the far light is still drawn
