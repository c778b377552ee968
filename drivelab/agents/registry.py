"""``--algo`` names → agents, with the action kinds each can take."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from drivelab.errors import UsageError


@dataclass(frozen=True)
class AlgoSpec:
    """A registered algorithm.

    :param build: (algo, env, seed, hyperparams, log_dir) → a new agent.
    :param load: (algo, path, env or None) → a saved agent.
    :param action_kinds: action adapters it accepts.
    :param sb3_replay: the agent has an SB3 replay buffer worth checkpointing.
    """

    name: str
    description: str
    action_kinds: tuple[str, ...]
    build: Callable
    load: Callable
    sb3_replay: bool = False


def _registry() -> dict[str, AlgoSpec]:
    from drivelab.agents.sb3 import build_sb3, load_sb3

    discrete, continuous = ("meta", "grid"), ("continuous", "target_speed")
    everything = discrete + continuous
    return {
        "dqn": AlgoSpec("dqn", "stable-baselines3 DQN", discrete, build_sb3, load_sb3, sb3_replay=True),
        "ppo": AlgoSpec("ppo", "stable-baselines3 PPO", everything, build_sb3, load_sb3),
        "a2c": AlgoSpec("a2c", "stable-baselines3 A2C", everything, build_sb3, load_sb3),
        "sac": AlgoSpec("sac", "stable-baselines3 SAC", continuous, build_sb3, load_sb3, sb3_replay=True),
    }


ALGO_NAMES = ("dqn", "ppo", "a2c", "sac")


def get_algo(name: str) -> AlgoSpec:
    """The algorithm called ``name``, or a UsageError listing the known ones."""
    registry = _registry()
    if name not in registry:
        raise UsageError(f"unknown algorithm {name!r} (choose from {', '.join(registry)})")
    return registry[name]


def check_combination(algo: str, action: str) -> AlgoSpec:
    """Fail before training when ``algo`` cannot take ``action``."""
    spec = get_algo(algo)
    if action not in spec.action_kinds:
        raise UsageError(
            f"algorithm {algo!r} cannot take {action!r} actions (it takes {', '.join(spec.action_kinds)})"
        )
    return spec
