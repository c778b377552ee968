"""The Sensor protocol: K worlds in (a WorldBatch), K observations written into one buffer."""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Sequence

import numpy as np
from gymnasium import spaces

from drivelab.world.batch import WorldBatch
from drivelab.world.geometry import box_corners, ego_frame  # noqa: F401  (re-exported for sensors)
from drivelab.world.state import WorldState


class Sensor(ABC):
    """Turns the K worlds of a WorldBatch into K observations of one declared (single-world) space.

    ``reset(batch, rngs, mask)`` when worlds start an episode, then ``observe(batch, out)`` once
    per policy step; a WorldState instead of a batch observes that one world. Subclasses set
    ``_space`` and implement ``_observe(batch, out)`` and, when they keep history, ``_reset(batch,
    mask)``; ``self.rngs[k]`` is world k's generator. ``_observe`` may get a sub-batch
    (``batch.select``), whose per-world state lives at ``state[batch.rows]``.
    """

    name: str = "sensor"
    help: str = ""  # one line for `drivelab envs`
    # draws noise from ``self.rngs`` (the environments make generators only for such sensors)
    uses_rng: bool = False

    @property
    def space(self) -> spaces.Space:
        """The observation space of one world, fixed at construction (subclasses set ``_space``)."""
        return self._space

    def reset(
        self,
        batch: WorldBatch | WorldState,
        rngs: Sequence[np.random.Generator] | np.random.Generator,
        mask: np.ndarray | None = None,
    ) -> None:
        """Clear the history of the worlds where ``mask`` (default: all) at the start of their
        episode; ``rngs[k]`` becomes world k's generator. A WorldState and one generator reset a
        one-world sensor."""
        if isinstance(batch, WorldState):
            batch, rngs = WorldBatch.stack([batch]), [rngs]
        count = batch.num_worlds
        if len(getattr(self, "rngs", ())) != count:  # a new number of worlds: every world starts
            self.rngs, mask = [None] * count, None
        mask = np.ones(count, dtype=bool) if mask is None else np.asarray(mask, dtype=bool)
        for k in np.flatnonzero(mask):
            self.rngs[k] = rngs[k]
        self._reset(batch, mask)

    def scenario_problem(self, scenario) -> str | None:
        """Why this sensor reads nothing meaningful in ``scenario`` (a ``Scenario``), e.g. paint the
        road does not have; None (the default) where it can observe it."""
        return None

    def _reset(self, batch: WorldBatch, mask: np.ndarray) -> None:
        """Clear the ``(K, …)`` history of the worlds where ``mask`` (sensors without history: nothing)."""
        return None

    def observe(self, batch: WorldBatch | WorldState, out: np.ndarray | None = None) -> np.ndarray:
        """The observations of every world, written into ``out`` (allocated when None) and
        returned; for a WorldState, that world's observation alone."""
        if isinstance(batch, WorldState):
            return self.observe(WorldBatch.stack([batch]))[0]
        if out is None:
            out = self.empty(batch.num_worlds)
        self._observe(batch, out)
        return out

    @abstractmethod
    def _observe(self, batch: WorldBatch, out: np.ndarray) -> None:
        """Write the K observations of ``batch`` into ``out`` (K, *space.shape); called once per
        policy step, after ``reset``."""

    def empty(self, num_worlds: int) -> np.ndarray:
        """A zeroed ``(num_worlds, *space.shape)`` buffer of the space's dtype."""
        layout = self.__dict__.get("_buffer_layout")  # (shape, dtype): the space is fixed
        if layout is None:
            layout = self.__dict__["_buffer_layout"] = (tuple(self.space.shape), self.space.dtype)
        return np.zeros((num_worlds, *layout[0]), dtype=layout[1])


ZEBRA_STRIPE_M = (0.5, 1.0)  # stripe width, and stripe-to-stripe pitch across the road


def zebra_stripes(crossings: np.ndarray) -> np.ndarray:
    """The painted stripes of zebra crossings (rows x, y, walking heading, length, width) as boxes
    (K, 5) ``x, y, heading, length, width``: stripes run along the street, as wide as the crossing,
    one every metre across the road."""
    boxes = []
    width_m, pitch_m = ZEBRA_STRIPE_M
    for x, y, heading, length_m, crossing_width_m in np.asarray(crossings, dtype=float).reshape(-1, 5):
        across = np.array([np.cos(heading), np.sin(heading)])
        offsets = np.arange(-length_m / 2 + pitch_m / 2, length_m / 2, pitch_m)
        centres = np.array([x, y]) + offsets[:, None] * across
        street_heading = heading + np.pi / 2
        boxes += [[cx, cy, street_heading, crossing_width_m, width_m] for cx, cy in centres]
    return np.array(boxes, dtype=float).reshape(-1, 5)
