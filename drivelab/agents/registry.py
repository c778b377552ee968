"""``--algo`` names → agents, with the action kinds each can take."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from drivelab.errors import UsageError


@dataclass(frozen=True)
class AlgoSpec:
    """A registered algorithm.

    :param build: (algo, env, seed, hyperparams, log_dir) → a new agent.
    :param load: (algo, path, env or None, hyperparams=None, seed=None) → a saved agent; nothing in
        the file is unpickled. ``hyperparams`` and ``seed`` are the run config's (the file's own when
        None, and they must agree); SB3 models are rebuilt from them and need ``env``.
    :param action_kinds: action adapters it accepts.
    :param sb3_replay: the agent has a replay buffer worth checkpointing (``replay_buffer.observations``,
        ``save_replay_buffer``, ``load_replay_buffer``, as SB3's off-policy models).
    :param observation_kinds: observation kinds it can read (``networks.observation_kind``):
        "vector", "image" (channels-first uint8), "image+vector" (a Dict of both), "other".
    :param multi_env: it trains on a vector env of several worlds (``n_envs`` > 1).
    :param observation_check: observation space → why the agent cannot read it (None: it can),
        for agents that need particular sensors.
    """

    name: str
    description: str
    action_kinds: tuple[str, ...]
    build: Callable
    load: Callable
    sb3_replay: bool = False
    observation_kinds: tuple[str, ...] = ("vector", "image", "image+vector", "other")
    multi_env: bool = False
    observation_check: Callable | None = None


def build_own(algo: str, env, seed: int, hyperparams: dict, log_dir) -> object:
    """A fresh agent of drivelab's own (``dueling_ddqn``, ``a2c_own``, ``ppo_own``)."""
    return own_classes()[algo](env.observation_space, env.action_space, seed, hyperparams, env)


def load_own(algo: str, path, env, hyperparams: dict | None = None, seed: int | None = None) -> object:
    """A saved agent of drivelab's own (``env`` may be None for acting only)."""
    return own_classes()[algo].load(path, env, hyperparams, seed)


def own_classes() -> dict[str, type]:
    from drivelab.agents.a2c import OwnA2C
    from drivelab.agents.dueling_ddqn import DuelingDoubleDQN
    from drivelab.agents.expert import RuleBasedExpert
    from drivelab.agents.ppo import OwnPPO
    from drivelab.agents.rlad.sac import RLAD, DrQ

    return {
        "dueling_ddqn": DuelingDoubleDQN,
        "a2c_own": OwnA2C,
        "ppo_own": OwnPPO,
        "rlad": RLAD,
        "drq": DrQ,
        "expert": RuleBasedExpert,
    }


def _registry() -> dict[str, AlgoSpec]:
    from drivelab.agents.qlearning import build_qlearning, load_qlearning
    from drivelab.agents.rlad.sac import observation_error
    from drivelab.agents.sb3 import build_sb3, load_sb3

    discrete, continuous = ("meta", "grid"), ("continuous", "target_speed")
    everything = discrete + continuous
    readable = ("vector", "image", "image+vector")
    return {
        "dqn": AlgoSpec(
            "dqn", "stable-baselines3 DQN", discrete, build_sb3, load_sb3, sb3_replay=True, multi_env=True
        ),
        "ppo": AlgoSpec("ppo", "stable-baselines3 PPO", everything, build_sb3, load_sb3, multi_env=True),
        "a2c": AlgoSpec("a2c", "stable-baselines3 A2C", everything, build_sb3, load_sb3, multi_env=True),
        "sac": AlgoSpec(
            "sac", "stable-baselines3 SAC", continuous, build_sb3, load_sb3, sb3_replay=True, multi_env=True
        ),
        "dueling_ddqn": AlgoSpec(
            "dueling_ddqn",
            "drivelab's Dueling Double DQN, prioritised replay (seed 003)",
            discrete,
            build_own,
            load_own,
            sb3_replay=True,
            observation_kinds=("vector",),
        ),
        "a2c_own": AlgoSpec(
            "a2c_own",
            "drivelab's A2C, tanh-Gaussian, seed 003's CNN / fusion network",
            ("continuous",),
            build_own,
            load_own,
            observation_kinds=readable,
        ),
        "ppo_own": AlgoSpec(
            "ppo_own",
            "drivelab's PPO, tanh-Gaussian, seed 003's CNN / fusion network",
            ("continuous",),
            build_own,
            load_own,
            observation_kinds=readable,
        ),
        "rlad": AlgoSpec(
            "rlad",
            "drivelab's RLAD: SAC from pixels, A-LIX, DrQ shifts, WayConv1D, traffic-light loss (seed 000)",
            continuous,
            build_own,
            load_own,
            sb3_replay=True,
            observation_check=observation_error,
        ),
        "drq": AlgoSpec(
            "drq",
            "DrQ baseline of seed 000: rlad without A-LIX and the traffic-light loss, MLP waypoints",
            continuous,
            build_own,
            load_own,
            sb3_replay=True,
            observation_check=observation_error,
        ),
        "qlearning": AlgoSpec(
            "qlearning",
            "tabular Q-learning over discrete states (seed 004): line, lane, ttc_grid",
            ("seed_line", "seed_lane", "meta", "grid"),
            build_qlearning,
            load_qlearning,
            observation_kinds=("other",),  # a Discrete state; the builder checks it is one
        ),
        "expert": AlgoSpec(
            "expert",
            "rule-based town driver on waypoints + privileged affordances (learns nothing)",
            ("target_speed",),
            build_own,
            load_own,
        ),
    }


ALGO_NAMES = (
    "dqn", "ppo", "a2c", "sac", "dueling_ddqn", "a2c_own", "ppo_own", "rlad", "drq", "qlearning", "expert",
)  # fmt: skip


def get_algo(name: str) -> AlgoSpec:
    """The algorithm called ``name``, or a UsageError listing the known ones."""
    registry = _registry()
    if name not in registry:
        raise UsageError(f"unknown algorithm {name!r} (choose from {', '.join(registry)})")
    return registry[name]


def check_combination(algo: str, action: str, observation_space=None) -> AlgoSpec:
    """Fail before training when ``algo`` cannot take ``action`` or read ``observation_space``."""
    spec = get_algo(algo)
    if action not in spec.action_kinds:
        raise UsageError(
            f"algorithm {algo!r} cannot take {action!r} actions (it takes {', '.join(spec.action_kinds)})"
        )
    if observation_space is not None:
        from drivelab.agents.networks import observation_kind

        kind = observation_kind(observation_space)
        if kind not in spec.observation_kinds:
            raise UsageError(
                f"algorithm {algo!r} cannot read {kind!r} observations "
                f"(it reads {', '.join(spec.observation_kinds)})"
            )
        problem = spec.observation_check(observation_space) if spec.observation_check else None
        if problem is not None:
            raise UsageError(f"algorithm {algo!r} {problem}")
    return spec
