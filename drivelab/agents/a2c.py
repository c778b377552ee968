"""Our A2C (seed 003): CNN actor and critic on the 5×84×84 top-down image, continuous actions.

Read top to bottom: the config (defaults mirror drivelab's SB3 A2C so that the two compare one
to one), the loss, the agent. Rollouts, GAE and the tanh-Gaussian policy are in ``rollout.py``
and ``networks.py``, shared with our PPO.

Seed 003: "a critic loss based on mean squared error between predicted and actual returns, and
an actor loss that maximizes the probability of good actions using advantage-weighted
log-probabilities ... advantage values computed using Generalized Advantage Estimation".
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
from torch import nn

from drivelab.agents.base import MAX_LEARNING_RATE
from drivelab.agents.rollout import OnPolicyAgent, Rollout
from drivelab.errors import UsageError


@dataclass(frozen=True)
class A2CConfig:
    """Hyper-parameters (``-H key=value``).

    :param learning_rate: Adam step size (decays linearly to 0 when ``linear_lr``).
    :param n_steps: environment steps per update.
    :param gamma: discount (0.8 as drivelab's SB3 defaults for highway).
    :param gae_lambda: GAE λ (1.0 gives plain n-step returns, SB3 A2C's default).
    :param entropy_coef: weight of the entropy bonus.
    :param value_coef: weight of the critic's squared error.
    :param max_grad_norm: gradient clipping by global norm.
    :param normalize_advantages: standardise advantages per batch.
    :param shared_encoder: one CNN for actor and critic (the seed gives each its own).
    :param log_std_init: initial log σ of the Gaussian before tanh.
    :param linear_lr: linear learning-rate decay.
    """

    learning_rate: float = 7e-4
    n_steps: int = 16
    gamma: float = 0.8
    gae_lambda: float = 1.0
    entropy_coef: float = 0.01
    value_coef: float = 0.5
    max_grad_norm: float = 0.5
    normalize_advantages: bool = False
    shared_encoder: bool = False
    log_std_init: float = 0.0
    linear_lr: bool = False

    def check(self, algo: str) -> None:
        if self.n_steps < 1 or not 0 < self.gamma <= 1 or not 0 <= self.gae_lambda <= 1:
            raise UsageError(f"{algo!r} needs n_steps >= 1, 0 < gamma <= 1 and 0 <= gae_lambda <= 1")
        if not 0 < self.learning_rate <= MAX_LEARNING_RATE or self.max_grad_norm <= 0:
            raise UsageError(
                f"{algo!r} needs 0 < learning_rate <= {MAX_LEARNING_RATE:g} and max_grad_norm > 0"
            )
        if self.entropy_coef < 0 or self.value_coef < 0:
            raise UsageError(f"{algo!r} needs entropy_coef >= 0 and value_coef >= 0")


def a2c_loss(
    log_probs: torch.Tensor,
    advantages: torch.Tensor,
    values: torch.Tensor,
    returns: torch.Tensor,
    entropy: torch.Tensor,
    value_coef: float,
    entropy_coef: float,
) -> tuple[torch.Tensor, dict[str, float]]:
    """L = −mean(A·log π(a|s)) + c_v·mean((R − V)²) − c_e·mean(H): advantage-weighted log-probs,
    MSE critic, entropy bonus (Mnih et al. 2016)."""
    policy_loss = -(advantages.detach() * log_probs).mean()
    value_loss = nn.functional.mse_loss(values, returns)
    entropy_mean = entropy.mean()
    loss = policy_loss + value_coef * value_loss - entropy_coef * entropy_mean
    metrics = {
        "policy_loss": policy_loss.item(),
        "value_loss": value_loss.item(),
        "entropy": entropy_mean.item(),
        "loss": loss.item(),
    }
    return loss, metrics


class OwnA2C(OnPolicyAgent):
    """Synchronous advantage actor-critic: one gradient step per rollout of ``n_steps``."""

    config_class = A2CConfig

    def update(self, rollout: Rollout) -> dict[str, float]:
        config = self.config
        advantages = rollout.advantages
        if config.normalize_advantages and len(advantages) > 1:
            advantages = (advantages - advantages.mean()) / (advantages.std() + 1e-8)
        log_probs, entropy, values = self.policy.evaluate(rollout.observations, rollout.unsquashed_actions)
        loss, metrics = a2c_loss(
            log_probs, advantages, values, rollout.returns, entropy, config.value_coef, config.entropy_coef
        )
        self.optimizer.zero_grad()
        loss.backward()
        nn.utils.clip_grad_norm_(self.policy.parameters(), config.max_grad_norm)
        self.optimizer.step()
        return metrics
