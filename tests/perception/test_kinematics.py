"""Kinematics rows: ordering, ego-frame values and normalisation with known answers."""

import dataclasses

import numpy as np
import pytest

from drivelab.perception.kinematics import ALL_FEATURES, FEATURES, INTENTION_FEATURES, Kinematics
from tests.worlds import world


def _observe(sensor, w):
    sensor.reset(w, np.random.default_rng(0))
    return sensor.observe(w).reshape(sensor.vehicles_count, len(FEATURES))


def test_rows_sorted_by_distance_and_normalised():
    w = world(
        speed_mps=20.0,
        vehicles=[
            [30.0, 0.0, 0.0, 25.0, 5, 2],
            [10.0, 4.0, 0.0, 25.0, 5, 2],
            [150.0, 0.0, 0.0, 25.0, 5, 2],  # beyond the 100 m perception distance
            [-8.0, 0.0, 0.0, 15.0, 5, 2],  # behind, but the nearest
        ],
    )
    rows = _observe(Kinematics(), w)
    # presence, x / 100 m, y / 100 m, vx / 80 m/s, vy / 80 m/s, cos, sin of the relative heading
    np.testing.assert_allclose(rows[0], [1, 0, 0, 0.25, 0, 1, 0], atol=1e-7)
    np.testing.assert_allclose(rows[1], [1, -0.08, 0.0, -0.0625, 0, 1, 0], atol=1e-7)
    np.testing.assert_allclose(rows[2], [1, 0.1, 0.04, 0.0625, 0, 1, 0], atol=1e-7)
    np.testing.assert_allclose(rows[3], [1, 0.3, 0.0, 0.0625, 0, 1, 0], atol=1e-7)
    assert np.all(rows[4] == 0)


def test_ego_frame_and_heading():
    w = world(heading=np.pi / 2, speed_mps=10.0, vehicles=[[0.0, 20.0, np.pi, 10.0, 5, 2]])
    rows = _observe(Kinematics(vehicles_count=2), w)
    # 20 m ahead of an ego heading +y; its heading is π/2 relative to the ego: it drives to the
    # ego's right at 10 m/s while the ego drives forward at 10 m/s
    assert rows[1, 1] == pytest.approx(0.2) and rows[1, 2] == pytest.approx(0.0, abs=1e-7)
    assert rows[1, 3] == pytest.approx(-0.125) and rows[1, 4] == pytest.approx(0.125)
    assert rows[1, 5] == pytest.approx(0.0, abs=1e-7) and rows[1, 6] == pytest.approx(1.0)


def test_ego_heading_is_relative_to_its_lane():
    rows = _observe(Kinematics(vehicles_count=1), world(heading=0.3, lane_heading=0.1, speed_mps=40.0))
    np.testing.assert_allclose(rows[0], [1, 0, 0, 0.5, 0, np.cos(0.2), np.sin(0.2)], atol=1e-7)


def test_absolute_rows_are_in_the_world_frame_like_highway_envs():
    w = world(
        position=np.array([10.0, 5.0]), heading=np.pi / 2, lane_heading=0.0, speed_mps=10.0,
        vehicles=[[10.0, 25.0, np.pi, 16.0, 5, 2], [10.0, 300.0, 0.0, 10.0, 5, 2]],  # the 2nd: unseen
    )  # fmt: skip
    rows = _observe(Kinematics(vehicles_count=3, absolute=True), w)
    # presence, x / 100 m, y / 100 m, vx / 80 m/s, vy / 80 m/s, cos, sin of the heading on the map
    np.testing.assert_allclose(rows[0], [1, 0.1, 0.05, 0, 0.125, 0, 1], atol=1e-7)
    np.testing.assert_allclose(rows[1], [1, 0.1, 0.25, -0.2, 0, -1, 0], atol=1e-7)
    assert np.all(rows[2] == 0)
    relative = _observe(Kinematics(vehicles_count=3), w)
    np.testing.assert_array_equal(relative[:, 0], rows[:, 0])  # the same vehicles are chosen


def test_values_are_clipped():
    w = world(speed_mps=0.0, vehicles=[[60.0, -90.0, 0.0, 200.0, 5, 2]])
    rows = _observe(Kinematics(vehicles_count=2, perception_distance_m=110.0, speed_scale_mps=100.0), w)
    np.testing.assert_allclose(rows[1], [1, 60 / 110, -90 / 110, 1.0, 0, 1, 0], atol=1e-7)


