"""Dueling Double DQN pieces with known answers: sum tree, prioritised replay, dueling head, targets."""

import gymnasium as gym
import numpy as np
import pytest
import torch
from gymnasium import spaces

from drivelab.agents.dueling_ddqn import (
    DuelingDoubleDQN,
    DuelingQNetwork,
    PrioritizedReplayBuffer,
    SumTree,
    double_dqn_targets,
    dueling_q_values,
    linear,
)


def test_sum_tree_totals_follow_updates():
    tree = SumTree(5)
    tree.update(np.arange(5), np.array([1.0, 2.0, 3.0, 4.0, 5.0]))
    assert tree.total == pytest.approx(15.0)
    tree.update(np.array([2]), np.array([0.5]))
    assert tree.total == pytest.approx(12.5)
    assert tree.priorities(np.array([0, 2, 4])).tolist() == [1.0, 0.5, 5.0]


def test_sum_tree_find_maps_cumulative_values_to_leaves():
    tree = SumTree(4)
    tree.update(np.arange(4), np.array([1.0, 2.0, 3.0, 4.0]))  # cumulative edges 1, 3, 6, 10
    values = np.array([0.0, 0.99, 1.0, 2.99, 3.0, 5.99, 6.0, 9.99])
    assert tree.find(values).tolist() == [0, 0, 1, 1, 2, 2, 3, 3]


def test_sampling_is_proportional_to_priority():
    tree = SumTree(3)
    tree.update(np.arange(3), np.array([1.0, 3.0, 6.0]))
    rng = np.random.default_rng(0)
    leaves = tree.find(rng.random(100_000) * tree.total)
    frequencies = np.bincount(leaves, minlength=3) / len(leaves)
    np.testing.assert_allclose(frequencies, [0.1, 0.3, 0.6], atol=0.01)
    assert tree.find(np.array([9.999999])).tolist() == [2]  # never an empty padding leaf


def _add(buffer, observation, action, reward, next_observation, terminal):
    """One transition (the agent adds its K worlds' with ``add_many``)."""
    buffer.add_many(
        np.asarray(observation)[None], np.array([action]), np.array([reward]),
        np.asarray(next_observation)[None], np.array([terminal]),
    )  # fmt: skip


def _buffer(priorities, alpha=1.0):
    buffer = PrioritizedReplayBuffer(8, observation_size=2, alpha=alpha, priority_eps=0.0)
    for i in range(len(priorities)):
        _add(buffer, np.full(2, i), i, float(i), np.full(2, i + 1), False)
    buffer.update_priorities(np.arange(len(priorities)), np.array(priorities, dtype=float))
    return buffer


def test_priorities_are_td_errors_to_the_alpha():
    buffer = _buffer([1.0, -3.0], alpha=0.5)
    np.testing.assert_allclose(buffer.tree.priorities(np.array([0, 1])), [1.0, np.sqrt(3.0)])


@pytest.mark.parametrize("beta, expected", [(1.0, [1.0, 0.5]), (0.5, [1.0, np.sqrt(0.5)]), (0.0, [1.0, 1.0])])
def test_importance_weights(beta, expected):
    # priorities 1, 1, 2 (total 4), a batch of 2: one draw in [0, 2) (leaf 0 or 1), one in [2, 4) (leaf 2);
    # P = 1/4, 1/4, 1/2, N = 3: w = (N P)^-β = (3/4)^-β, (3/2)^-β, normalised by the largest
    buffer = _buffer([1.0, 1.0, 2.0])
    rng = np.random.default_rng(1)
    for _ in range(20):
        indices, batch, weights = buffer.sample(2, beta, rng)
        assert indices[1] == 2 and indices[0] in (0, 1)
        np.testing.assert_allclose(weights, expected, rtol=1e-6)
        np.testing.assert_array_equal(batch["actions"], indices)
        np.testing.assert_array_equal(batch["next_observations"][:, 0], indices + 1)


def test_new_transitions_get_the_largest_priority():
    buffer = _buffer([1.0, 5.0])
    _add(buffer, np.zeros(2), 0, 0.0, np.zeros(2), True)
    assert buffer.tree.priorities(np.array([2]))[0] == pytest.approx(5.0)
    assert buffer.size == 3 and buffer.terminals[2] == 1.0


