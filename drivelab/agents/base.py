"""The Agent protocol every algorithm satisfies, and the shared surface of drivelab's own agents.

The contract with ``drivelab.training.run`` (SB3 models satisfy it as they are; our own agents
derive from ``OwnAgent``, which implements everything but the learning loop):

- ``set_logger(logger)``: an SB3 ``Logger`` (CSV + TensorBoard); the agent records its own metrics
  into it (``train/epsilon``, ``train/loss``, ...) and calls ``logger.dump(num_timesteps)`` now
  and then.
- ``learn(total_timesteps, callback, reset_num_timesteps=False)``: trains for ``total_timesteps``
  more environment steps. It calls ``callback.init_callback(self)`` and
  ``callback.on_training_start(locals(), globals())``; ``callback.on_rollout_start()`` between
  training phases (before every step for off-policy agents, every rollout for on-policy ones),
  where nothing is half-done; right after every environment step, before the step changes the
  replay, the networks or the optimizer, ``callback.update_locals(locals())`` then
  ``callback.on_step()``, stopping when that returns False; finally ``callback.on_training_end()``.
  (SB3's loops keep the same order; checkpoints rely on it, see ``training/resume_state.py``.)
- ``num_timesteps``: environment steps taken so far, exact, so that a resume continues to the
  requested total.
- ``predict(obs, deterministic=True)`` → ``(action, None)`` for one unbatched observation.
- ``save(path)`` writes one zip file of tensors and JSON (``agents/storage.py``: nothing in it is
  unpickled); the registry's ``load(algo, path, env or None, hyperparams, seed)`` reads it back.
- Agents whose ``AlgoSpec.sb3_replay`` is set (the off-policy ones, and the on-policy ones for
  their self-imitation replay, ``None`` when unused) also offer ``replay_buffer.observations`` (a
  numpy array, for the size check), ``save_replay_buffer(path)`` and ``load_replay_buffer(path)``
  (an ``.npz`` file; own buffers provide ``state_arrays()`` / ``load_state_arrays(arrays)``).
"""

from __future__ import annotations

import dataclasses
import json
import time
import zipfile
from pathlib import Path
from typing import Any, Protocol, Self

import gymnasium as gym
import numpy as np
import torch
from gymnasium import spaces
from stable_baselines3.common.callbacks import BaseCallback, CallbackList
from stable_baselines3.common.logger import Logger

from drivelab.agents.registry import algo_of
from drivelab.agents.storage import (
    check_spaces,
    read_arrays,
    read_member,
    read_zip,
    space_from_json,
    space_to_json,
    state_limit,
    tensors_from_bytes,
    tensors_to_bytes,
    write_arrays,
)
from drivelab.agents.worlds import Worlds
from drivelab.errors import UsageError, like_default

FORMAT = "drivelab-agent-2"
# The largest learning rate of every agent, SB3's and drivelab's (and of Q-learning's α): a rate
# above 1 wipes a network's initialisation out in one update and overflows to NaN within a few.
MAX_LEARNING_RATE = 1.0


class Agent(Protocol):
    """What training, evaluation and comparison need from an algorithm."""

    num_timesteps: int

    def set_logger(self, logger: Logger) -> None:
        """Use ``logger`` for every metric from now on."""

    def learn(self, total_timesteps: int, callback: Any = None, reset_num_timesteps: bool = True) -> Any:
        """Train ``total_timesteps`` more steps (all of them again when ``reset_num_timesteps``)."""

    def predict(self, obs: Any, deterministic: bool = True) -> tuple[np.ndarray, Any]:
        """(action, state) for one observation."""

    def save(self, path: str | Path) -> None:
        """Write everything needed to continue training or to act, as one zip file."""


def parse_hyperparams(config_class: type, algo: str, hyperparams: dict) -> Any:
    """A frozen config dataclass from ``-H`` overrides; an unknown key or a wrong type is a UsageError."""
    fields = {f.name: f for f in dataclasses.fields(config_class)}
    values = {}
    for key, value in hyperparams.items():
        if key not in fields:
            raise UsageError(f"unknown hyperparameter {key!r} for {algo!r} (known: {', '.join(fields)})")
        values[key] = like_default(value, fields[key].default, f"hyperparameter {key!r} of {algo!r}")
    config = config_class(**values)
    config.check(algo)
    return config


