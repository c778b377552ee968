"""RLAD's vector encoders (the RLAD paper, Section III-B1): WayConv1D for the waypoints, its MLP
ablation, and the measurement MLP."""

from __future__ import annotations

import torch
from torch import nn

WAYPOINT_ENCODERS = ("wayconv1d", "mlp")
CONV_CHANNELS, HIDDEN = 20, 20


def _latent(inputs: int, features: int, hidden: int = HIDDEN) -> nn.Sequential:
    """inputs → hidden → ReLU → features → LayerNorm → tanh (waypoint encoders' tail, measurement MLP)."""
    return nn.Sequential(
        nn.Linear(inputs, hidden), nn.ReLU(), nn.Linear(hidden, features), nn.LayerNorm(features), nn.Tanh()
    )


class WayConv1D(nn.Module):
    """Waypoints (B, N, 2) → latent (B, ``features``) through a 1-D convolution over the points.

    :param count: number of waypoints N (≥ 2).
    :param features: latent size (32).
    """

    def __init__(self, count: int = 10, features: int = 32) -> None:
        super().__init__()
        if count < 2:
            raise ValueError("WayConv1D needs at least 2 waypoints")
        self.conv = nn.Conv1d(2, CONV_CHANNELS, kernel_size=2)
        self.latent = _latent(CONV_CHANNELS * (count - 1), features)
        self.features = features

    def forward(self, waypoints: torch.Tensor) -> torch.Tensor:
        return self.latent(torch.relu(self.conv(waypoints.transpose(1, 2))).flatten(1))


class WaypointMLP(nn.Module):
    """Waypoints (B, N, 2) flattened → dense layer as wide as WayConv1D's convolution output → the
    same tail (the paper's "replace WayConv1D" ablation).

    :param count: number of waypoints N.
    :param features: latent size (32).
    """

    def __init__(self, count: int = 10, features: int = 32) -> None:
        super().__init__()
        width = CONV_CHANNELS * max(count - 1, 1)
        self.dense = nn.Linear(2 * count, width)
        self.latent = _latent(width, features)
        self.features = features

    def forward(self, waypoints: torch.Tensor) -> torch.Tensor:
        return self.latent(torch.relu(self.dense(waypoints.flatten(1))))


def make_waypoint_encoder(kind: str, count: int, features: int = 32) -> nn.Module:
    """``wayconv1d`` or ``mlp``."""
    if kind == "wayconv1d":
        return WayConv1D(count, features)
    if kind == "mlp":
        return WaypointMLP(count, features)
    raise ValueError(f"unknown waypoint encoder {kind!r} (choose from {', '.join(WAYPOINT_ENCODERS)})")


class MeasurementEncoder(nn.Module):
    """Measurements (B, M) → 8 → ReLU → ``features`` → LayerNorm → tanh.

    :param size: number of measurement values M (6: speed and steer over 3 frames).
    :param features: latent size (16).
    """

    def __init__(self, size: int, features: int = 16) -> None:
        super().__init__()
        self.net = _latent(size, features, hidden=8)
        self.features = features

    def forward(self, measurements: torch.Tensor) -> torch.Tensor:
        return self.net(measurements)
