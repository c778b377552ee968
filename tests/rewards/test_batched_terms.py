"""Every reward term over K worlds equals the term on each world alone (K = 1) and the
single-world terms as they were before the batch-first rewrite, on random worlds of every
scenario whose worlds reset at different steps."""

import dataclasses

import numpy as np
import pytest

from drivelab.envs.actions import make_action
from drivelab.rewards.shapers import PRESETS, RewardShaper
from drivelab.rewards.terms import TERMS
from drivelab.scenarios import get_scenario
from drivelab.world.batch import EVENT_FLAGS, WorldBatch
from drivelab.world.state import Events
from tests.batch_worlds import ALL_SCENARIOS, world_sequences
from tests.rewards.legacy_terms import LEGACY_TERMS

NUM_WORLDS = 8


def _random_controls(scenario: str, rng: np.random.Generator) -> np.ndarray:
    """(K,) meta-actions or (K, 2) float32 [acceleration, steering] in [-1, 1], as the scenario's
    first action kind hands them to the backend."""
    if make_action(get_scenario(scenario).action_kinds[0]).control == "meta":
        return rng.integers(0, 5, size=NUM_WORLDS)
    return rng.uniform(-1.0, 1.0, size=(NUM_WORLDS, 2)).astype(np.float32)


def _transitions(scenario: str):
    """(prev worlds, worlds, prev batch, batch, controls, stepped mask) for every step after the
    first; worlds that just reset have no previous world of their episode and are left out."""
    sequence = world_sequences(scenario, num_worlds=NUM_WORLDS)
    rng = np.random.default_rng(1)
    for (prev_worlds, _), (worlds, started) in zip(sequence[:-1], sequence[1:], strict=True):
        prev, batch = WorldBatch.stack(list(prev_worlds)), WorldBatch.stack(list(worlds))
        yield prev_worlds, worlds, prev, batch, _random_controls(scenario, rng), ~started


def test_the_sequences_mix_resets_and_steps():
    stepped = np.array([mask for *_, mask in _transitions("highway")])
    assert (stepped.any(axis=1) & ~stepped.all(axis=1)).any()  # a step where some worlds just reset


@pytest.mark.parametrize("scenario", ALL_SCENARIOS)
def test_batched_terms_equal_single_world_terms(scenario):
    compared = 0
    for prev_worlds, worlds, prev, batch, controls, stepped in _transitions(scenario):
        for name, term in TERMS.items():
            values = term(prev, batch, controls)
            assert values.shape == (NUM_WORLDS,) and values.dtype == float, name
            for k in np.flatnonzero(stepped):
                alone = term(
                    WorldBatch.stack([prev_worlds[k]]), WorldBatch.stack([worlds[k]]), controls[k : k + 1]
                )
                legacy = LEGACY_TERMS[name](prev_worlds[k], worlds[k], controls[k])
                assert values[k] == alone[0], (name, k)
                # the old code took some values through other roundings: the 1-D norm through BLAS's
                # dot (fused multiply-adds), a float ``**`` through libm where numpy's vectorised
                # power may differ by an ulp; everything else is exact
                assert values[k] == pytest.approx(legacy, rel=1e-12, abs=1e-12), (name, k)
                compared += 1
    assert compared >= len(TERMS) * NUM_WORLDS * 2


@pytest.mark.parametrize("scenario", ALL_SCENARIOS)
def test_batched_shaper_equals_single_world_shaper(scenario):
    shapers = {preset: RewardShaper(preset) for preset in PRESETS}
    for (prev_worlds, worlds, prev, batch, controls, stepped), (preset, shaper) in zip(
        _transitions(scenario), list(shapers.items()) * 4, strict=False
    ):
        rewards, contributions = shaper(prev, batch, controls)
        assert rewards.shape == (NUM_WORLDS,)
        assert set(contributions) == set(PRESETS[preset].weights)
        for k in np.flatnonzero(stepped):
            reward, parts = shaper(prev_worlds[k], worlds[k], controls[k])
            assert rewards[k] == reward
            assert {name: value[k] for name, value in contributions.items()} == parts


def _perturbed(world, rng: np.random.Generator):
    """``world`` with its ego and events drawn at random, so that every branch of every term is taken
    (junctions, curves, steering jumps, route ends, every event)."""
    ego = dataclasses.replace(
        world.ego,
        heading=world.ego.heading + rng.normal(0.0, 0.3),
        speed_mps=rng.uniform(0.0, 35.0),
        steering=rng.uniform(-0.4, 0.4),
        lateral_offset_m=rng.uniform(-3.0, 3.0),
        lane_curvature=rng.choice([0.0, 0.005, 0.02, -0.05]),
        in_intersection=bool(rng.random() < 0.5),
        on_road=bool(rng.random() < 0.8),
        target_lane_id=int(rng.integers(0, 3)),
        lane_count=int(rng.integers(1, 4)),
    )
    flags = {name: bool(rng.random() < 0.2) for name in EVENT_FLAGS}
    events = Events(collision_with="vehicle" if flags["collided"] else "", **flags)
    length_m = rng.choice([np.inf, world.route.progress_m + rng.uniform(0.0, 100.0)])
    route = dataclasses.replace(world.route, length_m=float(length_m))
    return dataclasses.replace(world, ego=ego, events=events, route=route)


@pytest.mark.parametrize("scenario", ["highway", "intersection", "town"])
def test_batched_terms_equal_legacy_on_perturbed_worlds(scenario):
    rng = np.random.default_rng(7)
    taken = {name: set() for name in TERMS}
    for prev_worlds, worlds, _, _, controls, _ in _transitions(scenario):
        prev_worlds = [_perturbed(w, rng) for w in prev_worlds]
        worlds = [_perturbed(w, rng) for w in worlds]
        prev, batch = WorldBatch.stack(prev_worlds), WorldBatch.stack(worlds)
        for name, term in TERMS.items():
            values = term(prev, batch, controls)
            for k in range(NUM_WORLDS):
                legacy = LEGACY_TERMS[name](prev_worlds[k], worlds[k], controls[k])
                assert values[k] == pytest.approx(legacy, rel=1e-12, abs=1e-12), (name, k)  # as above
            taken[name] |= set(np.round(values, 6).tolist())
    for name in ("curve_control", "intersection_heading", "steering_smoothness", "roach_terminal", "speed"):
        assert len(taken[name]) >= 3, (name, taken[name])  # the branches were reached
