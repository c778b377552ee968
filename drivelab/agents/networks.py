"""The MetaDrive study's encoders (CNN and fusion), the MLP, an ego-attention encoder for sets of
vehicles, the tanh-Gaussian actor-critic, and SB3 features extractors of the study's encoders
(``-H features_extractor=seed``)."""

from __future__ import annotations

import math

import numpy as np
import torch
from gymnasium import spaces
from stable_baselines3.common.torch_layers import BaseFeaturesExtractor
from torch import nn


def is_image(space: spaces.Space) -> bool:
    """A channels-first uint8 image Box (``topdown``; the RGB ``birdeye`` is channels-last)."""
    if not (isinstance(space, spaces.Box) and len(space.shape) == 3 and space.dtype.name == "uint8"):
        return False
    channels, height, width = space.shape
    return channels < min(height, width)


def is_vector(space: spaces.Space) -> bool:
    """A 1-D Box or a floating-point Box of any shape (``waypoints``' (10, 2): the encoders flatten
    it), or a Dict of them."""
    if isinstance(space, spaces.Dict):
        return all(is_vector(sub) for sub in space.spaces.values())
    if not isinstance(space, spaces.Box) or len(space.shape) == 0:
        return False
    return len(space.shape) == 1 or np.issubdtype(space.dtype, np.floating)


def observation_kind(space: spaces.Space) -> str:
    """ "image", "vector", "image+vector" (a Dict with one image and 1-D vectors) or "other"."""
    if is_image(space):
        return "image"
    if is_vector(space):
        return "vector"
    if isinstance(space, spaces.Dict):
        subs = list(space.spaces.values())
        if sum(is_image(s) for s in subs) == 1 and all(is_image(s) or is_vector(s) for s in subs):
            return "image+vector"
    return "other"


class SeedCnn(nn.Module):
    """The MetaDrive study's image encoder; the FC input size follows the image size (2592 for 84×84)."""

    def __init__(self, image_space: spaces.Box, features: int = 256) -> None:
        super().__init__()
        channels = image_space.shape[0]
        self.conv = nn.Sequential(
            nn.Conv2d(channels, 16, kernel_size=8, stride=4), nn.ReLU(),
            nn.Conv2d(16, 32, kernel_size=4, stride=2), nn.ReLU(),
            nn.Flatten(),
        )  # fmt: skip
        with torch.no_grad():
            flat = self.conv(torch.zeros(1, *image_space.shape)).shape[1]
        self.fc = nn.Sequential(nn.Linear(flat, features), nn.ReLU())
        self.features = features

    def forward(self, image: torch.Tensor) -> torch.Tensor:
        return self.fc(self.conv(image))


class FusionEncoder(nn.Module):
    """Image (SeedCnn, 256) + LiDAR FC 128 (key ``lidar``, if present) + every other vector FC 64 → 256.

    Vectors other than ``lidar`` are flattened and concatenated in key order before their FC layer.
    """

    def __init__(self, space: spaces.Dict, features: int = 256) -> None:
        super().__init__()
        self.image_key = next(key for key, sub in space.spaces.items() if is_image(sub))
        self.lidar_key = "lidar" if "lidar" in space.spaces else None
        self.vector_keys = [k for k in space.spaces if k not in (self.image_key, self.lidar_key)]
        self.image = SeedCnn(space[self.image_key])
        width = self.image.features
        if self.lidar_key:
            self.lidar = nn.Sequential(nn.Linear(space[self.lidar_key].shape[0], 128), nn.ReLU())
            width += 128
        if self.vector_keys:
            size = sum(spaces.flatdim(space[k]) for k in self.vector_keys)
            self.vector = nn.Sequential(nn.Linear(size, 64), nn.ReLU())
            width += 64
        self.fusion = nn.Sequential(nn.Linear(width, features), nn.ReLU())  # 256 + 128 + 64 = 448 → 256
        self.features = features

    def forward(self, obs: dict[str, torch.Tensor]) -> torch.Tensor:
        parts = [self.image(obs[self.image_key])]
        if self.lidar_key:
            parts.append(self.lidar(obs[self.lidar_key]))
        if self.vector_keys:
            parts.append(self.vector(torch.cat([obs[k].flatten(1) for k in self.vector_keys], dim=1)))
        return self.fusion(torch.cat(parts, dim=1))


def _layers(size: int, hidden: tuple[int, ...], activation: type[nn.Module]) -> nn.Sequential:
    """Linear layers of widths ``hidden`` from ``size`` inputs, each followed by ``activation``."""
    layers = []
    for width in hidden:
        layers += [nn.Linear(size, width), activation()]
        size = width
    return nn.Sequential(*layers)


