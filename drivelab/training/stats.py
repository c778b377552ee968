"""Statistics over seeds: mean, percentile-bootstrap confidence interval, interquartile mean, as
rliable (Agarwal et al., 2021) recommends for a handful of seeds."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy import stats

CONFIDENCE = 0.90
RESAMPLES = 10_000


@dataclass(frozen=True)
class Summary:
    """One metric of one group of runs.

    :param n: number of runs with a value (runs that report None for the metric are left out).
    :param mean: mean over runs.
    :param ci_low: lower end of the bootstrap confidence interval of the mean (nan when n < 2).
    :param ci_high: upper end (nan when n < 2).
    :param iqm: interquartile mean over runs.
    """

    n: int
    mean: float
    ci_low: float
    ci_high: float
    iqm: float


def percent(confidence: float) -> str:
    """A confidence level as the percentage reports write, unrounded: 0.9 → "90", 0.995 → "99.5"."""
    return f"{confidence * 100:g}"


def interquartile_mean(values: Sequence[float]) -> float:
    """Mean of the values left after cutting ``floor(n / 4)`` from each end of the sorted list:
    rliable's IQM; with fewer than 4 values it equals the mean."""
    values = np.asarray(values, dtype=float)
    if values.size == 0:
        return math.nan
    return float(stats.trim_mean(values, proportiontocut=0.25))


def bootstrap_ci(
    values: Sequence[float] | np.ndarray,
    confidence: float = CONFIDENCE,
    resamples: int = RESAMPLES,
    seed: int = 0,
):
    """Percentile-bootstrap confidence interval of the mean (``scipy.stats.bootstrap``); ``(nan,
    nan)`` for fewer than two values.

    :param values: one value per run (seed); or runs × steps (learning curves): then two arrays,
        each step's interval the one its column alone gives.
    :param confidence: coverage of the interval, 0.90 for a 90 % interval.
    :param resamples: number of bootstrap resamples.
    :param seed: seed of the resampling generator."""
    values = np.asarray(values, dtype=float)
    if len(values) < 2:
        return math.nan, math.nan
    result = stats.bootstrap(
        (values,),
        # summed as a single step's resamples are (a contiguous copy): a step's interval, bit for bit
        lambda resamples, axis: np.mean(np.ascontiguousarray(resamples), axis=axis),
        confidence_level=confidence,
        n_resamples=resamples,
        method="percentile",
        axis=0,
        vectorized=True,
        rng=np.random.default_rng(seed),
    )
    same = np.all(values == values[0], axis=0)  # every resample has that mean, without float rounding
    low, high = (np.where(same, values[0], end) for end in result.confidence_interval)
    return (float(low), float(high)) if values.ndim == 1 else (low, high)


def summarize(values: Sequence[float | None], confidence: float = CONFIDENCE, seed: int = 0) -> Summary:
    """Mean, bootstrap interval and IQM of one metric over runs, skipping missing (None/nan) values."""
    kept = [float(v) for v in values if v is not None and not math.isnan(float(v))]
    if not kept:
        return Summary(0, math.nan, math.nan, math.nan, math.nan)
    low, high = bootstrap_ci(kept, confidence=confidence, seed=seed)
    if all(v == kept[0] for v in kept):  # exact, without the rounding of a float mean
        return Summary(len(kept), kept[0], low, high, kept[0])
    return Summary(len(kept), float(np.mean(kept)), low, high, interquartile_mean(kept))
