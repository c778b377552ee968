"""The fast backend for one world: a :class:`FastSimulator` of K = 1, read as a WorldState.

See ``simulator.py``: this class only gives DriveEnv its single-world API.
"""

from __future__ import annotations

import importlib

import numpy as np

from drivelab.sim.core import lanes as L
from drivelab.sim.core.simulator import (  # noqa: F401  (re-exported: tests, benchmarks)
    FastSimulator,
    idm_parameters,
    vehicles_to_array,
)
from drivelab.world.scenario import Scenario
from drivelab.world.state import WorldState


def fast_simulator(scenario: Scenario, traffic: str, control: str, num_worlds: int, overrides=None):
    """K worlds of ``scenario`` on the compiled core, run by the simulator class it names
    (``Scenario.simulator``)."""
    module, _, name = scenario.simulator.rpartition(".")
    simulator_class = getattr(importlib.import_module(module), name)
    return simulator_class(scenario, traffic, control, num_worlds, overrides)


class FastBackend:
    """Same scenarios, same WorldState as HighwayBackend, simulated by compiled array code.

    :param scenario: a scenario the compiled core runs (``fast_backend``).
    :param traffic: "empty", "regular" or "dense".
    :param control: "meta" or "continuous".
    :param overrides: extra highway-env config keys.
    """

    def __init__(
        self, scenario: Scenario, traffic: str = "regular", control: str = "meta", overrides=None
    ) -> None:
        self.scenario, self.control = scenario, control
        self.simulator = fast_simulator(scenario, traffic, control, 1, overrides)
        self.world: WorldState | None = None

    @property
    def route_time_limit_s(self) -> float | None:
        """The NoCrash time limit of the episode's fixed route (the town), else None."""
        limits = getattr(self.simulator, "route_time_limit_s", None)
        return None if limits is None or not np.isfinite(limits[0]) else float(limits[0])

    @property
    def policy_frequency_hz(self) -> float:
        return self.simulator.policy_frequency_hz

    @property
    def duration_s(self) -> float:
        return self.simulator.duration_s

    @property
    def table(self) -> L.LaneTable:
        return self.simulator.table

    @property
    def vehicles(self) -> np.ndarray:
        """(N, VEHICLE_COLUMNS) this world's vehicle rows (a view of the simulator's buffer)."""
        return self.simulator.vehicles[0, : self.simulator.count[0]]

    @property
    def ego(self) -> int:
        """The ego's row in ``vehicles``."""
        return int(self.simulator.ego[0])

    def reset(self, seed: int) -> WorldState:
        """A new episode from ``seed``."""
        self.world = self.simulator.reset_where(np.ones(1, dtype=bool), np.array([int(seed)]))[0]
        return self.world

    def step(self, control: int | np.ndarray) -> WorldState:
        """One policy step: the ego's control, then ``frames`` simulation steps."""
        self.world = self.simulator.step(np.asarray(control)[None])[0]
        return self.world