class MlpEncoder(nn.Module):
    """Tanh layers (two of 64 by default, SB3's MLP) for vector observations, Dicts concatenated."""

    def __init__(self, space: spaces.Space, hidden: tuple[int, ...] = (64, 64)) -> None:
        super().__init__()
        self.keys = list(space.spaces) if isinstance(space, spaces.Dict) else None
        self.net = _layers(spaces.flatdim(space), hidden, nn.Tanh)
        self.features = hidden[-1] if hidden else spaces.flatdim(space)

    def forward(self, obs) -> torch.Tensor:
        if self.keys is not None:
            return self.net(torch.cat([obs[k].flatten(1) for k in self.keys], dim=1))
        return self.net(obs.flatten(1))


ENCODERS = ("auto", "attention")
ENTITY_KEY = "kinematics"  # a Dict's vehicle set: the kinematics sensor's (rows, features) array


class EgoAttentionEncoder(nn.Module):
    """Ego-attention over a set of vehicles (Leurent & Mercat 2019, "Social Attention for
    Autonomous Decision-Making in Dense Traffic", rl-agents' ``EgoAttentionNetwork``).

    The vehicle set is a ``(rows, features)`` array whose row 0 is the ego (``kinematics`` with
    ``flatten=false``): the observation itself, or its ``kinematics`` entry in a Dict. Each row is
    embedded (ReLU layers ``hidden``; one embedding for the ego, one shared by the others), the ego's
    embedding queries every row's with multi-head attention, and the result plus the ego's
    embedding is the set's feature vector: invariant to the others' order and to their number.
    Rows that are all zero (kinematics' absent vehicles) are masked out, as rl-agents masks rows
    without presence; the mask is read from the observation before normalisation (``raw``). A
    Dict's other entries are concatenated through an MlpEncoder (tanh layers ``hidden``) and joined
    to the set's features. ``output``: ReLU layers over the joined features, rl-agents' output layer
    (none: the features go to the policy's linear heads as they are).
    """

    def __init__(
        self,
        space: spaces.Space,
        hidden: tuple[int, ...] = (64, 64),
        heads: int = 2,
        output: tuple[int, ...] = (),
    ) -> None:
        super().__init__()
        if isinstance(space, spaces.Dict):
            self.key = ENTITY_KEY if ENTITY_KEY in space.spaces else None
            entities = space.spaces.get(ENTITY_KEY)
            rest = {key: sub for key, sub in space.spaces.items() if key != ENTITY_KEY}
        else:
            self.key, entities, rest = "", space, {}
        if self.key is None or not (isinstance(entities, spaces.Box) and len(entities.shape) == 2):
            raise ValueError(
                "encoder attention needs the vehicles as rows: kinematics with flatten=false "
                f"(a (rows, features) array), got {space}"
            )
        width = hidden[-1]
        if width % heads:
            raise ValueError(f"encoder attention needs net_arch's last width divisible by {heads} heads")
        features = entities.shape[1]
        self.ego = _layers(features, hidden, nn.ReLU)
        self.others = _layers(features, hidden, nn.ReLU)
        self.attention = nn.MultiheadAttention(width, heads, batch_first=True)
        self.rest = MlpEncoder(spaces.Dict(rest), hidden) if rest else None
        joined = width + (self.rest.features if self.rest else 0)
        self.output = _layers(joined, output, nn.ReLU) if output else None
        self.features = output[-1] if output else joined

    def forward(self, obs, raw=None) -> torch.Tensor:
        """Features of a batch of (normalised) observations; ``raw``: the same before
        normalisation, which marks the absent rows (default: ``obs``)."""
        raw = obs if raw is None else raw
        rows = obs[self.key] if self.key else obs
        raw_rows = raw[self.key] if self.key else raw
        ego = self.ego(rows[:, :1])  # (B, 1, width)
        embedded = torch.cat([ego, self.others(rows[:, 1:])], dim=1)  # (B, rows, width)
        absent = (raw_rows == 0).all(-1)
        absent[:, 0] = False  # the ego always attends to itself
        attended, _ = self.attention(ego, embedded, embedded, key_padding_mask=absent, need_weights=False)
        features = (attended + ego).squeeze(1)
        if self.rest is not None:
            features = torch.cat([features, self.rest({k: obs[k] for k in self.rest.keys})], dim=1)
        return features if self.output is None else self.output(features)


