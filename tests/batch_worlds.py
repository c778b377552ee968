"""Random worlds of every scenario, K at a time, for the batched = single-world equivalence tests.

``world_sequences`` steps K independent single-world backends with random actions; world k starts
a new episode every ``3 + k % 4`` steps, so the worlds of one batch reset at different steps.
"""

from __future__ import annotations

import functools

import numpy as np

from drivelab.envs.actions import make_action
from drivelab.scenarios import SCENARIOS, get_scenario
from drivelab.world.batch import WorldBatch
from drivelab.world.state import WorldState

ALL_SCENARIOS = tuple(SCENARIOS)


def _backend(scenario_name: str, traffic: str, control: str):
    scenario = get_scenario(scenario_name)
    if scenario.fast_backend:
        from drivelab.sim.core.backend import FastBackend as backend_class
    else:
        from drivelab.sim.reference.highway import HighwayBackend as backend_class
    return backend_class(scenario, traffic, control, None)


@functools.cache
def world_sequences(
    scenario: str, num_worlds: int = 8, steps: int = 10, traffic: str = "dense", seed: int = 0
) -> tuple[tuple[tuple[WorldState, ...], np.ndarray], ...]:
    """Per step: the K worlds (WorldStates) and the (K,) mask of worlds that just started an
    episode (their world is the reset one). Cached: tests must not mutate what they get."""
    adapter = make_action(get_scenario(scenario).action_kinds[0])
    backends = [_backend(scenario, traffic, adapter.control) for _ in range(num_worlds)]
    rng = np.random.default_rng(seed)
    adapter.space.seed(seed)
    worlds: list[WorldState] = [None] * num_worlds  # type: ignore[list-item]
    sequence = []
    for t in range(steps):
        started = np.zeros(num_worlds, dtype=bool)
        for k, backend in enumerate(backends):
            if t % (3 + k % 4) == 0:
                worlds[k] = backend.reset(int(rng.integers(2**31 - 1)))
                started[k] = True
            else:
                adapter.reset()
                worlds[k] = backend.step(adapter.control_for(adapter.space.sample(), worlds[k]))
        sequence.append((tuple(worlds), started))
    return tuple(sequence)


def assert_same_observations(a, b) -> None:
    """Observations (arrays, or dicts of arrays) equal bit for bit."""
    if isinstance(a, dict):
        assert a.keys() == b.keys()
        for key in a:
            np.testing.assert_array_equal(a[key], b[key])
    else:
        np.testing.assert_array_equal(a, b)


def batches(scenario: str, **options) -> list[tuple[WorldBatch, np.ndarray]]:
    """``world_sequences`` as (WorldBatch, started mask) pairs."""
    return [
        (WorldBatch.stack(list(worlds)), started) for worlds, started in world_sequences(scenario, **options)
    ]
