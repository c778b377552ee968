"""RLAD's networks (the RLAD paper, Fig. 1): the state encoder h = [ĩ 256 | ṽ 16 | w̃ 32], the
tanh-Gaussian actor, the twin critics and the traffic-light head.
"""

from __future__ import annotations

import torch
from gymnasium import spaces
from torch import nn

from drivelab.agents.networks import squashed_log_prob
from drivelab.agents.rlad.encoder import ImageEncoder
from drivelab.agents.rlad.replay import LIGHT_CLASSES
from drivelab.agents.rlad.waypoints import MeasurementEncoder, make_waypoint_encoder

IMAGE_FEATURES, MEASUREMENT_FEATURES, WAYPOINT_FEATURES = 256, 16, 32  # Table II's dim(ĩ), dim(ṽ), dim(w̃)


class StateEncoder(nn.Module):
    """One encoder for critic and auxiliary head: h = [image | measurements | waypoints] (304)."""

    def __init__(self, space: spaces.Dict, config) -> None:
        """``config``: an ``RLADConfig`` (alix, alix_init, alix_target, waypoint_encoder)."""
        super().__init__()
        height, width, channels = space["camera"].shape
        self.image = ImageEncoder(
            channels, height, width, IMAGE_FEATURES, config.alix, config.alix_init, config.alix_target
        )
        self.measurements = MeasurementEncoder(space["measurements"].shape[0], MEASUREMENT_FEATURES)
        self.waypoints = make_waypoint_encoder(
            config.waypoint_encoder, space["waypoints"].shape[0], WAYPOINT_FEATURES
        )
        self.features = IMAGE_FEATURES + MEASUREMENT_FEATURES + WAYPOINT_FEATURES

    def forward(
        self,
        images: torch.Tensor,
        waypoints: torch.Tensor,
        measurements: torch.Tensor,
        offsets: torch.Tensor | None = None,
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """(h, image latent ĩ); ``offsets``: A-LIX's pre-drawn offsets (``ImageEncoder.conv_features``)."""
        image = self.image(images, offsets)
        return torch.cat([image, self.measurements(measurements), self.waypoints(waypoints)], dim=1), image


def mlp(inputs: int, hidden: int, outputs: int) -> nn.Sequential:
    """inputs → hidden → ReLU → hidden → ReLU → outputs."""
    return nn.Sequential(
        nn.Linear(inputs, hidden), nn.ReLU(), nn.Linear(hidden, hidden), nn.ReLU(), nn.Linear(hidden, outputs)
    )


class Actor(nn.Module):
    """π(a|h): a = tanh(μ(h) + σ(h)·ε), log σ squashed into [log_std_min, log_std_max]."""

    def __init__(self, features: int, actions: int, hidden: int, log_std_min: float, log_std_max: float):
        super().__init__()
        self.net = mlp(features, hidden, 2 * actions)
        self.log_std_min, self.log_std_max = log_std_min, log_std_max

    def forward(self, h: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """(μ, log σ)."""
        mean, log_std = self.net(h).chunk(2, dim=-1)
        span = self.log_std_max - self.log_std_min
        return mean, self.log_std_min + 0.5 * span * (torch.tanh(log_std) + 1.0)

    def sample(
        self, h: torch.Tensor, generator: torch.Generator | None, noise: torch.Tensor | None = None
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """(a in [−1, 1], log π(a|h)) by the reparameterisation u = μ + σ·ε; ε (B, |A|) is
        ``noise`` when given (already drawn, on h's device), else drawn from ``generator``."""
        mean, log_std = self(h)
        distribution = torch.distributions.Normal(mean, log_std.exp(), validate_args=False)
        if noise is None:
            noise = torch.randn(mean.shape, generator=generator).to(mean.device)  # drawn on the CPU: seeded
        unsquashed = mean + log_std.exp() * noise
        return torch.tanh(unsquashed), squashed_log_prob(distribution, unsquashed)


class TwinCritic(nn.Module):
    """Q_θ1(h, a), Q_θ2(h, a): two independent MLPs."""

    def __init__(self, features: int, actions: int, hidden: int) -> None:
        super().__init__()
        self.q1, self.q2 = mlp(features + actions, hidden, 1), mlp(features + actions, hidden, 1)

    def forward(self, h: torch.Tensor, action: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        inputs = torch.cat([h, action], dim=1)
        return self.q1(inputs).squeeze(-1), self.q2(inputs).squeeze(-1)


class TrafficLightHead(nn.Module):
    """f_l: image latent (256) → 128 → ReLU → 64 → ReLU → logits of none / green / red-or-yellow."""

    def __init__(self, features: int = IMAGE_FEATURES) -> None:
        super().__init__()
        self.net = nn.Sequential(
            nn.Linear(features, 128), nn.ReLU(),
            nn.Linear(128, 64), nn.ReLU(),
            nn.Linear(64, len(LIGHT_CLASSES)),
        )  # fmt: skip

    def forward(self, image: torch.Tensor) -> torch.Tensor:
        return self.net(image)
