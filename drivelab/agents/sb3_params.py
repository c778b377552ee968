"""The stable-baselines3 hyper-parameters drivelab accepts, with their types and ranges:
``check_sb3_hyperparams`` validates every ``-H`` / YAML value before a model is built (SB3 checks
few: ``batch_size=0`` trains on empty batches). Keys that take Python objects or that drivelab
sets itself are refused by name; keys SB3's constructor does not have are unknown.
"""

from __future__ import annotations

import functools
import inspect
import math
from collections.abc import Callable
from dataclasses import dataclass

from drivelab.agents.base import MAX_LEARNING_RATE
from drivelab.agents.buffer_memory import check_buffer_memory, observation_bytes
from drivelab.agents.registry import get_algo
from drivelab.errors import UsageError

DEVICES = ("cpu", "cuda", "auto")


@dataclass(frozen=True)
class Param:
    """One hyper-parameter: its kind and the interval its value must lie in.

    :param kind: "int", "float", "bool", "dict" or "str".
    :param low: smallest allowed value (None: unbounded).
    :param high: largest allowed value (None: unbounded).
    :param open_low: ``low`` itself is not allowed (``learning_rate > 0``).
    :param none: None (YAML ``null``) is allowed and means SB3's "off".
    """

    kind: str
    low: float | None = None
    high: float | None = None
    open_low: bool = False
    none: bool = False

    def describe(self) -> str:
        """The allowed values in words, e.g. ``a number > 0`` or ``an integer in [1, inf)``."""
        noun = {"int": "an integer", "float": "a number", "bool": "true or false", "dict": "a mapping"}
        text = noun.get(self.kind, "a string")
        if self.low is not None and self.high is not None:
            text += f" in {'(' if self.open_low else '['}{self.low}, {self.high}]"
        elif self.low is not None:
            text += f" {'>' if self.open_low else '>='} {self.low}"
        return text + (" or null" if self.none else "")


POSITIVE = Param("float", 0, open_low=True)
LEARNING_RATE = Param("float", 0, MAX_LEARNING_RATE, open_low=True)
FRACTION = Param("float", 0, 1)
COUNT = Param("int", 1)
NON_NEGATIVE_INT = Param("int", 0)
NON_NEGATIVE = Param("float", 0)
FLAG = Param("bool")
MAPPING = Param("dict")

_COMMON = {
    "learning_rate": LEARNING_RATE,
    "gamma": FRACTION,
    "stats_window_size": COUNT,
    "policy_kwargs": MAPPING,
}
_OFF_POLICY = {
    "buffer_size": COUNT,
    "learning_starts": NON_NEGATIVE_INT,
    "batch_size": COUNT,
    "tau": Param("float", 0, 1, open_low=True),
    # -1: as many gradient steps as environment steps; 0 is refused (_check_gradient_steps)
    "gradient_steps": Param("int", -1),
    "optimize_memory_usage": FLAG,
    "n_steps": COUNT,
    "target_update_interval": COUNT,
    "replay_buffer_kwargs": MAPPING,
}
_ON_POLICY = {
    "max_grad_norm": POSITIVE,
    "n_steps": COUNT,
    "gae_lambda": FRACTION,
    "ent_coef": NON_NEGATIVE,
    "vf_coef": NON_NEGATIVE,
    "normalize_advantage": FLAG,
    "use_sde": FLAG,
    "sde_sample_freq": Param("int", -1),
    "rollout_buffer_kwargs": MAPPING,
}

PARAMS: dict[str, dict[str, Param]] = {
    "dqn": {
        **_COMMON,
        **_OFF_POLICY,
        "max_grad_norm": POSITIVE,
        "exploration_fraction": FRACTION,
        "exploration_initial_eps": FRACTION,
        "exploration_final_eps": FRACTION,
    },
    "ppo": {
        **_COMMON,
        **_ON_POLICY,
        "batch_size": COUNT,
        "n_epochs": COUNT,
        "clip_range": POSITIVE,
        "clip_range_vf": Param("float", 0, open_low=True, none=True),
        "target_kl": Param("float", 0, open_low=True, none=True),
    },
    "a2c": {**_COMMON, **_ON_POLICY, "rms_prop_eps": POSITIVE, "use_rms_prop": FLAG},
    "sac": {
        **_COMMON,
        **_OFF_POLICY,
        "use_sde": FLAG,
        "sde_sample_freq": Param("int", -1),
        "use_sde_at_warmup": FLAG,
    },
}


def _check_device(algo: str, value) -> str:
    """cpu, cuda (only where torch sees a GPU) or auto (SB3 picks: cuda when there is one)."""
    if value not in DEVICES:
        choices = ", ".join(DEVICES)
        raise UsageError(f"hyperparameter 'device' of {algo!r} must be one of {choices}, got {value!r}")
    if value == "cuda":
        import torch

        if not torch.cuda.is_available():
            raise UsageError(f"-H device=cuda for {algo!r}, but torch sees no CUDA GPU on this machine")
    return value


def _check_train_freq(algo: str, value):
    """An integer >= 1 (steps), or ``[n, "step" | "episode"]`` as SB3 takes it."""
    if isinstance(value, (list, tuple)) and len(value) == 2 and value[1] in ("step", "episode"):
        return (_check_value(algo, "train_freq", value[0], COUNT), value[1])
    return _check_value(algo, "train_freq", value, COUNT)


def _check_sac_coefficient(algo: str, key: str, value, param: Param):
    """SAC's ``ent_coef`` / ``target_entropy``: "auto" (``ent_coef`` also "auto_<initial value>")
    or a number."""
    if isinstance(value, str):
        auto, _, initial = value.partition("_")
        if auto == "auto" and (not initial or key == "ent_coef" and _is_positive_number(initial)):
            return value
        forms = "'auto', 'auto_<number>'" if key == "ent_coef" else "'auto'"
        raise UsageError(f"hyperparameter {key!r} of {algo!r} must be {forms} or a number, got {value!r}")
    return _check_value(algo, key, value, param)


