"""GAE, the tanh-Gaussian log-probability, A2C's and PPO's losses against hand computations."""

import math

import numpy as np
import pytest
import torch

from drivelab.agents.a2c import a2c_loss
from drivelab.agents.networks import squashed_log_prob
from drivelab.agents.onpolicy import compute_gae
from drivelab.agents.ppo import clipped_policy_loss, value_loss


def test_gae_against_a_hand_computation():
    rewards = np.array([1.0, 2.0, 3.0])
    values = np.array([0.5, 1.0, 1.5])
    ends = np.array([0.0, 1.0, 0.0])  # the episode ends after step 1
    advantages, returns = compute_gae(rewards, values, ends, last_value=2.0, gamma=0.9, gae_lambda=0.8)
    # t=2: δ = 3 + 0.9·2 − 1.5 = 3.3;  t=1: δ = 2 − 1 = 1 (end: no bootstrap, no carry);
    # t=0: δ = 1 + 0.9·1 − 0.5 = 1.4, A = 1.4 + 0.9·0.8·1 = 2.12
    np.testing.assert_allclose(advantages, [2.12, 1.0, 3.3], rtol=1e-6)
    np.testing.assert_allclose(returns, [2.62, 2.0, 4.8], rtol=1e-6)


def test_gae_with_lambda_one_is_the_discounted_return_minus_value():
    rewards, values = np.array([1.0, 1.0, 1.0]), np.array([0.2, 0.4, 0.6])
    advantages, returns = compute_gae(rewards, values, np.zeros(3), last_value=1.0, gamma=0.5, gae_lambda=1.0)
    np.testing.assert_allclose(returns, [1 + 0.5 + 0.25 + 0.125, 1 + 0.5 + 0.25, 1 + 0.5], rtol=1e-6)
    np.testing.assert_allclose(advantages, returns - values, rtol=1e-6)


def test_squashed_log_prob_matches_the_change_of_variables():
    mean, std = torch.tensor([[0.3, -1.0]]), torch.tensor([[0.5, 2.0]])
    unsquashed = torch.tensor([[1.2, -0.4]])
    normal = torch.distributions.Normal(mean, std)
    expected = (normal.log_prob(unsquashed) - torch.log(1 - torch.tanh(unsquashed) ** 2)).sum(-1)
    torch.testing.assert_close(squashed_log_prob(normal, unsquashed), expected)


@pytest.mark.parametrize(
    "ratio, advantage, expected_loss, clipped",
    [
        (1.1, 2.0, -2.2, False),  # inside [0.8, 1.2]: the plain surrogate r·A
        (1.5, 2.0, -2.4, True),  # above 1 + ε with A > 0: capped at 1.2·A
        (0.5, 2.0, -1.0, False),  # below 1 − ε with A > 0: min keeps the worse, unclipped r·A
        (0.5, -2.0, 1.6, True),  # below 1 − ε with A < 0: capped at 0.8·A
        (1.5, -2.0, 3.0, False),  # above 1 + ε with A < 0: unclipped r·A is the worse
    ],
)
def test_ppo_clipped_loss(ratio, advantage, expected_loss, clipped):
    old = torch.tensor([-1.0])
    new = old + math.log(ratio)
    loss, clip_fraction = clipped_policy_loss(new, old, torch.tensor([advantage]), clip_range=0.2)
    assert float(loss) == pytest.approx(expected_loss, rel=1e-5)
    assert float(clip_fraction) == float(clipped)


def test_value_clipping():
    values, old, returns = torch.tensor([2.0]), torch.tensor([1.0]), torch.tensor([3.0])
    assert float(value_loss(values, old, returns, 0.0)) == pytest.approx(1.0)
    # clipped value 1 + 0.5 = 1.5: max((3 − 2)², (3 − 1.5)²) = 2.25
    assert float(value_loss(values, old, returns, 0.5)) == pytest.approx(2.25)


def test_a2c_loss():
    loss, metrics = a2c_loss(
        log_probs=torch.tensor([-1.0, -2.0]),
        advantages=torch.tensor([1.0, -1.0]),
        values=torch.tensor([0.0, 1.0]),
        returns=torch.tensor([1.0, 1.0]),
        entropy=torch.tensor([0.5, 0.5]),
        value_coef=0.5,
        entropy_coef=0.1,
    )
    # policy −mean(A·logπ) = −mean(−1, 2) = −0.5; value mean((R−V)²) = 0.5; total −0.5 + 0.25 − 0.05
    assert metrics["policy_loss"] == pytest.approx(-0.5)
    assert metrics["value_loss"] == pytest.approx(0.5)
    assert float(loss) == pytest.approx(-0.3)


def test_gae_over_k_worlds_is_each_world_on_its_own():
    rng = np.random.default_rng(5)
    steps, worlds = 12, 4
    rewards, values = rng.normal(size=(steps, worlds)), rng.normal(size=(steps, worlds)).astype(np.float32)
    ends = (rng.random((steps, worlds)) < 0.2).astype(float)
    last = rng.normal(size=worlds)
    advantages, returns = compute_gae(rewards, values, ends, last, 0.9, 0.95)
    assert advantages.shape == returns.shape == (steps, worlds)
    for k in range(worlds):
        alone = compute_gae(rewards[:, k], values[:, k], ends[:, k], float(last[k]), 0.9, 0.95)
        np.testing.assert_array_equal(advantages[:, k], alone[0])
        np.testing.assert_array_equal(returns[:, k], alone[1])
