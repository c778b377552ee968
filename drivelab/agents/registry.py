"""``--algo`` names → agents, with the action kinds each can take: ``ALGORITHMS``, the one table
every other list of algorithms derives from. Implementations are named by entry point
(``"module:attribute"``) and imported when first used, so listing the algorithms imports neither
torch nor stable-baselines3.
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass

from drivelab.errors import UsageError

FAMILIES = {  # how a family's agents are built and loaded: (builder, loader) entry points
    "sb3": ("drivelab.agents.sb3:build_sb3", "drivelab.agents.sb3:load_sb3"),
    "own": ("drivelab.agents.registry:build_own", "drivelab.agents.registry:load_own"),
    "qlearning": ("drivelab.agents.qlearning:build_qlearning", "drivelab.agents.qlearning:load_qlearning"),
}


def load_entry_point(entry_point: str):
    """The object an entry point ``"package.module:attribute"`` names (its module imported)."""
    module, _, attribute = entry_point.partition(":")
    return getattr(importlib.import_module(module), attribute)


@dataclass(frozen=True)
class AlgoSpec:
    """A registered algorithm.

    :param implementation: entry point of its agent class (an SB3 class for the ``sb3`` family).
    :param family: "sb3", "own" or "qlearning": which builder (algo, env, seed, hyperparams,
        log_dir) and loader (algo, path, env or None, hyperparams=None, seed=None) make its agents
        (``FAMILIES``); loaders unpickle nothing.
    :param action_kinds: action adapters it accepts.
    :param sb3_replay: the agent may have a replay buffer worth checkpointing (``replay_buffer.observations``,
        ``save_replay_buffer``, ``load_replay_buffer``, as SB3's off-policy models; the on-policy
        agents' self-imitation replay, ``None`` without ``sil_updates``).
    :param observation_kinds: observation kinds it can read (``networks.observation_kind``):
        "vector", "image" (channels-first uint8), "image+vector" (a Dict of both), "other".
    :param multi_env: it trains on a vector env of several worlds (``n_envs`` > 1).
    :param observation_check: entry point of a function: observation space → why the agent cannot
        read it (None: it can), for agents that need particular sensors.
    :param on_policy: it collects a whole rollout, ``n_steps`` from each world, before it looks at
        the step budget again (``config.steps_per_update``).
    """

    name: str
    description: str
    action_kinds: tuple[str, ...]
    implementation: str
    family: str
    sb3_replay: bool = False
    observation_kinds: tuple[str, ...] = ("vector", "image", "image+vector", "other")
    multi_env: bool = False
    observation_check: str | None = None
    on_policy: bool = False

    def agent_class(self) -> type:
        """The class of its agents (importing its module)."""
        return load_entry_point(self.implementation)

    def build(self, algo: str, env, seed: int, hyperparams: dict, log_dir) -> object:
        """A fresh agent for ``env``."""
        return load_entry_point(FAMILIES[self.family][0])(algo, env, seed, hyperparams, log_dir)

    def load(self, algo: str, path, env, hyperparams: dict | None = None, seed: int | None = None) -> object:
        """A saved agent (``env`` may be None for acting only, except for SB3 models)."""
        return load_entry_point(FAMILIES[self.family][1])(algo, path, env, hyperparams, seed)


def build_own(algo: str, env, seed: int, hyperparams: dict, log_dir) -> object:
    """A fresh agent of drivelab's own (``dueling_ddqn``, ``a2c_own``, ``ppo_own``, ...)."""
    return get_algo(algo).agent_class()(env.observation_space, env.action_space, seed, hyperparams, env)


def load_own(algo: str, path, env, hyperparams: dict | None = None, seed: int | None = None) -> object:
    """A saved agent of drivelab's own (``env`` may be None for acting only)."""
    return get_algo(algo).agent_class().load(path, env, hyperparams, seed)


_DISCRETE, _CONTINUOUS = ("meta", "grid"), ("continuous", "target_speed")
_READABLE = ("vector", "image", "image+vector")
# what each observation kind is, by the sensors that give it (an error names those it reads)
_KIND_EXAMPLES = {
    "vector": "vectors (--obs kinematics, lidar, ego_state, waypoints,measurements, ...)",
    "image": "one channels-first image (--obs topdown)",
    "image+vector": "one channels-first image with vectors (--obs topdown,measurements)",
    "other": "any other observation",
}
_RLAD_CHECK = "drivelab.agents.rlad.sac:observation_error"

ALGORITHMS: dict[str, AlgoSpec] = {
    spec.name: spec
    for spec in (
        AlgoSpec("dqn", "stable-baselines3 DQN", _DISCRETE, "drivelab.agents.sb3:DrivelabDQN", "sb3",
                 sb3_replay=True, multi_env=True),
        AlgoSpec("ppo", "stable-baselines3 PPO", _DISCRETE + _CONTINUOUS, "drivelab.agents.sb3:DrivelabPPO",
                 "sb3", multi_env=True, on_policy=True),
        AlgoSpec("a2c", "stable-baselines3 A2C", _DISCRETE + _CONTINUOUS, "drivelab.agents.sb3:DrivelabA2C",
                 "sb3", multi_env=True, on_policy=True),
        AlgoSpec("sac", "stable-baselines3 SAC", _CONTINUOUS, "drivelab.agents.sb3:DrivelabSAC", "sb3",
                 sb3_replay=True, multi_env=True),
        AlgoSpec("dueling_ddqn", "Dueling Double DQN, prioritised replay (the MetaDrive study)", _DISCRETE,
                 "drivelab.agents.dueling_ddqn:DuelingDoubleDQN", "own", sb3_replay=True,
                 observation_kinds=("vector",), multi_env=True),
        AlgoSpec("a2c_own", "drivelab's A2C on the fast on-policy trainer (categorical, tanh-Gaussian or "
                 "Beta; MLP, the MetaDrive study's CNN / fusion network)", _DISCRETE + _CONTINUOUS,
                 "drivelab.agents.a2c:OwnA2C", "own", sb3_replay=True, observation_kinds=_READABLE,
                 multi_env=True, on_policy=True),
        AlgoSpec("ppo_own", "drivelab's PPO on the fast on-policy trainer (categorical, tanh-Gaussian or "
                 "Beta; MLP, the MetaDrive study's CNN / fusion network)", _DISCRETE + _CONTINUOUS,
                 "drivelab.agents.ppo:OwnPPO", "own", sb3_replay=True, observation_kinds=_READABLE,
                 multi_env=True, on_policy=True),
        AlgoSpec("rlad", "drivelab's RLAD: SAC from pixels, A-LIX, DrQ shifts, WayConv1D, traffic-light loss "
                 "(the RLAD paper)", _CONTINUOUS, "drivelab.agents.rlad.sac:RLAD", "own", sb3_replay=True,
                 observation_check=_RLAD_CHECK),
        AlgoSpec("drq", "DrQ baseline of the RLAD paper: rlad without A-LIX and the traffic-light loss, MLP "
                 "waypoints", _CONTINUOUS, "drivelab.agents.rlad.sac:DrQ", "own", sb3_replay=True,
                 observation_check=_RLAD_CHECK),
        AlgoSpec("qlearning", "tabular Q-learning on discrete states (the CARLA study): line, lane, ttc_grid",
                 ("seed_line", "seed_lane", "meta", "grid"), "drivelab.agents.qlearning:QLearning",
                 "qlearning", observation_check="drivelab.agents.qlearning:observation_error"),
        AlgoSpec("expert", "rule-based driver (town, racetrack, block maps) on waypoints + privileged "
                 "affordances (learns nothing)",
                 ("target_speed",), "drivelab.agents.expert:RuleBasedExpert", "own", multi_env=True),
        AlgoSpec("bc", "behaviour cloning of the rule-based expert on the learner's own --obs "
                 "(tanh-Gaussian, the MetaDrive study's networks)", ("target_speed",),
                 "drivelab.agents.bc:BehaviourCloning", "own", sb3_replay=True, observation_kinds=_READABLE,
                 multi_env=True),
        AlgoSpec("dagger", "DAgger: the learner drives (beta-mixture with the rule-based expert), the expert "
                 "labels, the data aggregate", ("target_speed",), "drivelab.agents.dagger:DAgger", "own",
                 sb3_replay=True, observation_kinds=_READABLE, multi_env=True),
    )
}  # fmt: skip

ALGO_NAMES = tuple(ALGORITHMS)


def agent_classes(family: str) -> dict[str, type]:
    """Algorithm name → agent class for every algorithm of ``family`` ("sb3", "own", "qlearning")."""
    return {name: spec.agent_class() for name, spec in ALGORITHMS.items() if spec.family == family}


def algo_of(agent_class: type) -> str:
    """The algorithm name whose agents are of ``agent_class`` (what a saved model records); found
    by entry point, so no other algorithm's module is imported."""
    entry_point = f"{agent_class.__module__}:{agent_class.__qualname__}"
    for name, spec in ALGORITHMS.items():
        if spec.implementation == entry_point:
            return name
    raise LookupError(f"{agent_class.__qualname__} is no registered algorithm's agent class")


def get_algo(name: str) -> AlgoSpec:
    """The algorithm called ``name``, or a UsageError listing the known ones."""
    if name not in ALGORITHMS:
        raise UsageError(f"unknown algorithm {name!r} (choose from {', '.join(ALGORITHMS)})")
    return ALGORITHMS[name]


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
            readable = [_KIND_EXAMPLES[k] for k in spec.observation_kinds]
            readable = ", ".join(readable[:-1]) + " or " + readable[-1] if len(readable) > 1 else readable[0]
            what = f"the observation {observation_space}" if kind == "other" else f"{kind!r} observations"
            raise UsageError(f"algorithm {algo!r} cannot read {what}; it reads {readable}")
        check = load_entry_point(spec.observation_check) if spec.observation_check else None
        problem = check(observation_space) if check else None
        if problem is not None:
            raise UsageError(f"algorithm {algo!r} {problem}")
    return spec
