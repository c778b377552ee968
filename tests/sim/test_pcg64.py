"""The compiled PCG64 draws numpy's numbers: seeded as gymnasium's ``np_random``, same order."""

import numpy as np
import pytest
from gymnasium.utils import seeding

from drivelab.sim.core import pcg64


@pytest.mark.parametrize("seed", [0, 1, 42, 2**31 - 2, 2**40 + 7])
def test_seeded_state_is_numpys(seed):
    state = pcg64.seeded_states([seed])[0]
    expected = seeding.np_random(seed)[0].bit_generator.state["state"]
    assert (int(state[pcg64.STATE_HI]) << 64) | int(state[pcg64.STATE_LO]) == expected["state"]
    assert (int(state[pcg64.INC_HI]) << 64) | int(state[pcg64.INC_LO]) == expected["inc"]


@pytest.mark.parametrize("seed", [3, 2024])
def test_mixed_draws_follow_numpys_generator(seed):
    """integers(0, n) (32-bit buffered Lemire, n = 1 draws nothing), uniform and raw 64-bit
    outputs interleaved at random give numpy's numbers exactly."""
    generator, _ = seeding.np_random(seed)
    state = pcg64.seeded_states([seed])[0]
    choose = np.random.default_rng(seed + 1)
    for _ in range(3000):
        kind = choose.integers(3)
        if kind == 0:
            n = int(choose.choice([1, 2, 3, 7, 1000, 2**31, 2**32 - 1]))
            assert pcg64.bounded_int(state, n) == generator.integers(0, n)
        elif kind == 1:
            low, high = choose.uniform(-5, 5), choose.uniform(5, 50)
            assert pcg64.uniform(state, low, high) == generator.uniform(low, high)
        else:
            assert pcg64.next_uint64(state) == generator.bit_generator.random_raw()


def test_seed_sequence_hash_is_numpys_for_many_seeds():
    large = np.random.default_rng(0).integers(0, 2**62, 200)
    seeds = np.concatenate([np.arange(50), large, [2**32 - 1, 2**32]])
    states = pcg64.seeded_states(seeds)
    for seed, state in zip(seeds, states, strict=True):
        expected = np.random.PCG64(np.random.SeedSequence(int(seed))).state["state"]
        assert (int(state[pcg64.STATE_HI]) << 64) | int(state[pcg64.STATE_LO]) == expected["state"], seed
        assert (int(state[pcg64.INC_HI]) << 64) | int(state[pcg64.INC_LO]) == expected["inc"], seed
    with pytest.raises(ValueError, match="seeds must be >= 0"):
        pcg64.seeded_states([-1])


def test_state_round_trips_through_numpy():
    rng = np.random.default_rng(7)
    rng.integers(10, size=3)  # leaves half a 64-bit output buffered
    words = pcg64.state_of(rng)
    expected = [rng.integers(0, 17) for _ in range(5)] + [rng.uniform(2.0, 3.0)]
    drawn = [pcg64.bounded_int(words, 17) for _ in range(5)] + [pcg64.uniform(words, 2.0, 3.0)]
    assert drawn == expected
    other = np.random.default_rng(0)
    pcg64.set_state(other, words)
    assert other.integers(0, 1000, size=4).tolist() == rng.integers(0, 1000, size=4).tolist()


@pytest.mark.parametrize("seed", [5, 77])
def test_standard_exponential_inv_is_numpys(seed):
    """standard_exponential(method="inv") gives numpy's bits, interleaved with integers(0, n) (which
    leaves half a 64-bit output buffered: the exponential draw must not touch the buffer) and
    uniform draws, after a state transfer from a generator that has drawn already."""
    generator = np.random.default_rng(seed)
    generator.integers(0, 10, size=int(seed % 3))
    state = pcg64.state_of(generator)
    choose = np.random.default_rng(seed + 1)
    exponentials = 0
    for _ in range(20000):
        kind = choose.integers(4)
        if kind <= 1:
            assert pcg64.standard_exponential_inv(state) == generator.standard_exponential(method="inv")
            exponentials += 1
        elif kind == 2:
            n = int(choose.choice([2, 5, 31, 2**31]))
            assert pcg64.bounded_int(state, n) == generator.integers(0, n)
        else:
            assert pcg64.uniform(state, 0.0, 40.0) == generator.uniform(0.0, 40.0)
    assert exponentials > 9000
    after = np.random.default_rng(0)
    pcg64.set_state(after, state)
    assert after.bit_generator.state == generator.bit_generator.state


def test_standard_exponential_inv_covers_its_range():
    """Many draws straight from one stream: every value equal, including the tail (U near 1) and
    values near 0 (U near 0), where -log(1 - U) loses the most bits."""
    generator = np.random.default_rng(123)
    state = pcg64.state_of(generator)
    ours = np.array([pcg64.standard_exponential_inv(state) for _ in range(200000)])
    expected = generator.standard_exponential(200000, method="inv")
    assert np.array_equal(ours, expected)
    assert ours.min() < 1e-4 and ours.max() > 10.0
