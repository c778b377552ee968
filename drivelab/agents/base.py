"""The Agent protocol every algorithm satisfies, SB3 adapters and drivelab's own agents alike."""

from __future__ import annotations

from pathlib import Path
from typing import Any, Protocol

import numpy as np


class Agent(Protocol):
    """What training, evaluation and comparison need from an algorithm."""

    num_timesteps: int

    def learn(self, total_steps: int, callback: Any = None) -> Any:
        """Train until ``num_timesteps`` reaches ``total_steps`` (continues after a resume)."""

    def predict(self, obs: Any, deterministic: bool = True) -> tuple[np.ndarray, Any]:
        """(action, state) for one observation."""

    def save(self, path: str | Path) -> None:
        """Write everything needed to continue training or to act."""
