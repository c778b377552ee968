"""The actor-critic of drivelab's on-policy trainer: an encoder (``networks.py``), an action
distribution (``categorical``, ``tanh_gaussian`` or ``beta``), a value head, and the running
statistics that normalise its input. A rollout stores the distribution's own variable (the class
index, the pre-tanh u, the Beta's x in (0, 1)), so that log π is computed again without inverting.
"""

from __future__ import annotations

import numpy as np
import torch
from gymnasium import spaces
from torch import nn

from drivelab.agents.networks import EgoAttentionEncoder, make_encoder, squashed_log_prob

DISTRIBUTIONS = ("auto", "categorical", "tanh_gaussian", "beta")
BETA_ACTIONS = ("mode", "mean")  # a Beta policy's deterministic action
BETA_EPSILON = 1e-6  # a Beta sample is kept inside (ε, 1 − ε), where its log-density is finite
NORM_CLIP = 10.0  # normalised observations and rewards are clipped to ±this (SB3 VecNormalize's)
NORM_EPSILON = 1e-8


def beta_mode(alpha: torch.Tensor, beta: torch.Tensor) -> torch.Tensor:
    """The most likely x of Beta(α, β) for α, β ≥ 1 (the head's ``1 + softplus``): (α − 1) / (α + β − 2),
    which reaches 0 and 1 where α or β is 1, unlike the mean α / (α + β); ½ for the uniform α = β = 1."""
    excess = alpha + beta - 2.0
    return torch.where(excess > 0, (alpha - 1.0) / excess.clamp(min=torch.finfo(excess.dtype).tiny), 0.5)


def distribution_of(action_space: spaces.Space, distribution: str) -> str:
    """The distribution an action space gets: ``categorical`` for Discrete, the given one (or
    ``tanh_gaussian`` for "auto") for Box; a ValueError for a combination that cannot be."""
    if isinstance(action_space, spaces.Discrete):
        if distribution not in ("auto", "categorical"):
            raise ValueError(f"discrete actions take the categorical distribution, not {distribution!r}")
        return "categorical"
    if isinstance(action_space, spaces.Box) and len(action_space.shape) == 1:
        if distribution == "categorical":
            raise ValueError("continuous actions take distribution tanh_gaussian or beta, not 'categorical'")
        if not (np.all(np.isfinite(action_space.low)) and np.all(np.isfinite(action_space.high))):
            raise ValueError("continuous actions need finite bounds")
        return "tanh_gaussian" if distribution == "auto" else distribution
    raise ValueError(f"no action distribution for {action_space}")


class RunningNorm(nn.Module):
    """Running mean and variance of each float observation part (Chan et al.'s parallel update),
    applied as clip((x − mean) / sqrt(var + ε), ±10); uint8 images are scaled to [0, 1] instead.

    :param space: the observation space (Box or Dict).
    :param enabled: normalise the float parts (else only images are scaled).
    """

    def __init__(self, space: spaces.Space, enabled: bool) -> None:
        super().__init__()
        parts = space.spaces if isinstance(space, spaces.Dict) else {"": space}
        self.keys = list(parts) if isinstance(space, spaces.Dict) else None
        self.images = {key for key, sub in parts.items() if sub.dtype == np.uint8}
        self.normalised = [key for key in parts if key not in self.images] if enabled else []
        for key in self.normalised:
            shape = parts[key].shape
            self.register_buffer(_name("mean", key), torch.zeros(shape, dtype=torch.float64))
            self.register_buffer(_name("var", key), torch.ones(shape, dtype=torch.float64))
        self.register_buffer("count", torch.zeros((), dtype=torch.float64))

    def forward(self, obs):
        """Float tensors (B, ...) ready for the encoder, from stored observations of any dtype."""
        if self.keys is None:
            return self._one(obs, "")
        return {key: self._one(obs[key], key) for key in self.keys}

    def _one(self, value: torch.Tensor, key: str) -> torch.Tensor:
        if key in self.images:
            return value.float() / 255.0
        value = value.float()
        if key not in self.normalised or self.count <= 0:
            return value
        mean, var = getattr(self, _name("mean", key)), getattr(self, _name("var", key))
        scaled = (value - mean.float()) / torch.sqrt(var.float() + NORM_EPSILON)
        return scaled.clamp(-NORM_CLIP, NORM_CLIP)

    @torch.no_grad()
    def update(self, obs) -> None:
        """Merge a batch (N, ...) of raw observations into the statistics."""
        if not self.normalised:
            return
        count = None
        for key in self.normalised:
            mean, var = getattr(self, _name("mean", key)), getattr(self, _name("var", key))
            batch = (obs if self.keys is None else obs[key]).double().reshape(-1, *mean.shape)
            count = batch.shape[0]
            merged_mean, merged_var = merge_moments(
                mean, var, self.count, batch.mean(0), batch.var(0, unbiased=False), count
            )
            mean.copy_(merged_mean)
            var.copy_(merged_var)
        self.count += count


