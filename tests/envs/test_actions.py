import numpy as np
import pytest

from drivelab.envs.actions import ContinuousAction, GridAction, MetaAction


def test_grid_default_has_18_actions_with_known_values():
    grid = GridAction()
    assert grid.space.n == 18
    # action i = steering level i // 3, acceleration level i % 3; rows are [acceleration, steering]
    np.testing.assert_allclose(grid.to_control(0), [-1.0, -1.0])
    np.testing.assert_allclose(grid.to_control(7), [0.0, -0.04], atol=1e-6)
    np.testing.assert_allclose(grid.to_control(11), [1.0, 0.04], atol=1e-6)
    np.testing.assert_allclose(grid.to_control(17), [1.0, 1.0])
    steering = np.unique(grid.table[:, 1])
    np.testing.assert_allclose(steering, -steering[::-1])  # symmetric


def test_grid_is_configurable():
    grid = GridAction(steer_levels=5, accel_levels=2)
    assert grid.space.n == 10
    assert 0.0 in grid.table[:, 1]


def test_continuous_swaps_to_backend_order_and_clips():
    control = ContinuousAction().to_control(np.array([0.5, -2.0]))
    np.testing.assert_allclose(control, [-1.0, 0.5])  # [acceleration, steering]


def test_out_of_range_discrete_action_raises():
    with pytest.raises(ValueError):
        MetaAction().to_control(5)
    with pytest.raises(ValueError):
        GridAction().to_control(18)


def test_target_speed_pid_matches_a_hand_computation():
    from drivelab.envs.actions import TargetSpeedAction
    from tests.worlds import world

    adapter = TargetSpeedAction(max_speed_mps=6.0)
    state = world(speed_mps=4.0)  # dt 1 s
    # error 0.5 * 6 - 4 = -1: P -1, I 0.2 * -1, no derivative on the first update
    np.testing.assert_allclose(adapter.control_for([0.5, 0.25], state), [-1.0, 0.25], atol=1e-6)
    # error 6 - 4 = 2: P 2 + I 0.2 * (-1 + 2) + D 0.001 * 3 = 2.203 -> clipped to 1
    np.testing.assert_allclose(adapter.control_for([1.0, -2.0], state), [1.0, -1.0], atol=1e-6)
    adapter.pid(3.9, 4.0, 1.0)
    assert adapter.integral == pytest.approx(-1 + 2 - 0.1)
    adapter.reset()
    # small error: P 0.1 + I 0.2 * 0.1 = 0.12 (inside the range, not clipped)
    assert adapter.pid(4.1, 4.0, 1.0) == pytest.approx(0.12)


def test_target_speed_stop_zone_stops_within_the_step_and_holds():
    """Below ``stop_below`` the command brakes to a standstill within the step (never harder than
    that, never into reverse) and clears the PID; above it, [stop_below, 1] spans 0..max."""
    from drivelab.envs.actions import TargetSpeedAction
    from drivelab.errors import UsageError
    from tests.worlds import world

    adapter = TargetSpeedAction(max_speed_mps=6.0, stop_below=0.2)
    moving, dt = world(speed_mps=2.0), 1.0  # tests.worlds: dt 1 s
    # 2 m/s to 0 within 1 s: -2 m/s², -0.4 of highway-env's 5 m/s²
    np.testing.assert_allclose(adapter.control_for([0.1, 0.3], moving), [-0.4, 0.3], atol=1e-6)
    assert adapter.integral[0] == 0.0 and np.isnan(adapter.previous_error[0])
    np.testing.assert_allclose(adapter.control_for([0.0, 0.0], world(speed_mps=0.0))[0], 0.0, atol=1e-9)
    # rolling back at -0.5 m/s: pushed forward to a standstill, not further back
    np.testing.assert_allclose(adapter.control_for([0.0, 0.0], world(speed_mps=-0.5))[0], 0.1, atol=1e-6)
    np.testing.assert_allclose(adapter.control_for([0.0, 0.0], world(speed_mps=30.0))[0], -1.0)  # clipped
    # above the zone: 0.6 is (0.6 - 0.2) / 0.8 of 6 m/s = 3 m/s; from 2 m/s: P 1, I 0.2 · 1 → 1 (clipped)
    fresh = TargetSpeedAction(max_speed_mps=6.0, stop_below=0.2)
    np.testing.assert_allclose(fresh.pid(3.0, 2.0, dt), 1.0)
    fresh.reset()
    np.testing.assert_allclose(fresh.control_for([0.6, 0.0], world(speed_mps=2.9)), [0.12, 0.0], atol=1e-6)
    # without a zone (the default) the same actions are plain fractions of max_speed_mps
    plain = TargetSpeedAction(max_speed_mps=6.0)
    np.testing.assert_allclose(plain.control_for([0.1, 0.0], moving)[0], -1.0)  # P -1.4, I -0.28: clipped
    for bad in (-0.1, 1.0):
        with pytest.raises(UsageError, match="0 <= stop_below < 1"):
            TargetSpeedAction(stop_below=bad)


