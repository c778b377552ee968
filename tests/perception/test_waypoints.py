"""Waypoints and measurements on hand-built WorldStates with known answers."""

import dataclasses

import numpy as np
import pytest

from drivelab.perception.measurements import Measurements
from drivelab.perception.waypoints import Waypoints
from drivelab.world.state import Route
from tests.worlds import world


def _observe(sensor, state):
    sensor.reset(state, np.random.default_rng(0))
    return sensor.observe(state)


def test_a_straight_route_ahead_gives_points_on_the_x_axis():
    points = _observe(Waypoints(), world(progress_m=100.0, position=np.array([100.0, 0.0])))
    assert points.shape == (10, 2)
    np.testing.assert_allclose(points[:, 0], 2.0 * np.arange(1, 11), atol=1e-5)
    np.testing.assert_allclose(points[:, 1], 0.0, atol=1e-5)


def test_points_are_in_the_ego_frame():
    """Ego 1 m before the route line (y = -1) and facing it (+y): the route crosses 1 m ahead,
    running to the ego's left."""
    state = world(progress_m=0.0, position=np.array([0.0, -1.0]), heading=np.pi / 2)
    points = _observe(Waypoints(count=3, spacing_m=5.0), state)
    # world +x is the ego's left (-y); world +y its forward (+x)
    np.testing.assert_allclose(points, [[1.0, -5.0], [1.0, -10.0], [1.0, -15.0]], atol=1e-5)


def test_past_the_end_the_last_point_repeats():
    state = world(progress_m=995.0, position=np.array([995.0, 0.0]))
    points = _observe(Waypoints(count=4, spacing_m=2.0), state)
    np.testing.assert_allclose(points[:, 0], [2.0, 4.0, 5.0, 5.0], atol=1e-5)


def test_a_turning_route_bends_the_waypoints():
    polyline = np.array([[0.0, 0.0], [10.0, 0.0], [10.0, 10.0]])  # straight, then a right turn (+y)
    state = dataclasses.replace(world(position=np.array([6.0, 0.0])), route=Route(polyline, 6.0, 20.0))
    points = _observe(Waypoints(count=5, spacing_m=2.0), state)
    np.testing.assert_allclose(points, [[2, 0], [4, 0], [4, 2], [4, 4], [4, 6]], atol=1e-6)


def test_closed_route_wraps_round_the_lap():
    square = np.array([[0.0, 0.0], [10.0, 0.0], [10.0, 10.0], [0.0, 10.0], [0.0, 0.0]])
    route = Route(square, progress_m=38.0, length_m=float("inf"), closed=True)
    points, headings = route.poses_at(np.array([38.0, 42.0]))
    np.testing.assert_allclose(points, [[0.0, 2.0], [2.0, 0.0]], atol=1e-9)
    assert headings[1] == pytest.approx(0.0)


def test_measurements():
    values = _observe(Measurements(), world(speed_mps=20.0, steering=np.pi / 6))
    np.testing.assert_allclose(values, [0.5, 0.5], atol=1e-6)
    assert Measurements().space.contains(_observe(Measurements(), world(speed_mps=-50.0)))