def test_shape_matches_space():
    sensor = Kinematics(vehicles_count=3)
    obs = sensor.observe(world(vehicles=[[10.0, 0.0, 0.0, 20.0, 5, 2]]))
    assert obs.shape == sensor.space.shape == (21,) and obs.dtype == np.float32
    assert sensor.space.contains(obs)
    assert np.all(obs[14:] == 0)  # the third row is absent
    with pytest.raises(ValueError):
        Kinematics(vehicles_count=0)


def test_features_pick_and_order_the_columns():
    w = world(speed_mps=20.0, vehicles=[[30.0, 4.0, 0.0, 25.0, 5, 2]])
    every = _observe(Kinematics(vehicles_count=3), w)
    sensor = Kinematics(vehicles_count=3, features="vx+presence+y")
    obs = sensor.observe(w)
    assert sensor.space.shape == obs.shape == (9,)
    np.testing.assert_array_equal(obs.reshape(3, 3), every[:, [3, 0, 2]].astype(np.float32))
    np.testing.assert_allclose(obs.reshape(3, 3)[1], [0.0625, 1, 0.04], atol=1e-7)
    assert Kinematics(features=["presence", "x"]).features == ("presence", "x")


@pytest.mark.parametrize("features", ["presence+heading", "x+x", ""])
def test_unknown_or_repeated_features_are_refused(features):
    from drivelab.errors import UsageError

    with pytest.raises(UsageError, match="kinematics features must be names of presence, x, y"):
        Kinematics(features=features)


def test_unflattened_rows_are_highway_envs_vehicles_by_features():
    w = world(speed_mps=20.0, vehicles=[[30.0, 4.0, 0.0, 25.0, 5, 2]])
    sensor = Kinematics(vehicles_count=4, features="presence+x+y+vx+vy", flatten=False)
    obs = sensor.observe(w)
    assert obs.shape == sensor.space.shape == (4, 5) and sensor.space.contains(obs)
    np.testing.assert_allclose(obs[:2], [[1, 0, 0, 0.25, 0], [1, 0.3, 0.04, 0.0625, 0]], atol=1e-7)
    assert np.all(obs[2:] == 0)


def test_unnormalised_rows_are_metres_and_metres_per_second():
    w = world(speed_mps=20.0, vehicles=[[160.0, -90.0, 0.0, 200.0, 5, 2]])
    sensor = Kinematics(vehicles_count=2, perception_distance_m=200.0, normalize=False)
    rows = sensor.observe(w).reshape(2, 7)
    assert np.isinf(sensor.space.high).all()
    np.testing.assert_allclose(rows, [[1, 0, 0, 20, 0, 1, 0], [1, 160, -90, 180, 0, 1, 0]], atol=1e-5)


def test_without_clipping_normalised_values_may_leave_the_unit_range():
    w = world(speed_mps=0.0, vehicles=[[60.0, -90.0, 0.0, 200.0, 5, 2]])
    sensor = Kinematics(vehicles_count=2, perception_distance_m=110.0, speed_scale_mps=100.0, clip=False)
    rows = _observe(sensor, w)
    np.testing.assert_allclose(rows[1], [1, 60 / 110, -90 / 110, 2.0, 0, 1, 0], atol=1e-7)