def test_the_expert_refuses_a_stop_zone():
    from drivelab.agents.expert import check_expert_env
    from drivelab.envs.vector import VectorDriveEnv
    from drivelab.errors import UsageError

    vector = VectorDriveEnv(1, scenario="town", action="target_speed", action_options={"stop_below": 0.2})
    with pytest.raises(UsageError, match="without the target_speed action's stop_below"):
        check_expert_env(vector, 6.0, "expert")


def test_target_speed_needs_the_world():
    from drivelab.envs.actions import TargetSpeedAction
    from drivelab.errors import UsageError

    with pytest.raises(UsageError, match="control_for"):
        TargetSpeedAction().to_control([0.5, 0.0])
    with pytest.raises(UsageError, match="max_speed_mps > 0"):
        TargetSpeedAction(max_speed_mps=0)


def test_meta_action_subsets_are_highway_envs():
    from drivelab.errors import UsageError
    from drivelab.world.scenario import META_ACTIONS

    full = MetaAction()
    assert full.space.n == 5
    np.testing.assert_array_equal(full.to_controls([0, 1, 2, 3, 4]), [0, 1, 2, 3, 4])
    speed = MetaAction(lateral=False)  # highway-env's ACTIONS_LONGI: slower, idle, faster
    assert speed.space.n == 3
    assert [META_ACTIONS[i] for i in speed.to_controls([0, 1, 2])] == ["SLOWER", "IDLE", "FASTER"]
    lanes = MetaAction(longitudinal=False)  # ACTIONS_LAT
    assert [META_ACTIONS[i] for i in lanes.to_controls([0, 1, 2])] == ["LANE_LEFT", "IDLE", "LANE_RIGHT"]
    with pytest.raises(ValueError, match="outside Discrete"):
        speed.to_controls([3])
    with pytest.raises(UsageError, match="lateral or longitudinal"):
        MetaAction(lateral=False, longitudinal=False)
    with pytest.raises(UsageError, match="true or false"):
        MetaAction(lateral="no")


def test_a_stop_zone_brings_the_town_ego_to_a_standstill_without_rolling_back():
    import drivelab

    speeds = {}
    for name, options in (("plain", None), ("zone", {"stop_below": 0.2})):
        env = drivelab.make("town", obs="measurements", action="target_speed", action_options=options, seed=0)
        env.reset(seed=0)
        for _ in range(30):
            env.step(np.array([0.7, 0.0], np.float32))
        speeds[name] = []
        for _ in range(20):
            env.step(np.array([0.0, 0.0], np.float32))
            speeds[name].append(env.world.ego.speed_mps)
    zone = np.array(speeds["zone"])
    assert np.all(np.abs(zone[5:]) < 1e-9) and zone.min() > -1e-9  # stopped within 1 s, and held
    assert min(speeds["plain"]) < -0.1  # the PID alone at a target of 0 lets the ego roll back
