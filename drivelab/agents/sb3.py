"""stable-baselines3 algorithms behind drivelab's Agent protocol, saved without pickles.

A model is saved as a zip of ``sb3.json`` (the counters and statistics further training reads,
the seed, hyper-parameters and spaces) and ``parameters.pt`` (state dicts, read with
``torch.load(weights_only=True)``); ``load_sb3`` rebuilds the model from the run's config and
loads the parameters. Replays are ``.npz`` arrays. A loaded model's next ``learn`` resets the env.
"""

from __future__ import annotations

import copy
import json
import zipfile
from collections import deque
from operator import attrgetter
from pathlib import Path

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from stable_baselines3 import A2C, DQN, PPO, SAC
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.utils import get_device

from drivelab.agents.counters import check_counters
from drivelab.agents.registry import algo_of, get_algo
from drivelab.agents.sb3_params import check_sb3_hyperparams, check_sb3_memory
from drivelab.agents.storage import (
    check_spaces,
    read_arrays,
    read_member,
    read_zip,
    space_to_json,
    split_meta,
    state_limit,
    tensors_from_bytes,
    tensors_to_bytes,
    write_arrays,
)
from drivelab.errors import UsageError
from drivelab.hyperparams import shipped_hyperparams

FORMAT = "drivelab-sb3-1"
# model attributes that further training reads, restored after a load (those a model lacks are skipped)
COUNTERS = ("num_timesteps", "_n_updates", "_episode_num", "_n_calls", "exploration_rate",
            "_current_progress_remaining", "_total_timesteps", "_num_timesteps_at_start")  # fmt: skip
REPLAY_ARRAYS = ("observations", "next_observations", "actions", "rewards", "dones", "timeouts")


class SafeSave:
    """Mixin for SB3 algorithms: ``save`` and the replay methods write tensors, arrays and JSON
    (see the module docstring); the Agent protocol's ``save(path)`` is unchanged."""

    def save(self, path: str | Path) -> None:
        """One zip: ``sb3.json`` and ``parameters.pt``."""
        _, variables = self._get_torch_save_params()
        tensors = {name: attrgetter(name)(self).detach().cpu() for name in variables}
        parameters = {"state_dicts": self.get_parameters(), "variables": tensors}
        meta = {
            "format": FORMAT,
            "algo": algo_of(type(self)),
            "seed": self.seed,
            "hyperparams": self.drivelab_hyperparams,
            "n_envs": self.n_envs,
            "observation_space": space_to_json(self.observation_space),
            "action_space": space_to_json(self.action_space),
            "counters": {name: getattr(self, name) for name in COUNTERS if hasattr(self, name)},
            "ep_info_buffer": list(self.ep_info_buffer or []),
            "ep_success_buffer": [bool(value) for value in self.ep_success_buffer or []],
        }
        tensors = tensors_to_bytes(parameters)  # before the file is opened: a refusal writes nothing
        with zipfile.ZipFile(path, "w", compression=zipfile.ZIP_DEFLATED) as archive:
            archive.writestr("sb3.json", json.dumps(meta, default=_json_number))
            archive.writestr("parameters.pt", tensors)

    def save_replay_buffer(self, path: str | Path) -> None:
        """The replay buffer's arrays (dict observations key by key) and position as ``.npz``."""
        buffer = self.replay_buffer
        arrays = {key: holder[name] for key, (holder, name) in _replay_slots(buffer).items()}
        write_arrays(path, arrays, {"pos": int(buffer.pos), "full": bool(buffer.full)})

    def load_replay_buffer(self, path: str | Path) -> None:
        """Fill this model's fresh replay buffer from ``save_replay_buffer``'s file; every array
        must have the shape and dtype of the buffer's own (same buffer size and spaces)."""
        arrays, meta = split_meta(read_arrays(path))
        buffer = self.replay_buffer
        expected = _replay_slots(buffer)
        if set(arrays) != set(expected) or not {"pos", "full"} <= set(meta):
            raise ValueError("the replay's arrays do not match this model's replay buffer")
        for key, (holder, name) in expected.items():
            if arrays[key].shape != holder[name].shape or arrays[key].dtype != holder[name].dtype:
                raise ValueError(f"replay array {key!r} does not fit this model's buffer")
        for key, (holder, name) in expected.items():
            holder[name] = arrays[key].copy()
        buffer.pos, buffer.full = int(meta["pos"]), bool(meta["full"])


