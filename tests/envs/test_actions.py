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
