"""drivelab's A2C: one gradient step of the advantage-weighted log-likelihood per rollout (Mnih et
al. 2016), on the on-policy trainer of ``onpolicy.py`` (collect loop, GAE, networks, normalisation).

The MetaDrive study: "a critic loss based on mean squared error between predicted and actual returns, and
an actor loss that maximizes the probability of good actions using advantage-weighted
log-probabilities ... advantage values computed using Generalized Advantage Estimation".
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
from torch import nn

from drivelab.agents.base import gradient_step
from drivelab.agents.onpolicy import OnPolicyAgent, OnPolicyConfig, Rollout, explained_variance


@dataclass(frozen=True)
class A2CConfig(OnPolicyConfig):
    """A2C's defaults of the shared hyper-parameters (``OnPolicyConfig``): SB3 A2C's (learning rate
    7e-4, n-step returns with gae_lambda 1, entropy 0.01, raw advantages), rollouts of 16 steps,
    an encoder each for actor and critic."""

    learning_rate: float = 7e-4
    n_steps: int = 16
    gae_lambda: float = 1.0
    entropy_coef: float = 0.01
    normalize_advantages: bool = False
    # the MetaDrive study's A2C: "convolutional layers in both the actor and critic"
    shared_encoder: bool = False


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
    """Synchronous advantage actor-critic: one gradient step per rollout of ``n_steps`` × K."""

    config_class = A2CConfig

    def update(self, rollout: Rollout) -> dict[str, float]:
        config, policy = self.config, self.policy
        advantages = rollout.advantages
        if config.normalize_advantages and len(advantages) > 1:
            advantages = (advantages - advantages.mean()) / (advantages.std() + 1e-8)
        out, values = policy(rollout.observations)
        log_probs, entropy = policy.log_prob_entropy(out, rollout.actions)
        loss, metrics = a2c_loss(
            log_probs, advantages, values, rollout.returns, entropy, config.value_coef, self.entropy_coef
        )
        prior_kl = self.prior_kl(rollout.observations, out)
        if prior_kl is not None:
            loss = loss + config.prior_kl_coef * prior_kl
            metrics["prior_kl"] = prior_kl.item()
        gradient_step(self.optimizer, loss, policy.parameters(), config.max_grad_norm)
        return {**metrics, "explained_variance": explained_variance(rollout.values, rollout.returns)}