def merge_moments(mean, var, count, batch_mean, batch_var, batch_count):
    """(mean, variance) of two samples merged from each one's mean, variance and size (Chan et
    al.'s parallel update; numbers or tensors)."""
    total = count + batch_count
    delta = batch_mean - mean
    merged_var = (var * count + batch_var * batch_count + delta**2 * count * batch_count / total) / total
    return mean + delta * batch_count / total, merged_var


def _encode(encoder: nn.Module, normed, raw) -> torch.Tensor:
    """An encoder's features; the attention encoder also reads the raw rows for its mask."""
    return encoder(normed, raw) if isinstance(encoder, EgoAttentionEncoder) else encoder(normed)


def _name(kind: str, key: str) -> str:
    return f"{kind}_{key}" if key else kind


class ActorCritic(nn.Module):
    """π(a|s) and V(s) over one of ``networks.make_encoder``'s encoders.

    :param space: the observation space.
    :param action_space: Discrete or a 1-D Box with finite bounds.
    :param distribution: "auto", "categorical", "tanh_gaussian" or "beta" (``distribution_of``).
    :param shared_encoder: one encoder for actor and critic, or one each.
    :param log_std_init: initial log σ of the tanh-Gaussian.
    :param hidden: widths of the MLP encoder's layers (vector observations), or of the attention
        encoder's embeddings.
    :param encoder: "auto" (the observation's encoder: ``networks.make_encoder``) or "attention"
        (``networks.EgoAttentionEncoder`` over the kinematics rows).
    :param normalize_observations: keep running statistics of the float observations and
        normalise with them.
    :param attention_output: widths of the ReLU layers after the attention encoder's features
        (rl-agents' output layer; empty: none).
    :param beta_action: a Beta policy's deterministic action: its "mode" (Roach's, which reaches
        the ends of the range) or its "mean" (inside the range, and steadier while the Beta is wide).
    """

    def __init__(
        self,
        space: spaces.Space,
        action_space: spaces.Space,
        distribution: str = "auto",
        shared_encoder: bool = True,
        log_std_init: float = 0.0,
        hidden: tuple[int, ...] = (64, 64),
        normalize_observations: bool = False,
        encoder: str = "auto",
        beta_action: str = "mode",
        attention_output: tuple[int, ...] = (),
    ) -> None:
        super().__init__()
        if beta_action not in BETA_ACTIONS:
            raise ValueError(f"beta_action must be one of {', '.join(BETA_ACTIONS)}, got {beta_action!r}")
        self.kind = distribution_of(action_space, distribution)
        self.beta_action = beta_action
        self.norm = RunningNorm(space, normalize_observations)
        if attention_output and encoder != "attention":
            raise ValueError("attention_output needs encoder attention")
        self.actor_encoder = make_encoder(space, hidden, encoder, attention_output)
        self.critic_encoder = (
            self.actor_encoder if shared_encoder else make_encoder(space, hidden, encoder, attention_output)
        )
        if self.kind == "categorical":
            outputs = int(action_space.n)
        else:
            size = action_space.shape[0]
            outputs = 2 * size if self.kind == "beta" else size
            low = torch.as_tensor(action_space.low, dtype=torch.float32)
            high = torch.as_tensor(action_space.high, dtype=torch.float32)
            self.register_buffer("low", low, persistent=False)
            self.register_buffer("span", high - low, persistent=False)
            self.register_buffer("high", high, persistent=False)
        self.head = nn.Linear(self.actor_encoder.features, outputs)
        if self.kind == "tanh_gaussian":
            self.log_std = nn.Parameter(torch.full((outputs,), float(log_std_init)))
        self.value = nn.Linear(self.critic_encoder.features, 1)
        nn.init.orthogonal_(self.head.weight, gain=0.01)  # start near the uniform / zero action
        nn.init.zeros_(self.head.bias)

    def load_state_dict(self, state_dict, strict: bool = True, assign: bool = False):
        """Also weights saved before this class by the tanh-Gaussian networks (``mean`` for
        ``head``, no input statistics), such as behaviour cloning's ``TanhGaussianActorCritic``."""
        state_dict = dict(state_dict)
        for suffix in ("weight", "bias"):
            if f"mean.{suffix}" in state_dict and f"head.{suffix}" not in state_dict:
                state_dict[f"head.{suffix}"] = state_dict.pop(f"mean.{suffix}")
        state_dict.setdefault("norm.count", torch.zeros((), dtype=torch.float64))
        return super().load_state_dict(state_dict, strict, assign)

    def forward(self, obs) -> tuple[torch.Tensor, torch.Tensor]:
        """(the head's output, V) for a batch of stored observations."""
        normed = self.norm(obs)
        features = _encode(self.actor_encoder, normed, obs)
        value = self.value(features if self.shared else _encode(self.critic_encoder, normed, obs))
        return self.head(features), value.squeeze(-1)

    def values(self, obs, freeze_shared: bool = False) -> torch.Tensor:
        """V alone (the critic's encoder only, when it has its own); ``freeze_shared``: an encoder
        shared with the actor gets no gradient from it (the critic's warm-up)."""
        normed = self.norm(obs)
        with torch.set_grad_enabled(torch.is_grad_enabled() and not (freeze_shared and self.shared)):
            features = _encode(self.critic_encoder, normed, obs)
        return self.value(features).squeeze(-1)

    @property
    def shared(self) -> bool:
        """Actor and critic read one encoder."""
        return self.critic_encoder is self.actor_encoder

    # --- the distributions ----------------------------------------------------------------------
    def _beta(self, out: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        return (1.0 + nn.functional.softplus(out)).chunk(2, dim=-1)

    def sample(
        self, out: torch.Tensor, deterministic: bool, generator: torch.Generator, rng: np.random.Generator
    ) -> torch.Tensor:
        """The distribution's variable for a batch of head outputs: drawn (from ``generator``, or
        ``rng`` for the Beta, which torch samples without a generator), or the mode (categorical),
        μ (Gaussian) or the Beta's ``beta_action`` when ``deterministic``: nothing is drawn then."""
        if self.kind == "categorical":
            if deterministic:
                return out.argmax(-1)
            uniform = torch.rand(out.shape, generator=generator).clamp_(min=1e-20)
            return (out - torch.log(-torch.log(uniform))).argmax(-1)  # Gumbel-max: a draw of softmax(out)
        if self.kind == "tanh_gaussian":
            if deterministic:
                return out
            return out + self.log_std.exp() * torch.randn(out.shape, generator=generator)
        alpha, beta = self._beta(out)
        if deterministic:
            x = beta_mode(alpha, beta) if self.beta_action == "mode" else alpha / (alpha + beta)
        else:
            x = torch.from_numpy(rng.beta(alpha.double().numpy(), beta.double().numpy())).float()
        return x.clamp(BETA_EPSILON, 1.0 - BETA_EPSILON)

    def distribution(self, out: torch.Tensor) -> torch.distributions.Distribution:
        """π(·|s) for a batch of head outputs: the Gaussian before the tanh, the Beta, or the
        categorical."""
        if self.kind == "categorical":
            return torch.distributions.Categorical(logits=out)
        if self.kind == "tanh_gaussian":
            return torch.distributions.Normal(out, self.log_std.exp().expand_as(out))
        return torch.distributions.Beta(*self._beta(out))

    def kl_to(self, out: torch.Tensor, other: ActorCritic, other_out: torch.Tensor) -> torch.Tensor:
        """KL(π ‖ π_other) per row, from each one's head outputs for the same observations (the
        tanh is a bijection, so the Gaussians' KL before it is the policies')."""
        kl = torch.distributions.kl_divergence(self.distribution(out), other.distribution(other_out))
        return kl if self.kind == "categorical" else kl.sum(-1)

    def log_prob_entropy(
        self, out: torch.Tensor, stored: torch.Tensor, entropy: bool = True
    ) -> tuple[torch.Tensor, torch.Tensor | None]:
        """(log π of stored variables, entropy, or None without ``entropy``) per row; the
        Gaussian's entropy is before squashing."""
        if self.kind == "categorical":
            log_softmax = out.log_softmax(-1)
            log_prob = log_softmax.gather(-1, stored.long().unsqueeze(-1)).squeeze(-1)
            return log_prob, -(log_softmax.exp() * log_softmax).sum(-1) if entropy else None
        if self.kind == "tanh_gaussian":
            distribution = torch.distributions.Normal(out, self.log_std.exp().expand_as(out))
            log_prob = squashed_log_prob(distribution, stored)
        else:
            distribution = torch.distributions.Beta(*self._beta(out))
            log_prob = distribution.log_prob(stored).sum(-1)
        return log_prob, distribution.entropy().sum(-1) if entropy else None

    def to_env(self, stored: torch.Tensor) -> np.ndarray:
        """The environment's actions for stored variables: class indices, or Box values in bounds."""
        if self.kind == "categorical":
            return stored.numpy()
        if self.kind == "tanh_gaussian":  # tanh(u) clipped into the box, as behaviour cloning acts
            return torch.clamp(torch.tanh(stored), self.low, self.high).numpy()
        return (self.low + stored * self.span).numpy()

    def stored_shape(self) -> tuple[int, ...]:
        """The shape of one stored variable: () for a class, (action size,) for a Box."""
        return () if self.kind == "categorical" else (self.span.shape[0],)

    def std(self) -> float:
        """The tanh-Gaussian's mean σ."""
        return self.log_std.exp().mean().item()