def test_intentions_point_to_each_vehicles_destination_in_the_ego_frame():
    """cos_d, sin_d: the unit direction to a vehicle's destination (none: zeros), the ego's to
    its route's end; rotated into the ego frame, or left on the map with ``absolute``."""
    w = world(
        heading=np.pi / 2, lane_heading=np.pi / 2, speed_mps=10.0,
        vehicles=[[0.0, 20.0, np.pi, 10.0, 5, 2], [0.0, -30.0, 0.0, 10.0, 5, 2]],
    )  # fmt: skip
    # the first turns off to -x, 50 m away; the second has no destination (its own position)
    w = dataclasses.replace(w, vehicle_destinations=np.array([[-50.0, 20.0], [0.0, -30.0]]))
    features = "presence+x+cos_d+sin_d"
    rows = Kinematics(vehicles_count=4, features=features, flatten=False)
    rows.reset(w, np.random.default_rng(0))
    observed = rows.observe(w)
    assert observed.shape == (4, 4)
    # rotated as positions are: the ego heads +y, so +x on the map (its route's end, (1000, 0)) is
    # (0, -1) in its frame and -x (where the first vehicle heads) is (0, 1)
    np.testing.assert_allclose(observed[0], [1, 0, 0, -1], atol=1e-7)
    np.testing.assert_allclose(observed[1], [1, 0.2, 0, 1], atol=1e-7)
    np.testing.assert_allclose(observed[2], [1, -0.3, 0, 0], atol=1e-7)
    assert np.all(observed[3] == 0)
    absolute = Kinematics(vehicles_count=4, features=features, flatten=False, absolute=True)
    absolute.reset(w, np.random.default_rng(0))
    np.testing.assert_allclose(absolute.observe(w)[:3, 2:], [[1, 0], [-1, 0], [0, 0]], atol=1e-7)
    # destinations not known: every other vehicle's intention is zeros
    unknown = dataclasses.replace(w, vehicle_destinations=None)
    rows.reset(unknown, np.random.default_rng(0))
    assert np.all(rows.observe(unknown)[1:, 2:] == 0)


def test_intention_features_leave_the_other_columns_as_they_were():
    w = world(speed_mps=20.0, vehicles=[[30.0, 4.0, 0.3, 25.0, 5, 2], [-8.0, 0.0, 0.0, 15.0, 5, 2]])
    w = dataclasses.replace(w, vehicle_destinations=np.array([[60.0, 40.0], [-8.0, 0.0]]))
    plain = _observe(Kinematics(), w)
    both = Kinematics(features="+".join(FEATURES + INTENTION_FEATURES))
    both.reset(w, np.random.default_rng(0))
    rows = both.observe(w).reshape(5, len(FEATURES) + 2)
    np.testing.assert_array_equal(rows[:, : len(FEATURES)], plain)
    direction = np.array([30.0, 36.0]) / np.hypot(30.0, 36.0)
    np.testing.assert_allclose(rows[2, len(FEATURES) :], direction, atol=1e-7)  # the farther one


def test_accel_is_each_rows_acceleration_scaled_and_clipped_in_either_frame():
    """accel: the row's vehicle's acceleration over ``accel_scale_mps2`` (6 m/s², IDM's limit),
    clipped to [-1, 1]; the ego's own in row 0; raw m/s² unnormalised; zeros where unknown."""
    w = world(
        heading=np.pi / 2, speed_mps=10.0, acceleration_mps2=-1.5,
        vehicles=[[0.0, 20.0, np.pi, 10.0, 5, 2], [0.0, -30.0, 0.0, 10.0, 5, 2], [0.0, 50.0, 0.0, 5.0, 5, 2]],
    )  # fmt: skip
    w = dataclasses.replace(w, vehicle_accelerations=np.array([3.0, -9.0, 0.0]))
    sensor = Kinematics(vehicles_count=5, features="presence+x+accel", flatten=False)
    sensor.reset(w, np.random.default_rng(0))
    observed = sensor.observe(w)
    assert observed.shape == (5, 3)
    # nearest first: the one 20 m ahead (+3), 30 m behind (-9: clipped), 50 m ahead (0), then none
    np.testing.assert_allclose(observed[:, 2], [-0.25, 0.5, -1.0, 0.0, 0.0], atol=1e-7)
    absolute = Kinematics(vehicles_count=5, features="presence+x+accel", flatten=False, absolute=True)
    absolute.reset(w, np.random.default_rng(0))
    np.testing.assert_array_equal(absolute.observe(w)[:, 2], observed[:, 2])
    raw = Kinematics(vehicles_count=5, features="accel", flatten=False, normalize=False)
    raw.reset(w, np.random.default_rng(0))
    np.testing.assert_allclose(raw.observe(w)[:, 0], [-1.5, 3.0, -9.0, 0.0, 0.0], atol=1e-6)
    unknown = dataclasses.replace(w, vehicle_accelerations=None)
    sensor.reset(unknown, np.random.default_rng(0))
    np.testing.assert_allclose(sensor.observe(unknown)[:, 2], [-0.25, 0, 0, 0, 0], atol=1e-7)


