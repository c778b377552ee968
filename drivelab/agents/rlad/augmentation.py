"""DrQ's random-shift augmentation (Kostrikov et al. 2021; RLAD, Section III-B1).

Each image is replicate-padded by ``pad`` pixels and cropped back to its size at a random integer
offset, independently per sample. The pad and the crop are one gather with clamped indices (a
clamped index is a replicated border pixel), so uint8 images stay uint8. DrQ-v2 resamples the
crop with ``grid_sample``; at integer offsets that is the same image.
"""

from __future__ import annotations

import torch


def default_pad(image_size: int) -> int:
    """RLAD pads 256-px images by 8, DrQ 84-px images by 4: 8 from 192 px up, 4 below."""
    return 8 if image_size >= 192 else 4


def draw_shifts(batch: int, pad: int, generator: torch.Generator) -> torch.Tensor:
    """The offsets (B, 2) in [−pad, pad]² that ``random_shift`` draws (on the CPU: seeded)."""
    return torch.randint(-pad, pad + 1, (batch, 2), generator=generator)


def random_shift(
    images: torch.Tensor, pad: int, generator: torch.Generator | None, offsets: torch.Tensor | None = None
) -> torch.Tensor:
    """Images (B, C, H, W) each shifted by a random offset in [−pad, pad]² with replicated borders.

    :param images: a batch of images (any dtype).
    :param pad: largest shift in pixels (0 returns ``images``).
    :param generator: draws the offsets (unused when ``offsets`` is given).
    :param offsets: the offsets (B, 2) already drawn (``draw_shifts``).
    """
    if pad <= 0:
        return images
    batch, _, height, width = images.shape
    device = images.device
    if offsets is None:
        offsets = draw_shifts(batch, pad, generator)
    offsets = offsets.to(device)
    rows = (torch.arange(height, device=device)[None, :] + offsets[:, :1]).clamp(0, height - 1)  # (B, H)
    cols = (torch.arange(width, device=device)[None, :] + offsets[:, 1:]).clamp(0, width - 1)  # (B, W)
    samples = torch.arange(batch, device=device)[:, None, None]
    shifted = images[samples, :, rows[:, :, None], cols[:, None, :]]  # (B, H, W, C)
    return shifted.permute(0, 3, 1, 2).contiguous()
