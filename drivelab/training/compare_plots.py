"""Plots of a comparison: learning curves with bands, and bar charts of final metrics."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

from drivelab.training.metrics import labels
from drivelab.training.stats import bootstrap_ci, percent

BAR_METRICS = labels(
    ("mean_return", "success_rate", "crash_rate", "mean_speed_mps", "mean_distance_km", "collisions_per_km")
)
CURVE_RESAMPLES = 2_000  # enough for a drawn band


def short_labels(keys: list[tuple[str, ...]]) -> list[str]:
    """Group names keeping only the fields that differ between groups (the algorithm if none do)."""
    varying = [i for i in range(len(keys[0])) if len({k[i] for k in keys}) > 1] if keys else []
    return [" · ".join(k[i] for i in varying or [0]) for k in keys]


def aligned_curves(curves: list[list[tuple[int, float]]]) -> tuple[np.ndarray, np.ndarray]:
    """Put runs evaluated at different steps on one grid: every evaluation step of any run between
    the first step every run has and the last step all runs reached, each run interpolated linearly,
    never extrapolated. Returns (steps, values of shape runs × steps)."""
    curves = [c for c in curves if c]
    if not curves:
        return np.zeros(0, dtype=int), np.zeros((0, 0))
    start, reach = max(c[0][0] for c in curves), min(c[-1][0] for c in curves)
    steps = np.array(sorted({s for c in curves for s, _ in c if start <= s <= reach}), dtype=int)
    if steps.size == 0:
        return steps, np.zeros((len(curves), 0))
    values = np.array([np.interp(steps, [s for s, _ in c], [v for _, v in c]) for c in curves])
    return steps, values


def plot_learning_curves(groups: dict, path: Path, confidence: float) -> Path:
    """Mean evaluation return over seeds against steps, with a bootstrap band per step."""
    fig = Figure(figsize=(8, 4.5), dpi=100)
    ax = fig.subplots()
    labels = short_labels(list(groups))
    for index, runs in enumerate(groups.values()):
        steps, values = aligned_curves([list(r.curve) for r in runs])
        if steps.size == 0:
            continue
        color = f"C{index % 10}"
        ax.plot(
            steps, values.mean(axis=0), "o-", ms=3, color=color, label=f"{labels[index]} (n={len(values)})"
        )
        if len(values) >= 2:
            low, high = bootstrap_ci(values, confidence, CURVE_RESAMPLES)  # one interval per step
            ax.fill_between(steps, low, high, color=color, alpha=0.2)
    ax.set_xlabel("environment steps")
    ax.set_ylabel("evaluation return (mean over seeds)")
    ax.set_title(f"learning curves, {percent(confidence)} % bootstrap bands")
    ax.grid(alpha=0.3)
    if groups:
        ax.legend(loc="best", fontsize=7)
    fig.tight_layout()
    fig.savefig(path)
    return path


def plot_metric_bars(groups: dict, summaries: dict, path: Path, confidence: float) -> Path:
    """One panel per main metric: bar = mean, whisker = bootstrap interval, diamond = IQM, dots = seeds."""
    keys = list(groups)
    fig = Figure(figsize=(12, 7), dpi=100)
    axes = fig.subplots(2, 3)
    positions = np.arange(len(keys))
    for ax, (metric, label) in zip(axes.flat, BAR_METRICS.items(), strict=True):
        for i, key in enumerate(keys):
            s = summaries[key][metric]
            if s.n == 0:
                continue
            color = f"C{i % 10}"
            ax.bar(i, s.mean, color=color, alpha=0.6)
            if not math.isnan(s.ci_low):
                below, above = max(s.mean - s.ci_low, 0.0), max(s.ci_high - s.mean, 0.0)  # float rounding
                ax.errorbar(i, s.mean, yerr=[[below], [above]], color="black", capsize=4)
            ax.plot(i, s.iqm, "D", color="black", ms=4)
            seeds = [r.final[metric] for r in groups[key] if r.final[metric] is not None]
            ax.plot(np.full(len(seeds), i) + 0.15, seeds, ".", color="dimgray", ms=5)
        ax.set_title(label, fontsize=9)
        ax.set_xticks(positions, short_labels(keys), rotation=30, ha="right", fontsize=7)
        ax.grid(alpha=0.3, axis="y")
    fig.suptitle(
        f"final evaluation: bar mean, whisker {percent(confidence)} % bootstrap CI, diamond IQM, dots seeds",
        fontsize=9,
    )
    fig.tight_layout()
    fig.savefig(path)
    return path
