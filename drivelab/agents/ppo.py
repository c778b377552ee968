"""drivelab's PPO: the clipped surrogate objective over several epochs of minibatches (Schulman et
al. 2017), on the on-policy trainer of ``onpolicy.py``. Defaults are drivelab's SB3 PPO values for
highway-env, so that the two compare one to one.
"""

from __future__ import annotations

from dataclasses import dataclass
from operator import itemgetter

import numpy as np
import torch
from torch import nn

from drivelab.agents.base import gradient_step
from drivelab.agents.onpolicy import OnPolicyAgent, OnPolicyConfig, Rollout, explained_variance
from drivelab.agents.worlds import map_obs
from drivelab.errors import UsageError


@dataclass(frozen=True)
class PPOConfig(OnPolicyConfig):
    """PPO's hyper-parameters (``-H key=value``), besides the shared ones of ``OnPolicyConfig``.

    :param batch_size: minibatch size.
    :param n_epochs: passes over each rollout.
    :param clip_range: ε of the clipped ratio.
    :param clip_range_value: clip the value change to ±this around the old value (0: no clipping).
    :param target_kl: stop the epochs early when the approximate KL exceeds 1.5 × this (0: never).
    """

    learning_rate: float = 5e-4
    n_steps: int = 256
    batch_size: int = 64
    n_epochs: int = 10
    clip_range: float = 0.2
    clip_range_value: float = 0.0
    target_kl: float = 0.0

    def check(self, algo: str) -> None:
        super().check(algo)
        if min(self.batch_size, self.n_epochs) < 1:
            raise UsageError(f"{algo!r} needs n_steps, batch_size and n_epochs >= 1")
        if self.clip_range <= 0 or self.clip_range_value < 0 or self.target_kl < 0:
            raise UsageError(f"{algo!r} needs clip_range > 0, clip_range_value >= 0 and target_kl >= 0")


def clipped_policy_loss(
    log_probs: torch.Tensor, old_log_probs: torch.Tensor, advantages: torch.Tensor, clip_range: float
) -> tuple[torch.Tensor, torch.Tensor]:
    """L^CLIP = −mean(min(r·A, clip(r, 1−ε, 1+ε)·A)), r = π/π_old (Schulman et al. 2017, eq. 7).

    Returns (loss, fraction of samples where the clipped term was the smaller one).
    """
    ratio = torch.exp(log_probs - old_log_probs)
    unclipped = ratio * advantages
    clipped = torch.clamp(ratio, 1.0 - clip_range, 1.0 + clip_range) * advantages
    clip_fraction = (clipped < unclipped).float().mean()
    return -torch.min(unclipped, clipped).mean(), clip_fraction


def value_loss(
    values: torch.Tensor, old_values: torch.Tensor, returns: torch.Tensor, clip_range_value: float
) -> torch.Tensor:
    """mean((R − V)²), or with value clipping mean(max((R − V)², (R − V_clip)²)),
    V_clip = V_old + clip(V − V_old, −ε_v, ε_v)."""
    if clip_range_value <= 0:
        return nn.functional.mse_loss(values, returns)
    clipped = old_values + torch.clamp(values - old_values, -clip_range_value, clip_range_value)
    return torch.max((returns - values) ** 2, (returns - clipped) ** 2).mean()


class OwnPPO(OnPolicyAgent):
    """Proximal policy optimisation with a clipped surrogate, from rollouts of ``n_steps`` × K."""

    config_class = PPOConfig

    def update(self, rollout: Rollout) -> dict[str, float]:
        config, policy = self.config, self.policy
        size = len(rollout.returns)
        history: dict[str, list[float]] = {
            "policy_loss": [], "value_loss": [], "entropy": [], "clip_fraction": [], "approx_kl": []
        }  # fmt: skip
        prior_kls: list[float] = []  # KL(π ‖ π_prior) with prior_kl_coef
        for _ in range(config.n_epochs):
            stop = False
            for indices in torch.randperm(size, generator=self.generator).split(config.batch_size):
                advantages = rollout.advantages[indices]
                if config.normalize_advantages and len(indices) > 1:
                    advantages = (advantages - advantages.mean()) / (advantages.std() + 1e-8)
                observations = map_obs(itemgetter(indices), rollout.observations)
                out, values = policy(observations)
                log_probs, entropy = policy.log_prob_entropy(out, rollout.actions[indices])
                old_log_probs = rollout.log_probs[indices]
                policy_loss, clip_fraction = clipped_policy_loss(
                    log_probs, old_log_probs, advantages, config.clip_range
                )
                critic_loss = value_loss(
                    values, rollout.values[indices], rollout.returns[indices], config.clip_range_value
                )
                entropy = entropy.mean()
                loss = policy_loss + config.value_coef * critic_loss - self.entropy_coef * entropy
                prior_kl = self.prior_kl(observations, out)
                if prior_kl is not None:
                    loss = loss + config.prior_kl_coef * prior_kl
                with torch.no_grad():  # KL(old‖new) ≈ mean((r − 1) − log r) (Schulman's k3 estimator)
                    log_ratio = log_probs - old_log_probs
                    approx_kl = float(((log_ratio.exp() - 1) - log_ratio).mean())
                if config.target_kl > 0 and approx_kl > 1.5 * config.target_kl:
                    stop = True
                    break
                gradient_step(self.optimizer, loss, policy.parameters(), config.max_grad_norm)
                for key, value in zip(
                    history, (policy_loss, critic_loss, entropy, clip_fraction, approx_kl), strict=True
                ):
                    history[key].append(value.item() if torch.is_tensor(value) else value)
                if prior_kl is not None:
                    prior_kls.append(prior_kl.item())
            if stop:
                break
        metrics = {key: float(np.mean(values)) for key, values in history.items() if values}
        if prior_kls:
            metrics["prior_kl"] = float(np.mean(prior_kls))
        return {**metrics, "explained_variance": explained_variance(rollout.values, rollout.returns)}
