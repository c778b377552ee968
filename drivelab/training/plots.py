"""Plots of a run directory (matplotlib, written as PNG)."""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

from drivelab.training.safe_files import replacing


def _read_csv(path: Path, skip_comment: bool = False) -> list[dict]:
    if not path.is_file():
        return []
    with path.open() as handle:
        lines = [line for line in handle if not (skip_comment and line.startswith("#"))]
    return list(csv.DictReader(lines))


def plot_learning_curve(run_dir: str | Path) -> Path:
    """learning_curve.png: training episode returns (raw and smoothed) and evaluation returns."""
    run_dir = Path(run_dir)
    episodes = _read_csv(run_dir / "monitor.csv", skip_comment=True)
    evaluations = _read_csv(run_dir / "evaluations.csv")
    fig = Figure(figsize=(7, 4), dpi=100)
    ax = fig.subplots()
    if episodes:
        returns = np.array([float(row["r"]) for row in episodes])
        steps = np.cumsum([int(row["l"]) for row in episodes])
        ax.plot(steps, returns, color="tab:blue", alpha=0.25, lw=1, label="training episode")
        window = max(1, min(20, len(returns) // 5))
        smooth = np.convolve(returns, np.ones(window) / window, mode="valid")
        ax.plot(steps[window - 1 :], smooth, color="tab:blue", lw=2, label=f"training (mean of {window})")
    if evaluations:
        steps = np.array([int(row["step"]) for row in evaluations])
        mean = np.array([float(row["mean_return"]) for row in evaluations])
        std = np.array([float(row["std_return"]) for row in evaluations])
        ax.plot(steps, mean, "o-", color="tab:orange", label="evaluation (mean ± std)")
        ax.fill_between(steps, mean - std, mean + std, color="tab:orange", alpha=0.2)
    ax.set_xlabel("environment steps")
    ax.set_ylabel("episode return")
    ax.set_title(run_dir.name)
    ax.grid(alpha=0.3)
    if episodes or evaluations:
        ax.legend(loc="best", fontsize=8)
    path = run_dir / "learning_curve.png"
    fig.tight_layout()
    # written whole or not at all: a run killed while drawing it has none, and a sweep's re-run
    # draws it (``sweep.cell_action``: "finish"), instead of keeping a cut-off image
    with replacing(path, run_dir / "learning_curve.tmp.png") as temporary:
        fig.savefig(temporary)
    return path
