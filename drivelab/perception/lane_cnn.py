"""The CARLA study's lane-line segmentation CNN (its section 4.1) and its training on given frames.

A small encoder-decoder maps a 120 x 160 camera frame to the ego lane's left and right line masks.
It is trained on frames that drivelab's own camera renders on the follow-lane circuit
(``drivelab.training.lane_dataset``); the weights ship in ``drivelab/perception/weights/lane_cnn.pt``
and ``drivelab perception train-lane`` retrains them.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import torch
from torch import nn
from torch.nn import functional

from drivelab.errors import UsageError

WEIGHTS_PATH = Path(__file__).parent / "weights" / "lane_cnn.pt"


class LaneNet(nn.Module):
    """Encoder (two stride-2 convolutions, a dilated block) and decoder with skips, 2 output logits.

    :param width: channels of the first stage (the second has ``width + 4``).
    """

    def __init__(self, width: int = 12) -> None:
        super().__init__()
        deep = width + 4
        self.down1 = nn.Conv2d(3, width, 3, stride=2, padding=1)
        self.down2 = nn.Conv2d(width, deep, 3, stride=2, padding=1)
        self.middle = nn.Sequential(
            nn.Conv2d(deep, deep, 3, padding=1), nn.ReLU(), nn.Conv2d(deep, deep, 3, padding=2, dilation=2)
        )
        self.up1 = nn.Conv2d(deep + width, 8, 3, padding=1)
        self.head = nn.Conv2d(8 + 3, 2, 1)

    def forward(self, images: torch.Tensor) -> torch.Tensor:
        """Images (N, 3, H, W) in [0, 1] → logits (N, 2, H, W); H and W divisible by 4."""
        half = functional.relu(self.down1(images))
        quarter = functional.relu(self.middle(functional.relu(self.down2(half))))
        up = functional.interpolate(quarter, size=half.shape[-2:], mode="bilinear", align_corners=False)
        up = functional.relu(self.up1(torch.cat([up, half], dim=1)))
        up = functional.interpolate(up, size=images.shape[-2:], mode="bilinear", align_corners=False)
        return self.head(torch.cat([up, images], dim=1))

    @torch.no_grad()
    def segment(self, image_rgb: np.ndarray) -> np.ndarray:
        """RGB uint8 frames (K, H, W, 3) → left/right line masks (K, 2, H, W) bool, in one forward
        pass; one frame (H, W, 3) → (2, H, W)."""
        frames = np.asarray(image_rgb)
        batch = torch.from_numpy(
            np.ascontiguousarray(frames.reshape(-1, *frames.shape[-3:]).transpose(0, 3, 1, 2))
        )
        masks = (self(batch.float() / 255.0) > 0).numpy()
        return masks[0] if frames.ndim == 3 else masks


def load_lane_cnn(path: str | Path | None = None) -> LaneNet:
    """The network with weights from ``path`` (default: the shipped ones), in evaluation mode."""
    path = Path(path) if path is not None else WEIGHTS_PATH
    if not path.is_file():
        raise UsageError(f"lane CNN weights not found: {path} (run `drivelab perception train-lane`)")
    try:
        saved = torch.load(path, map_location="cpu", weights_only=True)
        network = LaneNet(int(saved["width"]))
        network.load_state_dict(saved["state_dict"])
    except Exception as exc:  # not a torch file, another network's weights, a truncated file
        raise UsageError(
            f"{str(path)!r} is not lane CNN weights written by `drivelab perception train-lane` "
            f"({type(exc).__name__})"
        ) from None
    return network.eval()


def iou(predicted: np.ndarray, truth: np.ndarray) -> float:
    """Intersection over union of two boolean arrays (1 when both are empty)."""
    union = np.logical_or(predicted, truth).sum()
    return float(np.logical_and(predicted, truth).sum() / union) if union else 1.0


def train_lane_cnn(
    images: np.ndarray,
    masks: np.ndarray,
    epochs: int = 15,
    seed: int = 0,
    out: str | Path = WEIGHTS_PATH,
    batch_size: int = 32,
    learning_rate: float = 3e-3,
    width: int = 12,
    log=print,
) -> dict:
    """Train a LaneNet with Adam on a class-weighted binary cross-entropy, save its weights to
    ``out`` and return a summary.

    :param images: training frames (N, H, W, 3) uint8.
    :param masks: their left/right line masks (N, 2, H, W) in {0, 1}.
    """
    torch.manual_seed(seed)
    started = time.perf_counter()
    frames = len(images)
    inputs = torch.from_numpy(images.transpose(0, 3, 1, 2).copy()).float() / 255.0
    targets = torch.from_numpy(masks).float()
    network = LaneNet(width)
    optimiser = torch.optim.Adam(network.parameters(), lr=learning_rate)
    # lines cover about 1 % of the pixels: weigh them up so that "no line anywhere" does not win
    pos_weight = torch.tensor(4.0)
    generator = torch.Generator().manual_seed(seed)
    losses = []
    for epoch in range(epochs):
        order = torch.randperm(frames, generator=generator)
        total = 0.0
        for first in range(0, frames, batch_size):
            batch = order[first : first + batch_size]
            loss = functional.binary_cross_entropy_with_logits(
                network(inputs[batch]), targets[batch], pos_weight=pos_weight
            )
            optimiser.zero_grad()
            loss.backward()
            optimiser.step()
            total += loss.item() * len(batch)
        losses.append(total / frames)
        log(f"epoch {epoch + 1}/{epochs}: loss {losses[-1]:.4f}")
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    torch.save({"width": width, "state_dict": network.state_dict()}, out)
    return {
        "frames": frames,
        "epochs": epochs,
        "seed": seed,
        "losses": losses,
        "seconds": time.perf_counter() - started,
        "weights": str(out),
        "bytes": out.stat().st_size,
    }