def observation_to_tensor(obs: Any, space: spaces.Space) -> torch.Tensor | dict[str, torch.Tensor]:
    """A batch of observations (leading batch axis) → float tensors; uint8 images are scaled to [0, 1]."""
    if isinstance(space, spaces.Dict):
        return {key: observation_to_tensor(obs[key], sub) for key, sub in space.spaces.items()}
    tensor = torch.as_tensor(np.asarray(obs), dtype=torch.float32)
    return tensor / 255.0 if space.dtype == np.uint8 else tensor


def gradient_step(optimizer: torch.optim.Optimizer, loss: torch.Tensor, parameters=None, max_grad_norm=None):
    """One ``optimizer`` step on the gradients of ``loss``, their global norm over ``parameters``
    first clipped to ``max_grad_norm`` when given."""
    optimizer.zero_grad()
    loss.backward()
    if max_grad_norm is not None:
        torch.nn.utils.clip_grad_norm_(parameters, max_grad_norm)
    optimizer.step()


class RegisteredName:
    """Class attribute: the name ``agents/registry.py`` registers the class it is read from under."""

    def __get__(self, instance, owner: type) -> str:
        return algo_of(owner)


class OwnAgent:
    """Everything run.py needs from an agent, except the learning loop (``learn``) and networks.

    Subclasses set ``algo`` and ``config_class``, build their networks in ``_build`` and list what
    ``save`` must keep in ``_modules`` (and any further tensors in ``_state`` / ``_set_state``).

    :param observation_space: the environment's observation space.
    :param action_space: the environment's action space.
    :param seed: seeds torch and the agent's numpy generator.
    :param hyperparams: overrides of ``config_class``'s defaults.
    :param env: the training environment (not needed to act).
    """

    algo = RegisteredName()
    config_class: type

    def __init__(
        self,
        observation_space: spaces.Space,
        action_space: spaces.Space,
        seed: int = 0,
        hyperparams: dict | None = None,
        env: gym.Env | None = None,
    ) -> None:
        self.observation_space, self.action_space = observation_space, action_space
        self.seed, self.hyperparams = int(seed), dict(hyperparams or {})
        self.config = parse_hyperparams(self.config_class, self.algo, self.hyperparams)
        self.env = env
        self.num_timesteps = 0
        self.rng = np.random.default_rng(self.seed)
        torch.manual_seed(self.seed)  # network initialisation
        self.generator = torch.Generator().manual_seed(self.seed)  # every torch draw while training
        self.logger: Logger = Logger(folder=None, output_formats=[])  # silent until run.py sets one
        self._last_obs = None  # the observations the next ``learn`` goes on from (``_start_worlds``)
        self._build()

    # --- what subclasses provide ------------------------------------------------------------
    def _build(self) -> None:
        raise NotImplementedError

    def _modules(self) -> dict[str, Any]:
        """The networks and optimizers ``save`` keeps, by name."""
        raise NotImplementedError

    def _state(self) -> dict[str, Any]:
        """Tensors and state dicts to save: the ``_modules``' state dicts."""
        return {key: module.state_dict() for key, module in self._modules().items()}

    def _set_state(self, state: dict[str, Any]) -> None:
        for key, module in self._modules().items():
            module.load_state_dict(state[key])

    # --- the SB3-compatible surface ---------------------------------------------------------
    def set_logger(self, logger: Logger) -> None:
        self.logger = logger

    def get_env(self) -> gym.Env | None:
        """The training environment (SB3 callbacks read it in ``init_callback``)."""
        return self.env

    def set_env(self, env: gym.Env) -> None:
        self.env = env

    def save_replay_buffer(self, path: str | Path) -> None:
        """Write ``self.replay_buffer``'s arrays as an ``.npz`` file (run.py checkpoints it)."""
        write_arrays(path, self.replay_buffer.state_arrays())

    def load_replay_buffer(self, path: str | Path) -> None:
        """Fill this agent's (fresh) replay buffer from a ``save_replay_buffer`` file."""
        self.replay_buffer.load_state_arrays(read_arrays(path))

    def learn(
        self,
        total_timesteps: int,
        callback: BaseCallback | None = None,
        reset_num_timesteps: bool = True,
        progress_bar: bool = False,
    ) -> Self:
        """Train ``total_timesteps`` more environment steps (counted from 0 again when
        ``reset_num_timesteps``), with the callback calls of the contract above."""
        if reset_num_timesteps:
            self.num_timesteps = 0
        self._started = (self.num_timesteps, time.perf_counter())  # for the steps per second
        target = self.num_timesteps + int(total_timesteps)
        worlds = Worlds(self.env)
        self._start_worlds(worlds)
        callback = callback if callback is not None else CallbackList([])
        callback.init_callback(self)
        callback.on_training_start(locals(), globals())
        self._learn(worlds, callback, target)
        callback.on_training_end()
        return self

    def _start_worlds(self, worlds) -> None:
        """Start the K worlds (``worlds.Worlds``) unless a previous ``learn`` left them running."""
        self._last_obs = worlds.start(self._last_obs, self.observation_space)

    def _learn(self, worlds, callback: BaseCallback, target: int) -> None:
        """The learning loop, until ``num_timesteps`` reaches ``target`` or ``callback.on_step`` is False."""
        raise NotImplementedError

    def _log_progress(self, metrics: dict[str, float]) -> None:
        """Record ``train/<metric>``, the mean return of ``self.episode_returns`` and the steps per
        second since ``learn`` started, then dump the logger."""
        start_steps, start_time = self._started
        for key, value in metrics.items():
            self.logger.record(f"train/{key}", value)
        if getattr(self, "episode_returns", None):
            self.logger.record("rollout/ep_rew_mean", float(np.mean(self.episode_returns)))
        elapsed = max(time.perf_counter() - start_time, 1e-9)
        self.logger.record("time/fps", int((self.num_timesteps - start_steps) / elapsed))
        self.logger.record("time/total_timesteps", self.num_timesteps)  # progress.csv's step, as SB3
        self.logger.dump(self.num_timesteps)

    def save(self, path: str | Path) -> None:
        """One zip: ``agent.json`` (format, algo, seed, hyperparams, steps, numpy generator, spaces)
        and ``state.pt`` (networks, optimizers, torch generator: tensors only)."""
        meta = {
            "format": FORMAT,
            "algo": self.algo,
            "seed": self.seed,
            "hyperparams": self.hyperparams,
            "num_timesteps": self.num_timesteps,
            "rng": self.rng.bit_generator.state,
            "observation_space": space_to_json(self.observation_space),
            "action_space": space_to_json(self.action_space),
        }
        state = tensors_to_bytes({**self._state(), "generator": self.generator.get_state()})
        with zipfile.ZipFile(path, "w", compression=zipfile.ZIP_DEFLATED) as archive:
            archive.writestr("agent.json", json.dumps(meta, default=int))
            archive.writestr("state.pt", state)

    @classmethod
    def load(
        cls, path: str | Path, env: gym.Env | None = None, hyperparams: dict | None = None,
        seed: int | None = None,
    ) -> OwnAgent:  # fmt: skip
        """An agent saved by ``save``. ``env`` (optional) must have the saved spaces; ``hyperparams``
        and ``seed`` (the run's config, optional) must be those it was saved with."""
        meta, archive = read_zip(path, "agent.json")
        with archive:
            if meta.get("format") != FORMAT or meta.get("algo") != cls.algo:
                raise ValueError(f"the file holds a {meta.get('algo')!r} agent, not {cls.algo!r}")
            if hyperparams is not None and json.loads(json.dumps(dict(hyperparams))) != meta["hyperparams"]:
                raise ValueError("the model was saved with other hyperparameters than the run's config")
            if seed is not None and int(seed) != meta["seed"]:
                raise ValueError("the model was saved with another seed than the run's config")
            if env is not None:
                check_spaces(meta, env.observation_space, env.action_space)
            observation_space = space_from_json(meta["observation_space"])
            action_space = space_from_json(meta["action_space"])
            agent = cls(observation_space, action_space, meta["seed"], meta["hyperparams"], env)
            # CPU first: an agent saved on a GPU loads anywhere; ``_set_state`` copies onto its
            # device. The fresh agent's size bounds the file's: a crafted one cannot inflate past it.
            limit = state_limit(agent._state())
            state = tensors_from_bytes(read_member(archive, "state.pt", limit))
        agent.num_timesteps = int(meta["num_timesteps"])
        agent.rng.bit_generator.state = meta["rng"]
        agent.generator.set_state(state.pop("generator"))
        agent._set_state(state)
        return agent