def _is_positive_number(text: str) -> bool:
    try:
        return float(text) > 0
    except ValueError:
        return False


def _check_gradient_steps(algo: str, value) -> int:
    """-1 (as many gradient steps as environment steps) or >= 1: 0 would train nothing."""
    value = _check_value(algo, "gradient_steps", value, Param("int", -1))
    if value == 0:
        raise UsageError(
            f"hyperparameter 'gradient_steps' of {algo!r} must be -1 (one per environment step) or >= 1, "
            f"got 0 (no gradient step: the agent would not learn)"
        )
    return value


def _check_policy_kwargs(algo: str, value) -> dict:
    """A mapping whose ``net_arch``, when given, has positive integer layer widths: a list, or a
    mapping of lists (``pi`` / ``vf`` / ``qf``), as SB3 takes it."""
    value = _check_value(algo, "policy_kwargs", value, MAPPING)
    net_arch = value.get("net_arch")
    if net_arch is None:
        return value
    wrong = (
        f"policy_kwargs net_arch of {algo!r} must be a list of layer widths >= 1 (or pi/vf/qf lists of them)"
    )
    layers = net_arch.values() if isinstance(net_arch, dict) else [net_arch]
    for widths in layers:
        if not isinstance(widths, (list, tuple)):
            raise UsageError(f"{wrong}, got {net_arch!r}")
        for width in widths:
            if isinstance(width, bool) or not isinstance(width, int) or width < 1:
                raise UsageError(f"{wrong}, got {net_arch!r}")
    return value


SPECIAL: dict[str, Callable] = {
    "device": lambda algo, key, value: _check_device(algo, value),
    "train_freq": lambda algo, key, value: _check_train_freq(algo, value),
    "gradient_steps": lambda algo, key, value: _check_gradient_steps(algo, value),
    "policy_kwargs": lambda algo, key, value: _check_policy_kwargs(algo, value),
}
SAC_SPECIAL: dict[str, Callable] = {
    "ent_coef": lambda algo, key, value: _check_sac_coefficient(algo, key, value, POSITIVE),
    "target_entropy": lambda algo, key, value: _check_sac_coefficient(algo, key, value, Param("float")),
}


def _check_value(algo: str, key: str, value, param: Param):
    """``value`` as ``param``'s kind (an integral float becomes an int), or a UsageError."""
    wrong = UsageError(f"hyperparameter {key!r} of {algo!r} must be {param.describe()}, got {value!r}")
    if value is None:
        if param.none:
            return None
        raise wrong
    if param.kind in ("bool", "dict", "str"):
        if not isinstance(value, {"bool": bool, "dict": dict, "str": str}[param.kind]):
            raise wrong
        return value
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise wrong
    if param.kind == "int":
        if not float(value).is_integer():
            raise wrong
        value = int(value)
    else:
        value = float(value)
    too_low = param.low is not None and (value <= param.low if param.open_low else value < param.low)
    if too_low or (param.high is not None and value > param.high):
        raise wrong
    return value


def check_sb3_hyperparams(algo: str, hyperparams: dict) -> dict:
    """``hyperparams`` with every value checked against ``algo``'s declared type and range
    (integral floats as ints); an unknown, unsettable or out-of-range key is a UsageError."""
    constructor = inspect.signature(get_algo(algo).agent_class().__init__).parameters  # the installed SB3's
    declared = {key: param for key, param in PARAMS[algo].items() if key in constructor}
    special = {
        key: check
        for key, check in {**SPECIAL, **(SAC_SPECIAL if algo == "sac" else {})}.items()
        if key == "device" or key in constructor
    }
    checked = {}
    for key, value in hyperparams.items():
        if key == "features_extractor":
            checked[key] = value  # build_sb3 checks it against the observation
        elif key in special:
            checked[key] = special[key](algo, key, value)
        elif key in declared:
            checked[key] = _check_value(algo, key, value, declared[key])
        elif key in constructor:
            raise UsageError(f"hyperparameter {key!r} of {algo!r} cannot be set with -H or a config file")
        else:
            known = sorted([*declared, *special, "features_extractor"])
            raise UsageError(f"unknown hyperparameter {key!r} for {algo!r} (known: {', '.join(known)})")
    return checked


def _given_or_default(algo: str, hyperparams: dict, key: str):
    """``hyperparams[key]``, else the default of ``algo``'s SB3 constructor."""
    if key in hyperparams:
        return hyperparams[key]
    return inspect.signature(get_algo(algo).agent_class().__init__).parameters[key].default


def check_sb3_memory(algo: str, hyperparams: dict, observation_space, n_envs: int = 1) -> None:
    """Refuse sizes whose buffers this machine cannot hold (``buffer_memory``): the replay buffer
    and training batch of DQN and SAC, the rollout of PPO and A2C."""
    given = functools.partial(_given_or_default, algo, hyperparams)
    if "buffer_size" in PARAMS[algo]:
        copies = 1 if given("optimize_memory_usage") else 2
        stored = copies * observation_bytes(observation_space)
        check_buffer_memory(algo, "buffer_size", given("buffer_size"), stored, "replay buffer")
        batch = 2 * observation_bytes(observation_space, itemsize=4)
        check_buffer_memory(algo, "batch_size", given("batch_size"), batch, "training batch")
    else:
        entries = given("n_steps") * n_envs
        stored = observation_bytes(observation_space, itemsize=4)
        check_buffer_memory(algo, "n_steps", entries, stored, "rollout (n_steps × n_envs)")
