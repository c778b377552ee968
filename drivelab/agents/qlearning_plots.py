"""The CARLA study's three-panel training plot (its figs. 6 and 8): ε per step, return and length per episode.

The Q-learning agent writes it into its run directory with its Q-table (``write_run_artifacts``),
so it lives beside the agent: agents do not import ``training/``.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure


def plot_qlearning(
    epsilons: np.ndarray, returns: Sequence[float], lengths: Sequence[int], path: str | Path, title: str = ""
) -> Path:
    """Write the three panels to ``path`` (PNG): ε against steps, the accumulated reward of every
    episode, and the steps of every episode (each with a moving average where there are many)."""
    fig = Figure(figsize=(7, 8), dpi=100)
    axes = fig.subplots(3, 1)
    axes[0].plot(np.arange(len(epsilons)), epsilons, color="tab:purple")
    axes[0].set(xlabel="step", ylabel="epsilon")
    episodes = np.arange(1, len(returns) + 1)
    for axis, values, label, colour in (
        (axes[1], np.asarray(returns, float), "accumulated reward", "tab:blue"),
        (axes[2], np.asarray(lengths, float), "steps per episode", "tab:green"),
    ):
        axis.plot(episodes, values, color=colour, alpha=0.35, lw=1)
        window = max(1, min(25, len(values) // 10))
        if len(values) >= window > 1:
            smooth = np.convolve(values, np.ones(window) / window, mode="valid")
            axis.plot(episodes[window - 1 :], smooth, color=colour, lw=2, label=f"mean of {window}")
            axis.legend(loc="best", fontsize=8)
        axis.set(xlabel="episode", ylabel=label)
    for axis in axes:
        axis.grid(alpha=0.3)
    if title:
        axes[0].set_title(title)
    fig.tight_layout()
    path = Path(path)
    fig.savefig(path)
    return path
