"""The learning loops' counters that a saved model (``sb3.json``) or a resume state carries, and
what each may hold: they are set on the model as attributes, so a file (maybe someone else's) may
name only these, each with a value of its kind, and cannot set any other attribute.
"""

from __future__ import annotations

from typing import Any

from drivelab.errors import is_number

MAX_COUNT = 2**53  # far beyond any run; a float of it is still exact

# what each kind may hold; "progress" is SB3's remaining progress, below 0 when the last rollout
# overshot the budget; "state" is Q-learning's current state (None between episodes)
MEANING = {
    "count": f"a whole number from 0 to {MAX_COUNT}",
    "fraction": "a number from 0 to 1",
    "progress": "a finite number at most 1",
    "return": "a finite number",
    "state": f"null or a whole number from 0 to {MAX_COUNT}",
}
KINDS = {
    "num_timesteps": "count", "_n_updates": "count", "_episode_num": "count", "_n_calls": "count",
    "_total_timesteps": "count", "_num_timesteps_at_start": "count", "_episode_length": "count",
    "exploration_rate": "fraction", "epsilon": "fraction",
    "_current_progress_remaining": "progress",
    "_episode_return": "return",
    "_obs": "state",
}  # fmt: skip


def is_count(value: Any) -> bool:
    """Whether ``value`` is a whole number from 0 to ``MAX_COUNT`` (not a bool)."""
    return isinstance(value, int) and not isinstance(value, bool) and 0 <= value <= MAX_COUNT


def _fits(kind: str, value: Any) -> bool:
    if kind == "count":
        return is_count(value)
    if kind == "state":
        return value is None or is_count(value)
    if not is_number(value):
        return False
    if kind == "fraction":
        return 0.0 <= value <= 1.0
    return kind == "return" or value <= 1.0  # "progress"


def check_counters(counters: Any) -> dict[str, Any]:
    """``counters`` when it maps names of ``KINDS`` to values of their kind; else a ValueError
    naming the first name or value that does not."""
    if not isinstance(counters, dict):
        raise ValueError(f"the counters are a {type(counters).__name__}, not a mapping")
    for name, value in counters.items():
        if name not in KINDS:
            raise ValueError(f"{name!r} is not a counter of a learning loop")
        if not _fits(KINDS[name], value):
            raise ValueError(f"counter {name!r} holds {value!r}, not {MEANING[KINDS[name]]}")
    return counters