def test_accel_and_intentions_together_keep_each_features_values():
    w = world(speed_mps=20.0, vehicles=[[30.0, 4.0, 0.3, 25.0, 5, 2], [-8.0, 0.0, 0.0, 15.0, 5, 2]])
    destinations, accelerations = np.array([[60.0, 40.0], [-8.0, 0.0]]), np.array([1.2, -3.0])
    w = dataclasses.replace(w, vehicle_destinations=destinations, vehicle_accelerations=accelerations)
    every = Kinematics(features="+".join(ALL_FEATURES))
    every.reset(w, np.random.default_rng(0))
    rows = every.observe(w).reshape(5, len(ALL_FEATURES))
    intentions = Kinematics(features="+".join(FEATURES + INTENTION_FEATURES))
    intentions.reset(w, np.random.default_rng(0))
    accel = ALL_FEATURES.index("accel")
    np.testing.assert_array_equal(rows[:, :accel], intentions.observe(w).reshape(5, -1))
    np.testing.assert_allclose(rows[:3, accel], [0.0, -0.5, 0.2], atol=1e-7)  # ego 0; nearest: -8 m behind


def test_accel_scale_must_be_positive():
    with pytest.raises(ValueError, match="acceleration"):
        Kinematics(accel_scale_mps2=0.0)


def test_crossing_features_say_when_and_where_each_vehicle_meets_the_route_ahead():
    """t_cross, s_cross: a vehicle driving on straight at its speed meets the ego's route (the x
    axis from the origin) ahead: seconds to get there over 8 s, the ego's distance to that point
    over 100 m; 1 and 1 where it meets none within 8 s ahead of the ego, 0 in the ego's row and in
    absent rows."""
    w = world(
        vehicles=[
            [30.0, -20.0, np.pi / 2, 10.0, 5, 2],  # meets the route 30 m ahead in 2 s
            [40.0, 20.0, np.pi / 2, 10.0, 5, 2],  # drives away from it
            [-10.0, -5.0, np.pi / 2, 10.0, 5, 2],  # meets the road behind the ego
            [20.0, -70.0, np.pi / 2, 5.0, 5, 2],  # 70 m away at 5 m/s: not within 8 s
        ]
    )
    features = "presence+x+t_cross+s_cross"
    sensor = Kinematics(vehicles_count=6, features=features, flatten=False)
    sensor.reset(w, np.random.default_rng(0))
    observed = sensor.observe(w)
    # nearest first: behind (11 m), 30 m ahead (36 m), away (45 m), slow (73 m), then none
    np.testing.assert_allclose(observed[:, 2], [0.0, 1.0, 0.25, 1.0, 1.0, 0.0], atol=1e-7)
    np.testing.assert_allclose(observed[:, 3], [0.0, 1.0, 0.3, 1.0, 1.0, 0.0], atol=1e-7)
    absolute = Kinematics(vehicles_count=6, features=features, flatten=False, absolute=True)
    absolute.reset(w, np.random.default_rng(0))
    np.testing.assert_array_equal(absolute.observe(w)[:, 2:], observed[:, 2:])
    raw = Kinematics(vehicles_count=6, features="t_cross+s_cross", flatten=False, normalize=False)
    raw.reset(w, np.random.default_rng(0))
    np.testing.assert_allclose(raw.observe(w)[:3], [[0, 0], [8, 100], [2, 30]], atol=1e-5)
    passed = world(vehicles=w.vehicles, progress_m=35.0)  # the crossing 30 m along is behind now
    sensor.reset(passed, np.random.default_rng(0))
    np.testing.assert_allclose(sensor.observe(passed)[2, 2:], [1.0, 1.0], atol=1e-7)
    longer = Kinematics(vehicles_count=6, features=features, flatten=False, crossing_horizon_s=16.0)
    longer.reset(w, np.random.default_rng(0))
    np.testing.assert_allclose(longer.observe(w)[4, 2:], [14.0 / 16.0, 0.2], atol=1e-7)  # 70 m at 5 m/s


def test_crossing_horizon_must_be_positive():
    with pytest.raises(ValueError, match="crossing-horizon"):
        Kinematics(crossing_horizon_s=0.0)
