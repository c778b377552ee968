"""A-LIX, adaptive local signal mixing (Cetin et al., ICML 2022), after every conv + ReLU of RLAD's
image encoder (the RLAD paper, Table I).

Forward, training only: the feature maps are replicate-padded and resampled bilinearly at one
random 2-D offset within ±``MAX_SHIFT_PX``·S pixels, shared by the batch (S = 0 is the identity).
The strength S follows a dual objective: the last A-LIX layer hands S the gradient β − ND, ND
the normalised discontinuity of the feature gradient reaching it, so ND settles near β.
``shift_bilinear_tensor`` takes the shift as a device tensor, for the fast update (no host
round trip); it differs from ``shift_bilinear`` only by the shift's float32 rounding.
"""

from __future__ import annotations

import math

import torch
from torch import nn

PAD = 3  # replicate padding; covers the largest displacement
MAX_SHIFT_PX = 2.5  # displacement at S = 1
TARGET_DISCONTINUITY = 0.535  # β
STRENGTH_INIT = 0.5


def normalized_discontinuity(gradient: torch.Tensor) -> torch.Tensor:
    """ND of a feature gradient (B, C, H, W), a scalar.

    ḡ = the gradient averaged over the batch; at each location, over its 3×3 neighbourhood
    (replicate padding): signal = mean of the 8 neighbours' ḡ², noise = mean of the 8
    (ḡ_neighbour − ḡ_centre)²; ND = mean over C, H, W of log(1 + noise / (signal + 1e-20)).
    """
    mean = gradient.mean(dim=0, keepdim=True)  # (1, C, H, W)
    height, width = mean.shape[-2:]
    padded = nn.functional.pad(mean, (1, 1, 1, 1), mode="replicate")
    shifts = [(dy, dx) for dy in (-1, 0, 1) for dx in (-1, 0, 1) if (dy, dx) != (0, 0)]
    neighbours = torch.stack(
        [padded[..., 1 + dy : 1 + dy + height, 1 + dx : 1 + dx + width] for dy, dx in shifts]
    )
    signal = (neighbours**2).mean(dim=0)
    noise = ((neighbours - mean) ** 2).mean(dim=0)
    return torch.log1p(noise / (signal + 1e-20)).mean()


class DualStrengthGradient(torch.autograd.Function):
    """Identity on the features; on the way back the features' gradient passes unchanged and the
    strength S receives β − ND(gradient) (A-LIX's dual objective)."""

    @staticmethod
    def forward(ctx, features: torch.Tensor, strength: torch.Tensor, target: float) -> torch.Tensor:
        ctx.target, ctx.strength_shape = target, strength.shape
        return features.view_as(features)

    @staticmethod
    def backward(ctx, gradient: torch.Tensor):
        dual = ctx.target - normalized_discontinuity(gradient.float())  # float32 under bf16 autocast too
        return gradient, dual.reshape(ctx.strength_shape).to(gradient.dtype), None


def shift_bilinear(features: torch.Tensor, shift_px: tuple[float, float]) -> torch.Tensor:
    """``features`` (B, C, H, W) resampled at (row, column) + ``shift_px`` with bilinear
    interpolation, replicate padding outside; |shift| ≤ PAD − 1 in each axis."""
    shift_y, shift_x = shift_px
    if shift_y == 0.0 and shift_x == 0.0:
        return features
    height, width = features.shape[-2:]
    padded = nn.functional.pad(features, (PAD, PAD, PAD, PAD), mode="replicate")
    top, left = math.floor(shift_y), math.floor(shift_x)
    fy, fx = shift_y - top, shift_x - left
    top, left = PAD + top, PAD + left

    def window(dy: int, dx: int) -> torch.Tensor:
        return padded[..., top + dy : top + dy + height, left + dx : left + dx + width]

    upper = (1.0 - fx) * window(0, 0) + fx * window(0, 1)
    lower = (1.0 - fx) * window(1, 0) + fx * window(1, 1)
    return (1.0 - fy) * upper + fy * lower


def _mix_axis(features: torch.Tensor, dim: int, shift: torch.Tensor) -> torch.Tensor:
    """``features`` resampled along ``dim`` at positions i + ``shift``: linear interpolation
    between the two integer windows around the shift, gathered at indices computed on the device
    and clamped to the edge (replicate padding)."""
    size = features.shape[dim]
    floor = torch.floor(shift)
    fraction = shift - floor
    first = torch.arange(size, device=features.device) + floor.long()
    lower = features.index_select(dim, first.clamp(0, size - 1))
    upper = features.index_select(dim, (first + 1).clamp(0, size - 1))
    return (1.0 - fraction) * lower + fraction * upper


def shift_bilinear_tensor(features: torch.Tensor, shift_px: torch.Tensor) -> torch.Tensor:
    """``shift_bilinear`` with the (row, column) shift as a tensor (2,) on the features' device;
    no host synchronisation. (B, C, H, W) → (B, C, H, W)."""
    return _mix_axis(_mix_axis(features, 3, shift_px[1]), 2, shift_px[0])


def adaptive_local_signal_mixing(
    features: torch.Tensor,
    strength: torch.Tensor,
    generator: torch.Generator | None,
    learn_strength: bool,
    target: float = TARGET_DISCONTINUITY,
    offset: torch.Tensor | None = None,
) -> torch.Tensor:
    """One A-LIX layer in training mode (see the module docstring).

    :param features: feature maps (B, C, H, W) after a conv + ReLU.
    :param strength: the shared strength S (a parameter, clamped to [0, 1] by the caller).
    :param generator: draws the random offset (unused when ``offset`` is given).
    :param learn_strength: this layer produces S's dual gradient (the encoder's last layer).
    :param target: β, the target normalised discontinuity.
    :param offset: the offset (2,) in [−1, 1]² already drawn, on the features' device: on a
        GPU, or when compiled, the shift is then computed and applied on the device
        (``shift_bilinear_tensor``); eager on the CPU, as with a drawn offset (the same numbers).
    """
    if learn_strength:
        features = DualStrengthGradient.apply(features, strength, target)
    if offset is not None and (features.device.type != "cpu" or torch.compiler.is_compiling()):
        return shift_bilinear_tensor(features, offset * (MAX_SHIFT_PX * strength.detach()))
    if offset is None:
        offset = torch.rand(2, generator=generator) * 2.0 - 1.0
    # on the CPU reading the numbers costs nothing, and shifted slices beat index_select (eager)
    scale = MAX_SHIFT_PX * float(strength.detach())
    return shift_bilinear(features, (float(offset[0]) * scale, float(offset[1]) * scale))


def draw_offsets(generator: torch.Generator, layers: int) -> torch.Tensor:
    """The offsets (``layers``, 2) in [−1, 1]² that ``layers`` A-LIX layers draw from ``generator``
    one after another (the same numbers as the layers' own draws)."""
    return torch.stack([torch.rand(2, generator=generator) * 2.0 - 1.0 for _ in range(layers)])