def make_encoder(
    space: spaces.Space, hidden: tuple[int, ...] = (64, 64), kind: str = "auto", output: tuple[int, ...] = ()
) -> nn.Module:
    """SeedCnn for an image, FusionEncoder for image + vectors, MlpEncoder (layers ``hidden``) for
    vectors; with ``kind`` "attention", an EgoAttentionEncoder over the vehicles (``output``: its
    output layers)."""
    if kind == "attention":
        return EgoAttentionEncoder(space, hidden, output=output)
    kind = observation_kind(space)
    if kind == "image":
        return SeedCnn(space)
    if kind == "image+vector":
        return FusionEncoder(space)
    if kind == "vector":
        return MlpEncoder(space, hidden)
    raise ValueError(f"no encoder for observation space {space}")


class TanhGaussianActorCritic(nn.Module):
    """π(a|s): a = tanh(u), u ~ N(μ(s), σ²) with a trainable state-independent log σ; V(s).

    :param space: observation space.
    :param action_size: number of action dimensions (2: steering, throttle).
    :param shared_encoder: actor and critic share the encoder (seed's PPO) or own one each
        (seed's A2C: "convolutional layers in both the actor and critic networks").
    :param log_std_init: initial log σ.
    """

    def __init__(
        self, space: spaces.Space, action_size: int, shared_encoder: bool = True, log_std_init: float = 0.0
    ) -> None:
        super().__init__()
        self.actor_encoder = make_encoder(space)
        self.critic_encoder = self.actor_encoder if shared_encoder else make_encoder(space)
        self.mean = nn.Linear(self.actor_encoder.features, action_size)
        self.log_std = nn.Parameter(torch.full((action_size,), float(log_std_init)))
        self.value = nn.Linear(self.critic_encoder.features, 1)
        nn.init.orthogonal_(self.mean.weight, gain=0.01)  # start near the zero action
        nn.init.zeros_(self.mean.bias)

    def forward(self, obs) -> tuple[torch.Tensor, torch.Tensor]:
        """(μ, V) for a batch."""
        features = self.actor_encoder(obs)
        shared = self.critic_encoder is self.actor_encoder
        value = self.value(features if shared else self.critic_encoder(obs)).squeeze(-1)
        return self.mean(features), value

    def distribution(self, mean: torch.Tensor) -> torch.distributions.Normal:
        return torch.distributions.Normal(mean, self.log_std.exp().expand_as(mean))

    def sample(
        self, obs, deterministic: bool = False, generator: torch.Generator | None = None
    ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """(pre-tanh u, log π(tanh u), V): u = μ + σ·ε, ε ~ N(0, 1) drawn from ``generator``, or u = μ
        when ``deterministic`` (nothing drawn); log π is corrected for the squashing."""
        mean, value = self(obs)
        distribution = self.distribution(mean)
        if deterministic:
            unsquashed = mean
        else:
            unsquashed = mean + distribution.stddev * torch.randn(mean.shape, generator=generator)
        return unsquashed, squashed_log_prob(distribution, unsquashed), value


def squashed_log_prob(distribution: torch.distributions.Normal, unsquashed: torch.Tensor) -> torch.Tensor:
    """log π(a) for a = tanh(u): log N(u) − Σ log(1 − tanh²u), the change of variables, computed
    stably as 2·(log 2 − u − softplus(−2u))."""
    correction = 2.0 * (math.log(2.0) - unsquashed - nn.functional.softplus(-2.0 * unsquashed))
    return (distribution.log_prob(unsquashed) - correction).sum(-1)


class SeedCnnExtractor(BaseFeaturesExtractor):
    """The MetaDrive study's CNN as an SB3 features extractor (image observations)."""

    encoder_class: type[nn.Module] = SeedCnn

    def __init__(self, observation_space: spaces.Space) -> None:
        super().__init__(observation_space, features_dim=256)
        self.encoder = self.encoder_class(observation_space)

    def forward(self, observations) -> torch.Tensor:
        return self.encoder(observations)


class AttentionExtractor(BaseFeaturesExtractor):
    """``EgoAttentionEncoder`` (64-wide embeddings, two heads) as an SB3 features extractor: the
    vehicles of ``kinematics:flatten=false`` read as a set, as rl-agents' DQN reads highway-env's
    intersection; SB3's ``net_arch`` layers after it play rl-agents' output layer."""

    def __init__(self, observation_space: spaces.Space) -> None:
        encoder = EgoAttentionEncoder(observation_space)
        super().__init__(observation_space, features_dim=encoder.features)
        self.encoder = encoder

    def forward(self, observations) -> torch.Tensor:
        return self.encoder(observations)


class FusionExtractor(SeedCnnExtractor):
    """The MetaDrive study's fusion network as an SB3 features extractor (Dict: image + ego state + LiDAR)."""

    encoder_class = FusionEncoder
