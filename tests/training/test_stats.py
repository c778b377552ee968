"""Statistics over seeds: bootstrap intervals and IQM against hand-computed values."""

import math

import numpy as np
import pytest

from drivelab.training.stats import bootstrap_ci, interquartile_mean, summarize


def test_iqm_cuts_a_quarter_from_each_end():
    # sorted 1..7, 100: cut two from each end, mean of 3, 4, 5, 6
    assert interquartile_mean([1, 2, 3, 4, 100, 5, 6, 7]) == pytest.approx(4.5)
    assert interquartile_mean([10, 0, 3, 5]) == pytest.approx(4.0)  # mean of 3 and 5
    assert interquartile_mean([1, 2, 6]) == pytest.approx(3.0)  # fewer than 4 values: the mean
    assert math.isnan(interquartile_mean([]))


def test_bootstrap_two_values_spans_both():
    # resampled means of (0, 1): 0 w.p. 1/4, 0.5 w.p. 1/2, 1 w.p. 1/4 -> 5 % and 95 % quantiles 0 and 1
    assert bootstrap_ci([0.0, 1.0], seed=0) == (0.0, 1.0)


def test_bootstrap_three_values_by_hand():
    # resampled mean of (0, 0, 1) is k/3 with k ~ Binomial(3, 1/3):
    # P(k=0) = 8/27 = 0.296 > 0.05, so the 5 % quantile is 0;
    # P(k<=1) = 20/27 = 0.741 < 0.95 <= P(k<=2) = 26/27 = 0.963, so the 95 % quantile is 2/3.
    low, high = bootstrap_ci([0.0, 0.0, 1.0], confidence=0.90, seed=0)
    assert low == 0.0
    assert high == pytest.approx(2 / 3)
    # an 80 % interval: P(k=0) = 0.296 > 0.10 and P(k<=1) = 0.741 < 0.90 <= 0.963
    assert bootstrap_ci([0.0, 0.0, 1.0], confidence=0.80, seed=0) == (0.0, pytest.approx(2 / 3))


def test_bootstrap_is_seeded_and_close_to_normal_theory():
    values = np.random.default_rng(7).normal(10.0, 2.0, size=200)
    first = bootstrap_ci(values, seed=3)
    assert bootstrap_ci(values, seed=3) == first
    assert bootstrap_ci(values, seed=4) != first
    half_width = 1.6449 * values.std(ddof=1) / math.sqrt(values.size)  # z(0.95) * standard error
    assert first[0] == pytest.approx(values.mean() - half_width, abs=0.05)
    assert first[1] == pytest.approx(values.mean() + half_width, abs=0.05)


def test_degenerate_inputs():
    assert bootstrap_ci([3.0, 3.0, 3.0]) == (3.0, 3.0)
    low, high = bootstrap_ci([5.0])
    assert math.isnan(low) and math.isnan(high)


def test_summarize_skips_missing_values():
    s = summarize([0.0, None, 0.0, float("nan"), 1.0])
    assert s.n == 3
    assert s.mean == pytest.approx(1 / 3)
    assert (s.ci_low, s.ci_high) == (0.0, pytest.approx(2 / 3))
    assert s.iqm == pytest.approx(1 / 3)
    assert summarize([None]).n == 0


def test_equal_values_summarize_exactly():
    s = summarize([0.95, 0.95, 0.95])  # np.mean gives 0.9499999999999998
    assert (s.mean, s.ci_low, s.ci_high, s.iqm) == (0.95, 0.95, 0.95, 0.95)


def test_a_band_is_each_steps_own_interval_bit_for_bit():
    """Runs × steps in one call (compare's learning-curve bands): each step's interval is the one
    its column gives alone, to the last bit, a constant step included."""
    values = np.random.default_rng(5).normal(size=(8, 6))
    values[:, 2] = 0.95
    low, high = bootstrap_ci(values, confidence=0.9, resamples=500, seed=1)
    columns = [bootstrap_ci(values[:, i], confidence=0.9, resamples=500, seed=1) for i in range(6)]
    assert list(zip(low.tolist(), high.tolist(), strict=True)) == columns
    assert (low[2], high[2]) == (0.95, 0.95)
