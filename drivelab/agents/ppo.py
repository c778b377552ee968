"""Our PPO (seed 003): clipped surrogate objective, several epochs of minibatches, GAE, optional
value clipping, tanh-Gaussian policy with a trainable log-std.

The network follows the observation: seed 003's CNN on the 5×84×84 top-down image
(``--obs topdown``), its fusion network on image + ego state + LiDAR-120
(``--obs topdown,ego_state,lidar:beams=120``), or a small MLP on vectors (``networks.py``).
Defaults mirror drivelab's SB3 PPO so that the two compare one to one.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch
from torch import nn

from drivelab.agents.base import MAX_LEARNING_RATE
from drivelab.agents.rollout import OnPolicyAgent, Rollout
from drivelab.errors import UsageError


@dataclass(frozen=True)
class PPOConfig:
    """Hyper-parameters (``-H key=value``).

    :param learning_rate: Adam step size (decays linearly to 0 when ``linear_lr``).
    :param n_steps: environment steps per rollout.
    :param batch_size: minibatch size.
    :param n_epochs: passes over each rollout.
    :param gamma: discount (0.8 as drivelab's SB3 defaults for highway).
    :param gae_lambda: GAE λ.
    :param clip_range: ε of the clipped ratio.
    :param clip_range_value: clip the value change to ±this around the old value (0: no clipping).
    :param entropy_coef: weight of the entropy bonus.
    :param value_coef: weight of the value loss.
    :param max_grad_norm: gradient clipping by global norm.
    :param target_kl: stop the epochs early when the approximate KL exceeds it (0: never).
    :param shared_encoder: actor and critic share the encoder (the seed's PPO does).
    :param log_std_init: initial log σ of the Gaussian before tanh.
    :param linear_lr: linear learning-rate decay.
    """

    learning_rate: float = 5e-4
    n_steps: int = 256
    batch_size: int = 64
    n_epochs: int = 10
    gamma: float = 0.8
    gae_lambda: float = 0.95
    clip_range: float = 0.2
    clip_range_value: float = 0.0
    entropy_coef: float = 0.0
    value_coef: float = 0.5
    max_grad_norm: float = 0.5
    target_kl: float = 0.0
    shared_encoder: bool = True
    log_std_init: float = 0.0
    linear_lr: bool = False

    def check(self, algo: str) -> None:
        if min(self.n_steps, self.batch_size, self.n_epochs) < 1:
            raise UsageError(f"{algo!r} needs n_steps, batch_size and n_epochs >= 1")
        if not 0 < self.gamma <= 1 or not 0 <= self.gae_lambda <= 1 or self.clip_range <= 0:
            raise UsageError(f"{algo!r} needs 0 < gamma <= 1, 0 <= gae_lambda <= 1 and clip_range > 0")
        if not 0 < self.learning_rate <= MAX_LEARNING_RATE:
            raise UsageError(f"{algo!r} needs 0 < learning_rate <= {MAX_LEARNING_RATE:g}")
        if self.max_grad_norm <= 0 or self.clip_range_value < 0:
            raise UsageError(f"{algo!r} needs a positive max_grad_norm and clip_range_value >= 0")
        if min(self.entropy_coef, self.value_coef, self.target_kl) < 0:
            raise UsageError(f"{algo!r} needs entropy_coef, value_coef and target_kl >= 0")


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


def minibatch(observations, indices: torch.Tensor):
    """Rows ``indices`` of a tensor or of every tensor of a dict."""
    if isinstance(observations, dict):
        return {key: value[indices] for key, value in observations.items()}
    return observations[indices]


class OwnPPO(OnPolicyAgent):
    """Proximal policy optimisation with a clipped surrogate, from rollouts of ``n_steps``."""

    config_class = PPOConfig

    def update(self, rollout: Rollout) -> dict[str, float]:
        config = self.config
        size = len(rollout.returns)
        history: dict[str, list[float]] = {
            "policy_loss": [], "value_loss": [], "entropy": [], "clip_fraction": [], "approx_kl": []
        }  # fmt: skip
        for _ in range(config.n_epochs):
            stop = False
            for indices in torch.randperm(size, generator=self.generator).split(config.batch_size):
                advantages = rollout.advantages[indices]
                if len(indices) > 1:  # per-minibatch standardisation, as SB3
                    advantages = (advantages - advantages.mean()) / (advantages.std() + 1e-8)
                log_probs, entropy, values = self.policy.evaluate(
                    minibatch(rollout.observations, indices), rollout.unsquashed_actions[indices]
                )
                old_log_probs = rollout.log_probs[indices]
                policy_loss, clip_fraction = clipped_policy_loss(
                    log_probs, old_log_probs, advantages, config.clip_range
                )
                critic_loss = value_loss(
                    values, rollout.values[indices], rollout.returns[indices], config.clip_range_value
                )
                loss = policy_loss + config.value_coef * critic_loss - config.entropy_coef * entropy.mean()
                with torch.no_grad():  # KL(old‖new) ≈ mean((r − 1) − log r) (Schulman's k3 estimator)
                    log_ratio = log_probs - old_log_probs
                    approx_kl = float(((log_ratio.exp() - 1) - log_ratio).mean())
                if config.target_kl > 0 and approx_kl > 1.5 * config.target_kl:
                    stop = True
                    break
                self.optimizer.zero_grad()
                loss.backward()
                nn.utils.clip_grad_norm_(self.policy.parameters(), config.max_grad_norm)
                self.optimizer.step()
                for key, value in zip(
                    history, (policy_loss, critic_loss, entropy.mean(), clip_fraction, approx_kl), strict=True
                ):
                    history[key].append(value.item() if torch.is_tensor(value) else value)
            if stop:
                break
        metrics = {key: float(np.mean(values)) for key, values in history.items() if values}
        variance = float(rollout.returns.var()) if size > 1 else 0.0
        explained = 1.0 - float((rollout.returns - rollout.values).var()) / variance if variance > 0 else 0.0
        return {**metrics, "explained_variance": explained}
