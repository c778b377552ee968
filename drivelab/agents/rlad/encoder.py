"""RLAD's image encoder (the RLAD paper, Table I): 9 conv 3×3 layers, each followed by ReLU and A-LIX,
then Linear → LayerNorm → tanh to a 256-d latent.

At 256×256 the strides are 2, 2, 2, 2, 1, 1, 1, 1, 1 (a 64×5×5 map); smaller inputs turn the
trailing stride-2 layers into stride-1 ones until at least 3×3 is left (``encoder_strides``).
"""

from __future__ import annotations

import torch
from torch import nn

from drivelab.agents.rlad.alix import STRENGTH_INIT, TARGET_DISCONTINUITY, adaptive_local_signal_mixing

CHANNELS = (32, 32, 32, 64, 64, 64, 64, 64, 64)
KERNEL = 3
MAX_HALVINGS = 4  # Table I's stride-2 layers
MIN_FEATURE_SIZE = 3


def conv_output_size(size: int, strides: tuple[int, ...]) -> int:
    """Side of the last feature map for an input side ``size`` (no padding)."""
    for stride in strides:
        size = (size - KERNEL) // stride + 1
    return size


def encoder_strides(size: int) -> tuple[int, ...]:
    """Table I's strides for 256 px; for smaller inputs the most leading stride-2 layers (at most
    four) that still leave a feature map of at least 3×3."""
    for halvings in range(MAX_HALVINGS, -1, -1):
        strides = (2,) * halvings + (1,) * (len(CHANNELS) - halvings)
        if conv_output_size(size, strides) >= MIN_FEATURE_SIZE:
            return strides
    raise ValueError(f"images of {size} px are too small for the 9-layer encoder (need at least 21 px)")


class ImageEncoder(nn.Module):
    """uint8 image stacks (B, C, H, W) → latent (B, ``features``) in (−1, 1).

    :param channels: input channels (3 per stacked RGB frame).
    :param height: image height in pixels.
    :param width: image width in pixels.
    :param features: latent size (256).
    :param alix: A-LIX after every conv + ReLU (training mode only).
    :param alix_init: initial strength S.
    :param alix_target: β, the target normalised discontinuity.
    """

    def __init__(
        self,
        channels: int,
        height: int,
        width: int,
        features: int = 256,
        alix: bool = True,
        alix_init: float = STRENGTH_INIT,
        alix_target: float = TARGET_DISCONTINUITY,
    ) -> None:
        super().__init__()
        self.strides = encoder_strides(min(height, width))
        layers, previous = [], channels
        for out_channels, stride in zip(CHANNELS, self.strides, strict=True):
            layers.append(nn.Conv2d(previous, out_channels, KERNEL, stride))
            previous = out_channels
        self.convs = nn.ModuleList(layers)
        self.feature_shape = (
            CHANNELS[-1], conv_output_size(height, self.strides), conv_output_size(width, self.strides)
        )  # fmt: skip
        flat = self.feature_shape[0] * self.feature_shape[1] * self.feature_shape[2]
        self.head = nn.Sequential(nn.Linear(flat, features), nn.LayerNorm(features), nn.Tanh())
        self.alix, self.alix_target, self.features = alix, float(alix_target), features
        self.strength = nn.Parameter(torch.tensor(float(alix_init))) if alix else None
        self.generator = torch.Generator().manual_seed(0)  # the agent hands in its own

    def conv_features(self, images: torch.Tensor, offsets: torch.Tensor | None = None) -> torch.Tensor:
        """The last feature map, flattened; pixels are scaled to [−0.5, 0.5].

        :param images: (B, C, H, W), uint8 (or float in [0, 255]).
        :param offsets: A-LIX's offsets (9, 2), already drawn (``alix.draw_offsets``), on the
            images' device: the mixing then runs without a host synchronisation, and the caller
            has clamped S to [0, 1] (the fast update). None: each layer draws from ``generator``.
        """
        x = images.float() / 255.0 - 0.5
        mixing = self.alix and self.training
        if mixing and offsets is None:
            with torch.no_grad():
                self.strength.clamp_(0.0, 1.0)
        last = len(self.convs) - 1
        for index, conv in enumerate(self.convs):
            x = torch.relu(conv(x))
            if mixing:
                x = adaptive_local_signal_mixing(
                    x, self.strength, self.generator, learn_strength=index == last, target=self.alix_target,
                    offset=None if offsets is None else offsets[index],
                )  # fmt: skip
        return x.flatten(1)

    def forward(self, images: torch.Tensor, offsets: torch.Tensor | None = None) -> torch.Tensor:
        return self.head(self.conv_features(images, offsets))
