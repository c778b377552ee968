"""Road geometry of the bottom layer: segment arrays, guide lines kept on the map, and where
lines cross the ground ahead of K egos."""

import dataclasses

import numpy as np

from drivelab.world.batch import WorldBatch
from drivelab.world.road_geometry import GuideSegments, guide_segment_sets, guide_segments, polyline_segments
from drivelab.world.state import RoadMap, Route
from tests.crossings import (
    batch_guide_segments,
    batch_lateral_at_distances,
    batch_route_segments,
    lateral_at_distances,
    lateral_crossings,
    polyline_crossings,
)
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


def _lateral_by_numpy(position, heading, segments, distances):
    """The (K, D, M) numpy formulation the compiled kernel replaced, as an independent reference."""
    from drivelab.world.geometry import ego_frame

    local = ego_frame(segments, position[:, None, None, :], heading[:, None, None])
    x0, x1 = local[:, None, :, 0, 0], local[:, None, :, 1, 0]
    y0, y1 = local[:, None, :, 0, 1], local[:, None, :, 1, 1]
    d = distances[None, :, None]
    span = np.where(np.abs(x1 - x0) < 1e-12, np.nan, x1 - x0)
    with np.errstate(invalid="ignore"):
        t = (d - x0) / span
        y = np.where((t >= 0) & (t <= 1), y0 + t * (y1 - y0), np.nan)
    y = np.where(np.isnan(y), np.inf, y)
    best = np.take_along_axis(y, np.argmin(np.abs(y), axis=2)[..., None], axis=2)[..., 0]
    return np.where(np.isfinite(best), best, np.nan)


def test_compiled_crossings_equal_the_numpy_formulation():
    rng = np.random.default_rng(7)
    count, segments_per_world = 16, 40
    position = rng.uniform(-20, 20, (count, 2))
    heading = rng.uniform(-np.pi, np.pi, count)
    segments = rng.uniform(-30, 30, (count, segments_per_world, 2, 2))
    segments[3, 10:] = np.nan  # padding
    segments[5, 4, 1] = segments[5, 4, 0]  # zero length
    distances = np.array([0.5, 3.0, 8.0, 25.0])
    expected = _lateral_by_numpy(position, heading, segments, distances)
    got = lateral_crossings(position, heading, segments, distances)
    # the same operations in the same order on both sides (cos/sin from numpy on both): equal bits
    np.testing.assert_array_equal(got, expected)
    assert np.isfinite(got).sum() > 20  # the draw does produce crossings
    shared = lateral_crossings(position, heading, segments[:4], distances, index=np.arange(count) % 4)
    np.testing.assert_array_equal(
        shared, _lateral_by_numpy(position, heading, segments[np.arange(count) % 4], distances)
    )


def test_crossings_at_a_segments_very_end_are_found():
    """The search passes over segments whose x range misses every ground line; one that ends
    exactly on a line, or begins on it, still crosses it (t = 1, t = 0), from either side."""
    distances = np.array([4.0, 13.0])
    segments = np.array(
        [
            [[[0.0, 1.0], [4.0, 1.0]], [[13.0, -2.0], [20.0, -2.0]]],  # ends on 4 m; begins on 13 m
            [[[4.0, 0.5], [-3.0, 0.5]], [[30.0, 2.5], [13.0, 2.5]]],  # the same, drawn backwards
            [[[-9.0, 0.1], [3.999, 0.1]], [[13.001, 0.2], [40.0, 0.2]]],  # just short of both lines
        ]
    )
    got = lateral_crossings(np.zeros((3, 2)), np.zeros(3), segments, distances)
    np.testing.assert_array_equal(got[:2], [[1.0, -2.0], [0.5, 2.5]])
    assert np.isnan(got[2]).all()
    np.testing.assert_array_equal(got, _lateral_by_numpy(np.zeros((3, 2)), np.zeros(3), segments, distances))


def test_guide_segment_sets_follow_the_batch_roads():
    line_a = np.array([[0.0, 1.0], [10.0, 1.0], [20.0, 1.0]])
    line_b = np.array([[0.0, -1.0], [10.0, -1.0]])
    a, b = _guided([line_a]), _guided([line_b])
    first = guide_segment_sets(WorldBatch.stack([a, b, a]))
    assert first.shape == (2, 2, 2, 2) and np.isnan(first[1, 1]).all()
    assert guide_segment_sets(WorldBatch.stack([a, b, a])) is first  # kept while the maps are the same
    other = _guided([line_b])
    swapped = guide_segment_sets(WorldBatch.stack([a, other]))
    assert swapped is not first
    np.testing.assert_array_equal(swapped[1, :1], guide_segments(other.road))


def test_polyline_crossings_equal_the_segments_of_the_polyline():
    rng = np.random.default_rng(3)
    polylines = np.cumsum(rng.uniform(-2, 6, (5, 30, 2)), axis=1)
    polylines[2, 20:] = polylines[2, 19]  # a shorter route, padded by repeating its last point
    position, heading = rng.uniform(0, 40, (5, 2)), rng.uniform(-np.pi, np.pi, 5)
    distances = np.array([4.0, 6.0, 9.0, 13.0])
    segments = np.stack([polylines[:, :-1], polylines[:, 1:]], axis=2)
    np.testing.assert_array_equal(
        polyline_crossings(position, heading, polylines, distances),
        lateral_crossings(position, heading, segments, distances),
    )
