"""Issue 47: what the environments refuse from their Python users (the CLI's one-line errors are
``tests/test_bad_input.py``): actions that are NaN, infinite or not an integer of a discrete space,
a step after the episode ended without ``reset``, its time limit read before one, ``reset``
options that are not a dict, and episode seeds an int64 cannot hold."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

from drivelab.envs.actions import ContinuousAction, GridAction, MetaAction, SeedTable
from drivelab.envs.core import DriveEnv
from drivelab.envs.vector import VectorDriveEnv
from drivelab.errors import UsageError
from drivelab.scenarios import SCENARIOS

NOT_FINITE = [[np.nan, 0.0], [0.0, np.inf], [-np.inf, 0.5]]
NOT_AN_INDEX = [2.7, True, np.True_, np.float32(1.0), np.array([1.0, 2.0]), np.nan]


@pytest.mark.parametrize("scenario", list(SCENARIOS))
def test_non_finite_continuous_actions_are_refused_in_every_scenario(scenario):
    """Two worlds, the second's action broken: the whole step is refused (no NaN observation or
    reward comes back), the worlds stay where they were, and a finite action steps on."""
    env = VectorDriveEnv(2, scenario=scenario, action="continuous", traffic="empty")
    env.reset(seed=3)
    before = env.batch.ego.position.copy()
    for broken in NOT_FINITE:
        with pytest.raises(ValueError, match=r"continuous action \[.*\] is not finite"):
            env.step(np.array([[0.1, 0.2], broken]))
    np.testing.assert_array_equal(env.batch.ego.position, before)
    observations, rewards, *_ = env.step(np.zeros((2, 2)))
    assert np.isfinite(rewards).all() and np.isfinite(observations).all()


@pytest.mark.parametrize(
    ("scenario", "action"), [("follow-line", "continuous"), ("racetrack", "target_speed")]
)
def test_non_finite_actions_are_refused_by_one_world(scenario, action):
    """DriveEnv's own paths: the circuits' compiled step (follow-line) and the target-speed PID."""
    env = DriveEnv(scenario, action=action, traffic="empty")
    env.reset(seed=0)
    for broken in NOT_FINITE:
        with pytest.raises(ValueError, match="is not finite"):
            env.step(np.array(broken, dtype=np.float32))
    _, reward, *_ = env.step(env.action_space.sample())
    assert np.isfinite(reward)


@pytest.mark.parametrize("adapter", [MetaAction(), GridAction(), SeedTable("line")], ids=lambda a: a.name)
def test_discrete_actions_must_be_integers(adapter):
    for action in NOT_AN_INDEX:
        with pytest.raises(
            ValueError, match=r"of Discrete\(\d+\) is not an integer \((float|bool)\d* actions\)"
        ):
            adapter.to_controls(np.asarray(action).reshape(-1))
    for action in (2, np.int64(2), np.uint8(2), np.array([0, 1])):
        assert len(adapter.to_controls(np.asarray(action).reshape(-1))) == np.asarray(action).size


def test_a_discrete_action_of_2_7_or_true_is_refused_by_the_env():
    env = DriveEnv("highway", traffic="empty")
    env.reset(seed=0)
    for action in (2.7, True):
        with pytest.raises(ValueError, match="is not an integer"):
            env.step(action)
    env.step(2)


def test_continuous_actions_outside_the_box_are_still_clipped():
    np.testing.assert_array_equal(ContinuousAction().to_controls(np.array([[3.0, -1e30]])), [[-1.0, 1.0]])


@pytest.mark.parametrize("scenario", ["highway", "follow-line"])  # the second: the compiled step
def test_a_step_after_the_episode_ended_needs_a_reset(scenario):
    """gymnasium's contract: a finished episode is reset before the next step. The 20 steps the
    probe took past the end each emitted the ended episode's metrics again."""
    env = DriveEnv(scenario, traffic="empty", duration_s=2)
    env.reset(seed=0)
    ended, steps = False, 0
    while not ended:
        _, _, terminated, truncated, info = env.step(env.action_space.sample())
        ended, steps = terminated or truncated, steps + 1
    assert "episode_metrics" in info and steps < 100
    for _ in range(2):
        with pytest.raises(gym.error.ResetNeeded, match=r"episode is over .* call reset\(\) before step\(\)"):
            env.step(env.action_space.sample())
    env.reset()
    _, _, _, _, info = env.step(env.action_space.sample())
    assert "episode_metrics" not in info


def test_the_time_limit_is_read_after_reset():
    """The time limit is the episode's (a town or block route has its own): before the first
    reset there is none to read, and the error says so instead of an IndexError."""
    env = DriveEnv("highway", traffic="empty", duration_s=7)
    with pytest.raises(RuntimeError, match=r"call reset\(\) before reading time_limit_s"):
        _ = env.time_limit_s
    env.reset(seed=0)
    assert env.time_limit_s == 7


def test_the_vector_env_steps_through_episode_ends_by_itself():
    """VectorDriveEnv resets its finished worlds (autoreset): no reset is asked of its users."""
    env = VectorDriveEnv(2, scenario="highway", traffic="empty", duration_s=1)
    env.reset(seed=0)
    finished = 0
    for _ in range(12):
        _, _, terminated, truncated, _ = env.step(env.action_space.sample())
        finished += int(np.count_nonzero(terminated | truncated))
    assert finished >= 2


@pytest.mark.parametrize("options", [[1, 2], "episode_seed=3", 3])
def test_reset_options_must_be_a_dict(options):
    for env in (DriveEnv("highway", traffic="empty"), VectorDriveEnv(2, scenario="highway", traffic="empty")):
        with pytest.raises(TypeError, match="reset options must be a dict"):
            env.reset(options=options)
        env.reset(options=None)
        env.reset(options={})


def test_episode_seeds_outside_int64_are_refused_not_wrapped():
    env = DriveEnv("highway", traffic="empty")
    for seed in (2**63, 2**64 + 1, -1, 2.5, True):
        with pytest.raises(UsageError, match=r"episode_seeds must be integers in \[0, 2\*\*63\)"):
            env.reset(options={"episode_seed": seed})
    _, info = env.reset(options={"episode_seed": 2**63 - 1})
    assert info["episode_seed"] == 2**63 - 1
    vector = VectorDriveEnv(2, scenario="highway", traffic="empty")
    with pytest.raises(UsageError, match="one per world"):
        vector.reset(options={"episode_seeds": np.array([1, 2**63], dtype=np.uint64)})