def _replay_slots(buffer) -> dict[str, tuple[dict, str]]:
    """``{file key: (holder, key in it)}`` of the replay's arrays (dict observations key by key)."""
    slots = {}
    for name in REPLAY_ARRAYS:
        value = getattr(buffer, name, None)
        if isinstance(value, dict):
            slots.update({f"{name}/{key}": (value, key) for key in value})
        elif value is not None:
            slots[name] = (buffer.__dict__, name)
    return slots


class RolloutLogs:
    """Mixin for SB3's on-policy algorithms: a progress row every ``log_rollouts`` rollouts counted
    from step 0 (SB3 counts from each ``learn`` call, so a resumed run would log other steps);
    ``time/iterations`` is the rollouts since step 0."""

    SB3_LOG_INTERVAL = 1
    log_rollouts = 1

    def log_over(self, total_steps: int) -> None:
        """Log at SB3's interval, or often enough for about ten rows over ``total_steps``."""
        rollout = self.n_steps * self.n_envs
        self.log_rollouts = max(1, min(self.SB3_LOG_INTERVAL, total_steps // (10 * rollout)))

    def learn(self, *args, **kwargs):
        kwargs["log_interval"] = 1  # every rollout asks ``dump_logs``, which decides by the step
        return super().learn(*args, **kwargs)

    def dump_logs(self, iteration: int = 0) -> None:
        rollouts = self.num_timesteps // (self.n_steps * self.n_envs)  # every rollout is whole
        if rollouts % self.log_rollouts == 0:
            super().dump_logs(rollouts)


class DrivelabDQN(SafeSave, DQN):
    """SB3 DQN saved without pickles."""


class DrivelabPPO(SafeSave, RolloutLogs, PPO):
    """SB3 PPO saved without pickles."""


class DrivelabA2C(SafeSave, RolloutLogs, A2C):
    """SB3 A2C saved without pickles."""

    SB3_LOG_INTERVAL = 100  # A2C.learn's default


class DrivelabSAC(SafeSave, SAC):
    """SB3 SAC saved without pickles."""


def _json_number(value):
    """numpy scalars in counters and episode infos → Python numbers for JSON."""
    if isinstance(value, np.generic):
        return value.item()
    raise TypeError(f"cannot store {type(value).__name__} in a model file")


def policy_for(space: spaces.Space) -> str:
    """SB3 policy name for an observation space: Dict → MultiInput, image → Cnn, else Mlp."""
    if isinstance(space, spaces.Dict):
        return "MultiInputPolicy"
    if len(space.shape) == 3 and space.dtype.name == "uint8":
        return "CnnPolicy"
    return "MlpPolicy"


def seed_network_kwargs(algo: str, space: spaces.Space) -> dict:
    """policy_kwargs that give SB3 PPO/A2C the MetaDrive study's network: its CNN on an image, its fusion
    network on image + vectors, linear heads on the 256 features (as our own agents), actor and
    critic encoders shared for PPO and separate for A2C (as the seed)."""
    from drivelab.agents.networks import FusionExtractor, SeedCnnExtractor, observation_kind

    kind = observation_kind(space)
    if algo not in ("ppo", "a2c") or kind not in ("image", "image+vector"):
        raise UsageError(
            f"features_extractor=seed needs ppo or a2c on an image or image+vector observation, "
            f"got {algo!r} on {kind!r}"
        )
    extractor = SeedCnnExtractor if kind == "image" else FusionExtractor
    return {
        "features_extractor_class": extractor,
        "net_arch": [],
        "share_features_extractor": algo == "ppo",
        "normalize_images": True,
    }


def attention_network_kwargs(space: spaces.Space) -> dict:
    """policy_kwargs that read the vehicles as a set with ego-attention (``AttentionExtractor``)."""
    from drivelab.agents.networks import AttentionExtractor, EgoAttentionEncoder

    try:
        EgoAttentionEncoder(space)
    except ValueError as exc:
        raise UsageError(f"features_extractor=attention: {exc}") from None
    return {"features_extractor_class": AttentionExtractor}


def build_sb3(algo: str, env: gym.Env, seed: int, hyperparams: dict, log_dir: Path | None) -> BaseAlgorithm:
    """A fresh SB3 model for ``env``. ``features_extractor``: "sb3" (SB3's own networks, default),
    "seed" (the MetaDrive study's CNN / fusion network, ``seed_network_kwargs``) or "attention"
    (ego-attention over the vehicles, ``attention_network_kwargs``). ``device``: "cpu" (the
    default), "cuda" or "auto". Keys ``hyperparams`` leaves out take the ``default`` entry of
    ``drivelab/hyperparams/<algo>.yaml`` (highway-env's documented SB3 examples, else SB3's own).
    Every value is checked first (``sb3_params``)."""
    defaults = shipped_hyperparams(algo, "default")
    saved = json.loads(json.dumps(dict(hyperparams)))  # saved with the model, as given
    # a copy: SB3 fills some values in place (A2C puts its optimizer class into policy_kwargs)
    kwargs = check_sb3_hyperparams(algo, copy.deepcopy({"device": "cpu", **defaults, **hyperparams}))
    check_sb3_memory(algo, kwargs, env.observation_space, getattr(env, "num_envs", 1))
    extractor = kwargs.pop("features_extractor", "sb3")
    if extractor == "seed":
        kwargs["policy_kwargs"] = {**seed_network_kwargs(algo, env.observation_space),
                                   **hyperparams.get("policy_kwargs", {})}  # fmt: skip
    elif extractor == "attention":
        kwargs["policy_kwargs"] = {**attention_network_kwargs(env.observation_space),
                                   **kwargs.get("policy_kwargs", {})}  # fmt: skip
    elif extractor != "sb3":
        raise UsageError(f"features_extractor must be 'sb3', 'seed' or 'attention', got {extractor!r}")
    model = get_algo(algo).agent_class()(
        policy_for(env.observation_space), env, seed=seed, verbose=0, **kwargs
    )
    model.drivelab_hyperparams = saved
    return model


def load_sb3(algo: str, path: Path, env: gym.Env | None, hyperparams: dict | None = None,
             seed: int | None = None) -> BaseAlgorithm:  # fmt: skip
    """A model saved by ``SafeSave.save``, rebuilt by ``build_sb3`` on ``env`` (the run config's
    environment, needed for its spaces) from ``hyperparams`` and ``seed`` (the run's config; the
    file's own when None, and they must agree), then its parameters and counters restored."""
    meta, archive = read_zip(path, "sb3.json")
    with archive:
        if meta.get("format") != FORMAT or meta.get("algo") != algo:
            raise ValueError(f"the file holds a {meta.get('algo')!r} model, not {algo!r}")
        counters = check_counters(meta["counters"])  # set as attributes: only counters, each of its kind
        given = meta["hyperparams"] if hyperparams is None else json.loads(json.dumps(dict(hyperparams)))
        seed = meta["seed"] if seed is None else int(seed)
        if (given, seed) != (meta["hyperparams"], meta["seed"]):
            raise ValueError("the model was saved with other hyperparameters or seed than the run's config")
        if env is None:
            raise ValueError("an SB3 model is rebuilt on its environment: give one")
        check_spaces(meta, env.observation_space, env.action_space)
        model = build_sb3(algo, env, seed, given, None)
        # the model's own size bounds the file's: a crafted one cannot inflate past it
        limit = state_limit(model.get_parameters())
        parameters = tensors_from_bytes(read_member(archive, "parameters.pt", limit))
    model.set_parameters(parameters["state_dicts"], exact_match=True, device=get_device(model.device))
    for name, value in parameters["variables"].items():
        attrgetter(name)(model).data.copy_(value)
    for name, value in counters.items():
        setattr(model, name, value)
    model.ep_info_buffer = deque(meta["ep_info_buffer"], maxlen=model._stats_window_size)
    model.ep_success_buffer = deque(meta["ep_success_buffer"], maxlen=model._stats_window_size)
    return model
