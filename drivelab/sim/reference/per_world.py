"""The batch-first simulator API over single-world backends (highway-env, the reference).

``PerWorldSimulator`` holds K single-world backends and steps them one after another (the
reference runs one world at a time by design); for K > 1, ``gymnasium``'s ``AsyncVectorEnv`` over
DriveEnvs is faster, and ``drivelab.envs.vector.make_vec`` picks it.
"""

from __future__ import annotations

import numpy as np

from drivelab.world.batch import WorldBatch
from drivelab.world.state import WorldState


class PerWorldSimulator:
    """K worlds of one scenario, each its own single-world backend.

    :param backend_class: a single-world backend (``reset(seed) -> WorldState``,
        ``step(control) -> WorldState``), e.g. ``HighwayBackend``.
    :param num_worlds: K.
    The other parameters are the backend's own (scenario, traffic level, control kind, overrides).
    """

    def __init__(self, backend_class, scenario, traffic: str, control: str, num_worlds: int, overrides=None):
        self.backends = [backend_class(scenario, traffic, control, overrides) for _ in range(num_worlds)]
        self.num_worlds = num_worlds
        self.worlds: list[WorldState | None] = [None] * num_worlds

    @property
    def policy_frequency_hz(self) -> float:
        return self.backends[0].policy_frequency_hz

    @property
    def duration_s(self) -> float:
        return self.backends[0].duration_s

    @property
    def route_time_limit_s(self) -> np.ndarray | None:
        """(K,) each world's route time limit (the town's NoCrash routes), or None without one."""
        limits = [getattr(backend, "route_time_limit_s", None) for backend in self.backends]
        if all(limit is None for limit in limits):
            return None
        return np.array([np.inf if limit is None else limit for limit in limits], dtype=float)

    def reset_where(self, mask: np.ndarray, seeds: np.ndarray) -> WorldBatch:
        """A new episode from ``seeds[k]`` in every world where ``mask[k]``; the whole batch."""
        for k in np.flatnonzero(mask):
            self.worlds[k] = self.backends[k].reset(int(seeds[k]))
        return WorldBatch.stack(self.worlds)

    def step(
        self, controls: np.ndarray, restart: np.ndarray | None = None, seeds: np.ndarray | None = None
    ) -> WorldBatch:
        """One policy step of every world: ``controls`` (K,) meta-actions or (K, 2) rows; the
        worlds of ``restart`` (K,) start a new episode from ``seeds[k]`` instead."""
        for k, (backend, control) in enumerate(zip(self.backends, controls, strict=True)):
            restarting = restart is not None and restart[k]
            self.worlds[k] = backend.reset(int(seeds[k])) if restarting else backend.step(control)
        return WorldBatch.stack(self.worlds)
