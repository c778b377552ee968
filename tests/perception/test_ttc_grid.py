"""The discrete time-to-collision grid on hand-built highway worlds."""

import numpy as np

from drivelab.perception.ttc_grid import TTCGrid, lane_ttc_s
from tests.worlds import world


def test_ttc_per_lane_and_state():
    # ego at 25 m/s in the middle of 3 lanes (4 m wide); a car 25 m ahead in its lane at 15 m/s,
    # one 40 m ahead on the right at 30 m/s (pulling away), nothing on the left
    w = world(
        speed_mps=25.0, lane_id=1, lane_count=3, lane_width_m=4.0, length_m=5.0,
        vehicles=[[25.0, 0.0, 0.0, 15.0, 5.0, 2.0], [40.0, 4.0, 0.0, 30.0, 5.0, 2.0]],
    )  # fmt: skip
    np.testing.assert_allclose(lane_ttc_s(w), [np.inf, (25.0 - 5.0) / 10.0, np.inf])
    sensor = TTCGrid()
    assert sensor.space.n == 192
    # bins: left never (3), own 2 s → [2, 4) (1), right never (3); speed 25 → bin 1
    assert sensor.observe(w) == 3 + 4 * 1 + 16 * 3 + 64 * 1


def test_missing_lanes_count_as_blocked():
    w = world(speed_mps=20.0, lane_id=0, lane_count=1)
    np.testing.assert_array_equal(lane_ttc_s(w), [0.0, np.inf, 0.0])
    assert TTCGrid().observe(w) == 0 + 4 * 3 + 0 + 0


def test_qlearning_runs_on_highway_with_the_grid():
    from drivelab.agents.qlearning import build_qlearning
    from drivelab.envs.core import DriveEnv

    env = DriveEnv(
        "highway", obs="ttc_grid", action="meta", reward="highway", traffic="regular", duration_s=3
    )
    env.reset(seed=0)
    agent = build_qlearning("qlearning", env, 0, {}, None)
    agent.learn(20)
    assert agent.num_timesteps == 20 and agent.q_table.shape == (192, 5)
    assert np.count_nonzero(agent.q_table) > 0