def test_ring_buffer_overwrites_the_oldest():
    buffer = PrioritizedReplayBuffer(3, observation_size=1, alpha=0.6, priority_eps=1e-6)
    for i in range(5):
        _add(buffer, np.array([i]), 0, 0.0, np.array([i]), False)
    assert buffer.size == 3 and sorted(buffer.observations[:, 0].tolist()) == [2.0, 3.0, 4.0]


def test_dueling_aggregation():
    value = torch.tensor([[1.0], [2.0]])
    advantage = torch.tensor([[1.0, 2.0, 3.0], [0.0, 0.0, 3.0]])
    q = dueling_q_values(value, advantage)
    np.testing.assert_allclose(q.numpy(), [[0.0, 1.0, 2.0], [1.0, 1.0, 4.0]])
    np.testing.assert_allclose(q.mean(dim=1).numpy(), [1.0, 2.0])  # mean_a Q = V


def test_double_dqn_target_uses_online_argmax_and_target_values():
    rewards, terminals = torch.tensor([1.0, 0.5]), torch.tensor([0.0, 1.0])
    next_q_online = torch.tensor([[3.0, 1.0], [5.0, 2.0]])  # picks action 0 in both rows
    next_q_target = torch.tensor([[10.0, 20.0], [30.0, 40.0]])
    targets = double_dqn_targets(rewards, terminals, next_q_online, next_q_target, gamma=0.9)
    # row 0: 1 + 0.9 * Q_target(s', 0) = 10 (vanilla DQN's max would give 19); row 1 is terminal
    np.testing.assert_allclose(targets.numpy(), [10.0, 0.5])


def test_network_shapes_match_the_seed():
    network = DuelingQNetwork(750, 18)
    sizes = [m.out_features for m in network.features if isinstance(m, torch.nn.Linear)]
    assert sizes == [512, 512, 256]
    assert [m.out_features for m in network.value if isinstance(m, torch.nn.Linear)] == [256, 128, 1]
    assert [m.out_features for m in network.advantage if isinstance(m, torch.nn.Linear)] == [256, 128, 18]
    assert any(isinstance(m, torch.nn.BatchNorm1d) for m in network.value)
    assert network(torch.zeros(4, 750)).shape == (4, 18)


def test_linear_schedule():
    assert linear(1.0, 0.05, 0.0) == 1.0
    assert linear(1.0, 0.0, 0.25) == pytest.approx(0.75)
    assert linear(1.0, 0.05, 3.0) == pytest.approx(0.05)


class Counter(gym.Env):
    """The observation is [step of the episode, episode]: odd episodes terminate at step 3, the
    others are truncated at step 5."""

    observation_space = spaces.Box(-np.inf, np.inf, (2,), np.float32)
    action_space = spaces.Discrete(2)

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.episode, self.t = getattr(self, "episode", -1) + 1, 0
        return np.array([0, self.episode], np.float32), {}

    def step(self, action):
        self.t += 1
        odd = self.episode % 2 == 1
        observation = np.array([self.t, self.episode], np.float32)
        return observation, 0.0, odd and self.t == 3, not odd and self.t == 5, {}


def test_replay_transitions_across_episode_ends():
    """Each stored transition is (s, s') of one episode: an ended episode's s' is its final
    observation, and the next transition starts from the new episode's first one (a float32 Box
    observation, whose flattening is a view of the env's array)."""
    env = Counter()
    agent = DuelingDoubleDQN(env.observation_space, env.action_space, 0, {"learning_starts": 1000}, env)
    agent.learn(14)
    replay = agent.replay_buffer
    expected = [(t, e, t + 1, e, float(e % 2 == 1 and t == 2)) for e, ends in ((0, 5), (1, 3), (2, 5), (3, 1))
                for t in range(ends)]  # fmt: skip
    stored = np.c_[replay.observations[:14], replay.next_observations[:14], replay.terminals[:14]]
    assert stored.tolist() == [list(row) for row in expected]
