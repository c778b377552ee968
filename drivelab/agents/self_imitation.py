"""Self-imitation learning (Oh, Guo, Singh and Lee, ICML 2018) for the on-policy trainer: the
agent's own recent transitions with their discounted returns, and the loss that imitates only the
actions whose return beat the critic's estimate. With ``-H sil_updates=N`` every PPO or A2C update
ends with N such steps (``onpolicy.OnPolicyAgent``); the returns are the rollout's Monte-Carlo
ones (GAE with λ = 1 on the rewards the critic learns, bootstrapped where the rollout stops), so
that they are in the critic's own scale.

The replay is part of a run's checkpoint (``replay.npz``, arrays only), so that a resumed run goes
on as an uninterrupted one.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch
from gymnasium import spaces

from drivelab.agents.worlds import map_obs


def self_imitation_loss(
    log_probs: torch.Tensor, values: torch.Tensor, returns: torch.Tensor, value_coef: float
) -> tuple[torch.Tensor, int]:
    """(loss, n) for a minibatch, n the transitions whose return R beat the critic's V(s):

    L = (−Σ log π(a|s)·(R − V(s))₊ + c/2·Σ ((R − V(s))₊)²) / max(n, 1),

    the weight (R − V)₊ taken as a constant in the first term (Oh et al. 2018, eq. 1-3), so that
    the policy is pulled only towards the actions that did better than expected and the critic only
    up towards returns it underestimated."""
    better = (returns - values).clamp(min=0.0)
    count = int((better > 0).sum())
    imitation = -(log_probs * better.detach()).sum()
    return (imitation + 0.5 * value_coef * (better**2).sum()) / max(count, 1), count


class SelfImitationReplay:
    """The last ``capacity`` transitions (observation, stored action, return), a ring of arrays.

    Logical index 0 is the oldest transition kept, ``size - 1`` the newest; ``sample`` draws
    logical indices uniformly.

    :param space: the observation space (Box or Dict); images stay uint8, the rest float32.
    :param capacity: transitions kept.
    :param action_shape: the shape of one stored action (() for a class index).
    :param discrete: actions are class indices (int64) rather than float32 vectors.
    """

    SCALARS = ("position", "size")

    def __init__(self, space: spaces.Space, capacity: int, action_shape: tuple, discrete: bool) -> None:
        def block(sub: spaces.Box) -> np.ndarray:
            dtype = np.uint8 if sub.dtype == np.uint8 else np.float32
            return np.zeros((capacity, *sub.shape), dtype=dtype)

        self.observations = map_obs(block, space.spaces if isinstance(space, spaces.Dict) else space)
        self.actions = np.zeros((capacity, *action_shape), dtype=np.int64 if discrete else np.float32)
        self.returns = np.zeros(capacity, dtype=np.float32)
        self.capacity, self.position, self.size = int(capacity), 0, 0

    def __len__(self) -> int:
        return self.size

    def add(self, observations: Any, actions: torch.Tensor, returns: np.ndarray) -> None:
        """Append a rollout's transitions (flattened, oldest first); the oldest kept ones go when full."""
        count = len(returns)
        keep = min(count, self.capacity)
        rows = (self.position + np.arange(keep)) % self.capacity

        def write(target: np.ndarray, values) -> None:
            target[rows] = np.asarray(values)[count - keep :]

        map_obs(write, self.observations, map_obs(lambda value: value.numpy(), observations))
        write(self.actions, actions.numpy())
        write(self.returns, returns)
        self.position = int((self.position + keep) % self.capacity)
        self.size = min(self.size + keep, self.capacity)

    def sample(self, batch_size: int, generator: torch.Generator) -> tuple[Any, torch.Tensor, torch.Tensor]:
        """(observations, actions, returns) of ``batch_size`` transitions drawn uniformly (with
        replacement) from ``generator``."""
        logical = torch.randint(self.size, (batch_size,), generator=generator).numpy()
        rows = (self.position - self.size + logical) % self.capacity
        observations = map_obs(lambda block: torch.from_numpy(block[rows]), self.observations)
        return observations, torch.from_numpy(self.actions[rows]), torch.from_numpy(self.returns[rows])

    # --- checkpoints ----------------------------------------------------------------------------
    def _arrays(self) -> dict[str, np.ndarray]:
        observations = self.observations
        if isinstance(observations, dict):
            named = {f"observations.{key}": value for key, value in observations.items()}
        else:
            named = {"observations": observations}
        return {**named, "actions": self.actions, "returns": self.returns}

    def state_arrays(self) -> dict[str, np.ndarray]:
        """Everything the replay holds, as arrays (a checkpoint's ``replay.npz``)."""
        return {**self._arrays(), **{name: np.asarray(getattr(self, name)) for name in self.SCALARS}}

    def load_state_arrays(self, arrays: dict[str, np.ndarray]) -> None:
        """Restore ``state_arrays``; a ValueError, and nothing changed, when an array is missing or
        of another shape or dtype than this replay's (another configuration)."""
        expected = {**self._arrays(), **{name: np.asarray(0) for name in self.SCALARS}}
        for name, current in expected.items():
            if name not in arrays:
                raise ValueError(f"the self-imitation replay has no {name!r} array")
            value = arrays[name]
            if value.shape != current.shape or (name not in self.SCALARS and value.dtype != current.dtype):
                raise ValueError(
                    f"replay array {name!r} is {value.dtype}{value.shape}, this agent's is "
                    f"{current.dtype}{current.shape}"
                )
        position, size = int(arrays["position"]), int(arrays["size"])
        if not (0 <= size <= self.capacity and 0 <= position < self.capacity):
            raise ValueError(f"replay position {position} and size {size} outside its {self.capacity} rows")
        for name, current in self._arrays().items():
            np.copyto(current, arrays[name])
        self.position, self.size = position, size
