"""Road geometry of the bottom layer: segment arrays, guide lines kept on the map, and where
lines cross the ground ahead of K egos."""

import dataclasses

import numpy as np

from drivelab.world.batch import WorldBatch
from drivelab.world.road_geometry import (
    GuideSegments,
    batch_guide_segments,
    batch_lateral_at_distances,
    batch_route_segments,
    guide_segments,
    lateral_at_distances,
    polyline_segments,
)
from drivelab.world.state import RoadMap, Route
from tests.worlds import world


def _guided(lines, **ego):
    w = world(**ego)
    return dataclasses.replace(w, road=dataclasses.replace(RoadMap.empty(), guide_lines=tuple(lines)))


def test_polyline_segments():
    segments = polyline_segments(np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 2.0]]))
    np.testing.assert_array_equal(segments, [[[0, 0], [1, 0]], [[1, 0], [1, 2]]])
    assert polyline_segments(np.zeros((1, 2))).shape == (0, 2, 2)


def test_guide_segments_are_built_once_per_map():
    road = _guided(
        [np.array([[0.0, 0.0], [10.0, 0.0], [20.0, 0.0]]), np.array([[0.0, 5.0], [9.0, 5.0]])]
    ).road
    first = guide_segments(road)
    assert first.shape == (3, 2, 2)
    assert guide_segments(road) is first  # kept on the map (RoadMap.derived), not rebuilt
    np.testing.assert_array_equal(first, GuideSegments(road).segments)


def test_batch_guide_segments_pad_shorter_maps_with_nan():
    long_line = np.array([[0.0, 1.0], [10.0, 1.0], [20.0, 1.0], [30.0, 1.0]])
    worlds = [_guided([long_line]), world(), _guided([long_line])]
    segments = batch_guide_segments(WorldBatch.stack(worlds))
    assert segments.shape == (3, 3, 2, 2)
    assert np.isnan(segments[1]).all()  # the map without a guide line
    np.testing.assert_array_equal(segments[0], segments[2])


def test_lateral_at_distances_over_k_worlds():
    line = np.array([[-10.0, 2.0], [100.0, 2.0]])
    worlds = [_guided([line], position=np.array([0.0, y])) for y in (0.0, 0.5, 3.0)]
    worlds.append(_guided([line], position=np.array([0.0, 0.0]), heading=np.pi))  # facing away
    batch = WorldBatch.stack(worlds)
    lateral = batch_lateral_at_distances(batch, batch_guide_segments(batch), np.array([3.0, 30.0, 200.0]))
    expected = [[2.0, 2.0, np.nan], [1.5, 1.5, np.nan], [-1.0, -1.0, np.nan], [-2.0, np.nan, np.nan]]
    np.testing.assert_allclose(lateral, expected)  # facing −x: the line lies to the left and ends 10 m ahead
    for k, w in enumerate(worlds):
        single = lateral_at_distances(w, guide_segments(w.road), np.array([3.0, 30.0, 200.0]))
        np.testing.assert_array_equal(single, lateral[k])


def test_route_segments_padding_crosses_nothing():
    short = world()
    longer = dataclasses.replace(
        world(), route=Route(np.array([[0.0, 0.0], [5.0, 0.0], [9.0, 0.0]]), 0.0, 9.0)
    )
    batch = WorldBatch.stack([short, longer])
    segments = batch_route_segments(batch)
    assert segments.shape == (2, 2, 2, 2)
    np.testing.assert_array_equal(segments[0, 1, 0], segments[0, 1, 1])  # zero length: padding
    lateral = batch_lateral_at_distances(batch, segments, np.array([3.0, 20.0]))
    np.testing.assert_array_equal(lateral, [[0.0, 0.0], [0.0, np.nan]])
