"""Tabular Q-learning: the update by hand, ε decay, callbacks, save/load, bad combinations."""

import gymnasium as gym
import numpy as np
import pytest
from gymnasium import spaces
from stable_baselines3.common.callbacks import BaseCallback

from drivelab.agents.qlearning import (
    QLearning,
    QLearningConfig,
    build_qlearning,
    load_qlearning,
    write_run_artifacts,
)
from drivelab.errors import UsageError


class Corridor(gym.Env):
    """States 0..4 in a row; action 1 moves right, 0 left; reaching 4 pays 1 and ends the episode."""

    observation_space = spaces.Discrete(5)
    action_space = spaces.Discrete(2)

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.state = 0
        return np.int64(0), {}

    def step(self, action):
        self.state = int(np.clip(self.state + (1 if int(action) == 1 else -1), 0, 4))
        done = self.state == 4
        return np.int64(self.state), float(done), done, False, {}


class StopAfter(BaseCallback):
    def __init__(self, calls):
        super().__init__()
        self.calls, self.started, self.ended, self.seen_dones = calls, False, False, 0

    def _on_training_start(self):
        self.started = True

    def _on_step(self):
        self.seen_dones += int(self.locals["dones"][0])
        return self.n_calls < self.calls

    def _on_training_end(self):
        self.ended = True


def test_update_matches_hand_computation():
    agent = QLearning(Corridor(), config=QLearningConfig(learning_rate=0.8, gamma=0.9))
    agent.q_table[3] = [2.0, 5.0]
    agent.q_table[2, 1] = 1.0
    # Q(2,1) ← 1 + 0.8 · (0.5 + 0.9 · max(2, 5) − 1) = 1 + 0.8 · 4 = 4.2
    error = agent.update(2, 1, 0.5, 3, terminal=False)
    assert error == pytest.approx(4.0) and agent.q_table[2, 1] == pytest.approx(4.2)
    # terminal: no bootstrap, Q(3,1) ← 5 + 0.8 · (1 − 5) = 1.8
    agent.update(3, 1, 1.0, 4, terminal=True)
    assert agent.q_table[3, 1] == pytest.approx(1.8)


def test_learns_corridor_and_decays_epsilon():
    agent = QLearning(Corridor(), seed=0, config=QLearningConfig(epsilon=1.0, epsilon_decay=0.99))
    agent.learn(600)
    assert agent.num_timesteps == 600
    assert agent.epsilon == pytest.approx(0.99**600)
    np.testing.assert_allclose(agent.epsilon_history()[:3], [1.0, 0.99, 0.99**2])
    assert [int(agent.predict(np.int64(s))[0]) for s in range(4)] == [1, 1, 1, 1]
    # the greedy values are γ^k of the final reward
    np.testing.assert_allclose(agent.q_table[:4, 1], [0.9**3, 0.9**2, 0.9, 1.0], atol=1e-3)


def test_callback_stops_and_counts_exactly():
    agent = QLearning(Corridor(), seed=1)
    callback = StopAfter(7)
    agent.learn(100, callback=callback)
    assert callback.started and callback.ended and agent.num_timesteps == 7
    agent.learn(5, reset_num_timesteps=False)  # SB3's meaning: 5 more steps
    assert agent.num_timesteps == 12


def test_save_load_round_trip_continues_identically(tmp_path):
    a = QLearning(Corridor(), seed=3)
    a.learn(50)
    a.save(tmp_path / "model.zip")
    b = load_qlearning("qlearning", tmp_path / "model.zip", Corridor())
    np.testing.assert_array_equal(a.q_table, b.q_table)
    assert (b.epsilon, b.num_timesteps, b.episode_returns) == (a.epsilon, a.num_timesteps, a.episode_returns)
    a._obs = None  # both start the next learn() from a reset
    a.learn(40, reset_num_timesteps=False)
    b.learn(40, reset_num_timesteps=False)
    np.testing.assert_array_equal(a.q_table, b.q_table)
    paths = write_run_artifacts(b, tmp_path)
    assert all(p.is_file() for p in paths)
    assert np.loadtxt(tmp_path / "q_table.csv", delimiter=",", skiprows=1).shape == (5, 3)


def test_bad_spaces_and_hyperparameters():
    class Pixels(Corridor):
        observation_space = spaces.Box(0, 255, (8, 8, 3), np.uint8)

    with pytest.raises(UsageError, match="qlearning needs a discrete observation"):
        build_qlearning("qlearning", Pixels(), 0, {}, None)
    with pytest.raises(UsageError, match="unknown qlearning hyperparameter"):
        build_qlearning("qlearning", Corridor(), 0, {"alpha": 0.5}, None)
    with pytest.raises(ValueError):
        QLearningConfig(learning_rate=0.0)


def test_trains_through_a_drivelab_run(tmp_path):
    """``--algo qlearning`` trains, resumes and evaluates through drivelab's run machinery."""
    from drivelab.agents.qlearning import load_qlearning as load
    from drivelab.config import build_config
    from drivelab.training.run import resume, train

    config = build_config(
        {"algo": "qlearning", "env": "follow-line", "obs": "line", "action": "seed_line",
         "reward": "line_follow", "traffic": "empty", "backend": "highway", "steps": 60, "seed": 0,
         "name": "q", "eval_every": 60, "eval_episodes": 1, "env_options": {"duration_s": 4}}
    )  # fmt: skip
    run_dir = train(config, tmp_path)
    for name in ("model.zip", "q_table.npy", "q_table.csv", "qlearning_curves.png", "evaluations.csv"):
        assert (run_dir / name).is_file(), name
    assert load("qlearning", run_dir / "model.zip", None).num_timesteps == 60
    resume(run_dir, 90)
    assert load("qlearning", run_dir / "checkpoints" / "latest.zip", None).num_timesteps == 90


def test_qlearning_on_camera_pixels_fails_before_training(tmp_path):
    from drivelab.config import build_config
    from drivelab.training.run import train

    config = build_config(
        {"algo": "qlearning", "env": "follow-line", "obs": "camera", "action": "seed_line", "steps": 10}
    )
    with pytest.raises(UsageError, match=r"^algorithm 'qlearning' needs a discrete observation \(--obs line"):
        train(config, tmp_path)
    assert not any(tmp_path.iterdir())
