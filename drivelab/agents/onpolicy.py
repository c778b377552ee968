"""drivelab's on-policy trainer: one collect loop over K worlds' arrays, shared by PPO and A2C.

Each iteration fills preallocated ``(n_steps, K, ...)`` tensors from the worlds' batched arrays
(``worlds.Worlds``), computes GAE over the block, then hands the flattened batch to the
algorithm's ``update`` (``ppo.py``, ``a2c.py``). A time-limit end bootstraps from the final
observation. With ``sil_updates`` each update ends with self-imitation steps on a replay of the
recent transitions (``self_imitation.py``). Every running statistic, and that replay, changes only
between rollouts, the safe points where ``drivelab train`` checkpoints, so that a resumed run
equals an uninterrupted one.
"""

from __future__ import annotations

import copy
from collections import deque
from dataclasses import dataclass
from operator import itemgetter
from typing import Any

import numpy as np
import torch
from gymnasium import spaces
from stable_baselines3.common.callbacks import BaseCallback
from torch import nn

from drivelab.agents.actor_critic import (
    BETA_ACTIONS,
    DISTRIBUTIONS,
    NORM_CLIP,
    NORM_EPSILON,
    ActorCritic,
    merge_moments,
)
from drivelab.agents.base import MAX_LEARNING_RATE, OwnAgent, gradient_step
from drivelab.agents.buffer_memory import check_buffer_memory, observation_bytes
from drivelab.agents.networks import ENCODERS
from drivelab.agents.self_imitation import SelfImitationReplay, self_imitation_loss
from drivelab.agents.worlds import Worlds, batch_of_one, map_obs
from drivelab.errors import UsageError


@dataclass(frozen=True)
class OnPolicyConfig:
    """What PPO and A2C share (``-H key=value``).

    :param learning_rate: Adam step size (annealed linearly to 0 over the run when ``linear_lr``).
    :param n_steps: steps of every world per rollout (a rollout is n_steps × K transitions).
    :param gamma: discount.
    :param gae_lambda: GAE λ (1.0: plain n-step returns).
    :param entropy_coef: weight of the entropy bonus (annealed to 0 when ``linear_entropy``).
    :param value_coef: weight of the value loss.
    :param max_grad_norm: gradient clipping by global norm.
    :param normalize_advantages: standardise the advantages (per minibatch).
    :param normalize_observations: normalise the float observations with running statistics.
    :param normalize_rewards: scale rewards by the running std of the discounted return (SB3's
        ``VecNormalize(norm_reward=True)``), clipped to ±10.
    :param distribution: "auto" (categorical for discrete actions, tanh_gaussian for continuous),
        "tanh_gaussian" or "beta".
    :param beta_action: a Beta policy's deterministic action (evaluation, ``drivelab evaluate``):
        "mode", as Roach acts, which reaches the ends of the range (a full stop), or "mean".
    :param net_arch: widths of the MLP's tanh layers for vector observations, e.g. "256,256".
    :param shared_encoder: actor and critic share the encoder.
    :param encoder: "auto" (the MLP, CNN or fusion encoder the observation takes) or "attention":
        ego-attention over the vehicles of ``kinematics:flatten=false`` (Leurent & Mercat 2019, the
        encoder rl-agents learns highway-env's intersection with), its embeddings ``net_arch`` wide.
    :param attention_output: widths of ReLU layers after the attention encoder, e.g. "64,64" (rl-agents'
        EgoAttentionNetwork ends in such an output layer; empty, the default: the encoder's features
        go straight to the linear policy and value heads).
    :param log_std_init: initial log σ of the tanh-Gaussian (given with ``init_from``, it replaces
        the source policy's).
    :param linear_lr: anneal the learning rate linearly to 0.
    :param linear_entropy: anneal the entropy coefficient linearly to 0.
    :param bootstrap_time_limits: a time-limit end continues with γ·V(final observation), as SB3
        does (right when the limit only cuts a task that goes on); false: it ends the return like a
        crash, as CleanRL's PPO does (right when beating the clock is part of the task, e.g. the
        intersection's arrival within 13 s; Pardo et al. 2018, "Time Limits in Reinforcement
        Learning").
    :param critic_warmup_steps: rollouts that end within this many steps train the critic alone
        (the actor, and an encoder it shares with the critic, keep their weights): a policy started
        from imitation (``--init-from``) then meets a critic that knows its returns before the
        policy gradient moves it (Roach's and CaRL's fine-tuning lineage pre-trains the critic).
    :param prior_kl_coef: weight of KL(π ‖ π_prior) in the loss, π_prior a frozen copy of the
        policy the run started from (the ``--init-from`` policy, else the random initial one): a
        fine-tuning that improves on an imitation policy stays near it (0: no such term).
    :param sil_updates: self-imitation steps after each update (Oh et al. 2018,
        ``self_imitation.py``): minibatches of the last ``sil_capacity`` transitions, imitating the
        actions whose return beat the critic (0: none).
    :param sil_batch_size: transitions per self-imitation step.
    :param sil_capacity: transitions the self-imitation replay keeps.
    :param sil_value_coef: weight of the self-imitation value term (the critic pulled up towards
        the returns it underestimated).
    """

    learning_rate: float = 3e-4
    n_steps: int = 128
    gamma: float = 0.8
    gae_lambda: float = 0.95
    entropy_coef: float = 0.0
    value_coef: float = 0.5
    max_grad_norm: float = 0.5
    normalize_advantages: bool = True
    normalize_observations: bool = False
    normalize_rewards: bool = False
    distribution: str = "auto"
    beta_action: str = "mode"
    net_arch: str = "64,64"
    shared_encoder: bool = True
    encoder: str = "auto"
    attention_output: str = ""
    log_std_init: float = 0.0
    linear_lr: bool = False
    linear_entropy: bool = False
    bootstrap_time_limits: bool = True
    critic_warmup_steps: int = 0
    prior_kl_coef: float = 0.0
    sil_updates: int = 0
    sil_batch_size: int = 512
    sil_capacity: int = 100_000
    sil_value_coef: float = 0.01

    def check(self, algo: str) -> None:
        if self.n_steps < 1 or not 0 < self.gamma <= 1 or not 0 <= self.gae_lambda <= 1:
            raise UsageError(f"{algo!r} needs n_steps >= 1, 0 < gamma <= 1 and 0 <= gae_lambda <= 1")
        if not 0 < self.learning_rate <= MAX_LEARNING_RATE or self.max_grad_norm <= 0:
            raise UsageError(
                f"{algo!r} needs 0 < learning_rate <= {MAX_LEARNING_RATE:g} and max_grad_norm > 0"
            )
        if min(self.entropy_coef, self.value_coef, self.critic_warmup_steps, self.prior_kl_coef) < 0:
            raise UsageError(
                f"{algo!r} needs entropy_coef, value_coef, critic_warmup_steps and prior_kl_coef >= 0"
            )
        if self.sil_updates < 0 or min(self.sil_batch_size, self.sil_capacity) < 1 or self.sil_value_coef < 0:
            raise UsageError(
                f"{algo!r} needs sil_updates >= 0, sil_batch_size and sil_capacity >= 1 and "
                "sil_value_coef >= 0"
            )
        if self.distribution not in DISTRIBUTIONS:
            raise UsageError(f"{algo!r} distribution must be one of {', '.join(DISTRIBUTIONS)}")
        if self.beta_action not in BETA_ACTIONS:
            raise UsageError(
                f"{algo!r} beta_action must be one of {', '.join(BETA_ACTIONS)}, got {self.beta_action!r}"
            )
        if self.encoder not in ENCODERS:
            raise UsageError(f"{algo!r} encoder must be one of {', '.join(ENCODERS)}, got {self.encoder!r}")
        self.hidden(algo)
        if self.attention_output and self.encoder != "attention":
            raise UsageError(f"{algo!r} attention_output needs encoder=attention")
        self.output_layers(algo)

    def hidden(self, algo: str) -> tuple[int, ...]:
        """``net_arch`` as layer widths."""
        return _widths(algo, "net_arch", self.net_arch)

    def output_layers(self, algo: str) -> tuple[int, ...]:
        """``attention_output`` as layer widths (none when empty)."""
        return _widths(algo, "attention_output", self.attention_output) if self.attention_output else ()


def _widths(algo: str, key: str, text) -> tuple[int, ...]:
    """Comma-separated layer widths, or one ``error:`` naming ``key``."""
    try:
        widths = tuple(int(part) for part in str(text).split(","))
    except ValueError:
        widths = ()
    if not widths or min(widths) < 1 or max(widths) > 65536:
        raise UsageError(
            f"{algo!r} {key} must be layer widths between 1 and 65536 separated by commas "
            f"(e.g. 256,256), got {text!r}"
        )
    return widths


def compute_gae(
    rewards: np.ndarray,
    values: np.ndarray,
    episode_ends: np.ndarray,
    last_value: float | np.ndarray,
    gamma: float,
    gae_lambda: float,
) -> tuple[np.ndarray, np.ndarray]:
    """Generalised advantage estimation (Schulman et al. 2016, eq. 11-16), backwards in time.

    δ_t = r_t + γ·V(s_{t+1})·(1 − end_t) − V(s_t);  A_t = δ_t + γλ·(1 − end_t)·A_{t+1}.
    ``episode_ends[t]`` is 1 when the episode ended at step t (a time-limit end is bootstrapped by
    the caller, who adds γ·V(final observation) to its reward). Returns (advantages, returns = A + V)
    as float32, shaped like ``rewards``.

    :param rewards: (T,) rewards, or (T, K) for K worlds stepped together.
    :param values: V(s_t), shaped like ``rewards``.
    :param episode_ends: 1.0 where the episode ended after step t, shaped like ``rewards``.
    :param last_value: V of the observation after the last step (K,) (a float for (T,)).
    """
    rewards = np.asarray(rewards, dtype=np.float64)
    advantages = np.zeros(rewards.shape, dtype=np.float32)
    next_advantage = np.zeros(rewards.shape[1:])
    next_value = np.asarray(last_value, dtype=np.float64)
    for t in reversed(range(len(rewards))):
        not_end = 1.0 - np.asarray(episode_ends[t], dtype=np.float64)
        delta = rewards[t] + gamma * next_value * not_end - values[t]
        next_advantage = delta + gamma * gae_lambda * not_end * next_advantage
        advantages[t] = next_advantage
        next_value = np.asarray(values[t], dtype=np.float64)
    return advantages, advantages + np.asarray(values, dtype=np.float32)


@dataclass
class Rollout:
    """One batch of on-policy experience, flattened time-major to (n_steps·K, ...), for the update."""

    observations: Any  # tensor or dict of tensors, stored dtype (uint8 images stay uint8)
    actions: torch.Tensor  # the distribution's variables (class, pre-tanh u, Beta x)
    log_probs: torch.Tensor
    values: torch.Tensor
    advantages: torch.Tensor
    returns: torch.Tensor


class Storage:
    """Preallocated (n_steps, K, ...) tensors of one rollout; observations in their own dtype."""

    def __init__(self, space: spaces.Space, steps: int, worlds: int, action_shape: tuple, discrete: bool):
        def block(sub: spaces.Box) -> torch.Tensor:
            dtype = torch.uint8 if sub.dtype == np.uint8 else torch.float32
            return torch.zeros((steps, worlds, *sub.shape), dtype=dtype)

        self.obs = map_obs(block, space.spaces if isinstance(space, spaces.Dict) else space)
        action_dtype = torch.int64 if discrete else torch.float32
        self.actions = torch.zeros((steps, worlds, *action_shape), dtype=action_dtype)
        self.log_probs = torch.zeros((steps, worlds))
        self.values = torch.zeros((steps, worlds))
        self.rewards = np.zeros((steps, worlds))
        self.bootstrap = np.zeros((steps, worlds))  # γ·V(final observation) of time-limit ends
        self.ends = np.zeros((steps, worlds))
        self.steps, self.worlds = steps, worlds

    def put(self, t: int, obs: Any) -> Any:
        """Store step ``t``'s observations (K, ...); the stored tensors."""
        rows = map_obs(lambda block: block[t], self.obs)
        map_obs(lambda row, value: row.copy_(torch.from_numpy(np.asarray(value))), rows, obs)
        return rows


def to_tensor(obs: Any) -> Any:
    """A batch of raw observations (numpy) as tensors of their own dtype (no copy where possible)."""
    return map_obs(lambda value: torch.from_numpy(np.ascontiguousarray(value)), obs)


class OnPolicyAgent(OwnAgent):
    """The actor-critic and its collect loop; subclasses implement ``update`` (one readable file each)."""

    def _build(self) -> None:
        config = self.config
        worlds = getattr(self.env, "num_envs", 1)
        observation = observation_bytes(self.observation_space)
        check_buffer_memory(
            self.algo, "n_steps", config.n_steps * worlds, observation, "rollout (n_steps × worlds)"
        )
        try:
            self.policy = ActorCritic(
                self.observation_space,
                self.action_space,
                distribution=config.distribution,
                shared_encoder=config.shared_encoder,
                log_std_init=config.log_std_init,
                hidden=config.hidden(self.algo),
                normalize_observations=config.normalize_observations,
                encoder=config.encoder,
                beta_action=config.beta_action,
                attention_output=config.output_layers(self.algo),
            )
        except ValueError as exc:
            raise UsageError(f"{self.algo!r}: {exc}") from None
        self.optimizer = torch.optim.Adam(
            self.policy.parameters(), lr=config.learning_rate, eps=1e-5, foreach=True
        )
        self.prior = self._frozen_copy() if config.prior_kl_coef > 0 else None
        self.replay_buffer: SelfImitationReplay | None = None  # the checkpoint keeps it (replay.npz)
        if config.sil_updates > 0:
            check_buffer_memory(
                self.algo, "sil_capacity", config.sil_capacity, observation, "self-imitation replay"
            )
            self.replay_buffer = SelfImitationReplay(
                self.observation_space, config.sil_capacity, self.policy.stored_shape(),
                self.policy.kind == "categorical",
            )  # fmt: skip
        # the reward scale: running mean/var of the discounted return, and each world's return so far
        self.return_stats = torch.tensor([0.0, 1.0, 0.0], dtype=torch.float64)  # mean, var, count
        self.running_returns = torch.zeros(worlds, dtype=torch.float64)
        self.learning_rate, self.entropy_coef = config.learning_rate, config.entropy_coef  # annealed in learn
        self._storage: Storage | None = None
        self.episode_returns: deque[float] = deque(maxlen=100)

    def _modules(self) -> dict[str, Any]:
        prior = {} if self.prior is None else {"prior": self.prior}
        return {"policy": self.policy, "optimizer": self.optimizer, **prior}

    def _frozen_copy(self) -> ActorCritic:
        return copy.deepcopy(self.policy).requires_grad_(False)

    def start_from(self, weights: dict[str, torch.Tensor]) -> None:
        """Load another policy's weights (``--init-from``); the prior of ``prior_kl_coef`` becomes them."""
        self.policy.load_state_dict(weights)
        if self.prior is not None:
            self.prior = self._frozen_copy()

    def prior_kl(self, obs: Any, out: torch.Tensor) -> torch.Tensor | None:
        """mean KL(π ‖ π_prior) over a minibatch (its observations and π's head outputs); None
        without a prior."""
        if self.prior is None:
            return None
        with torch.no_grad():
            prior_out, _ = self.prior(obs)
        return self.policy.kl_to(out, self.prior, prior_out).mean()

    def _state(self) -> dict[str, Any]:
        return {
            **super()._state(),
            "return_stats": self.return_stats,
            "running_returns": self.running_returns,
        }

    def _set_state(self, state: dict[str, Any]) -> None:
        super()._set_state(state)
        if "return_stats" in state:  # (files saved before reward normalisation have none)
            self.return_stats = state["return_stats"].clone()
            self.running_returns = state["running_returns"].clone()

    # --- acting ---------------------------------------------------------------------------------
    def act(self, obs: Any, deterministic: bool) -> np.ndarray:
        """The environment's actions for a batch of observations (K, ...)."""
        with torch.no_grad():
            out, _ = self.policy(to_tensor(obs))
            stored = self.policy.sample(out, deterministic, self.generator, self.rng)
        return self.policy.to_env(stored)

    def predict(self, obs: Any, state=None, episode_start=None, deterministic: bool = True):
        """(action, None) for one observation; the mode / mean when deterministic (nothing drawn)."""
        return self.act(batch_of_one(obs), deterministic)[0], None

    def _values(self, batch: Any) -> np.ndarray:
        """V of a batch of observations (K, ...) as float64 (K,)."""
        with torch.no_grad():
            return self.policy.values(to_tensor(batch)).double().numpy()

    # --- collecting -----------------------------------------------------------------------------
    def _storage_for(self, worlds: int) -> Storage:
        storage, steps = self._storage, self.config.n_steps
        if storage is None or (storage.steps, storage.worlds) != (steps, worlds):
            shape, discrete = self.policy.stored_shape(), self.policy.kind == "categorical"
            self._storage = Storage(self.observation_space, steps, worlds, shape, discrete)
        return self._storage

    def collect(self, worlds: Worlds, callback: BaseCallback) -> Rollout | None:
        """``n_steps`` steps of each of the K worlds (fewer at the step budget), then advantages;
        None when the callback stops training."""
        config, count, policy = self.config, worlds.count, self.policy
        storage = self._storage_for(count)
        steps = min(config.n_steps, -(-(self._target - self.num_timesteps) // count))
        obs = self._last_obs
        for t in range(steps):
            with torch.no_grad():
                out, value = policy(storage.put(t, obs))
                stored = policy.sample(out, False, self.generator, self.rng)
                log_prob, _ = policy.log_prob_entropy(out, stored, entropy=False)
            new_obs, reward, terminated, truncated, final_obs, returns = worlds.step(policy.to_env(stored))
            self.num_timesteps += count
            storage.actions[t] = stored
            storage.log_probs[t] = log_prob
            storage.values[t] = value
            storage.rewards[t] = reward
            storage.ends[t] = terminated | truncated
            if config.bootstrap_time_limits and np.count_nonzero(truncated):  # the value goes on
                storage.bootstrap[t] = np.where(truncated, config.gamma * self._values(final_obs), 0.0)
            else:
                storage.bootstrap[t] = 0.0
            self.episode_returns.extend(returns)
            self._last_obs = obs = new_obs
            callback.update_locals(locals())
            if not callback.on_step():
                return None
        ends = storage.ends[:steps]
        rewards = self._scaled_rewards(storage.rewards[:steps], ends) + storage.bootstrap[:steps]
        values, last_values = storage.values[:steps].double().numpy(), self._values(obs)
        advantages, returns = compute_gae(rewards, values, ends, last_values, config.gamma, config.gae_lambda)
        rollout = Rollout(
            map_obs(lambda block: block[:steps].flatten(0, 1), storage.obs),
            storage.actions[:steps].flatten(0, 1),
            storage.log_probs[:steps].flatten(),
            storage.values[:steps].flatten(),
            torch.from_numpy(advantages.reshape(-1)),
            torch.from_numpy(returns.reshape(-1)),
        )
        if self.replay_buffer is not None:  # the Monte-Carlo returns of the rewards the critic learns
            _, discounted = compute_gae(rewards, values, ends, last_values, config.gamma, 1.0)
            self.replay_buffer.add(rollout.observations, rollout.actions, discounted.reshape(-1))
        return rollout

    def _scaled_rewards(self, rewards: np.ndarray, ends: np.ndarray) -> np.ndarray:
        """The rollout's rewards (T, K), divided by the running std of the discounted return when
        ``normalize_rewards`` (the statistics updated with this rollout's returns first)."""
        if not self.config.normalize_rewards:
            return rewards
        returns = np.empty_like(rewards)
        running = self.running_returns.numpy().copy()
        for t in range(len(rewards)):
            running = running * self.config.gamma + rewards[t]
            returns[t] = running
            running = running * (1.0 - ends[t])
        self.running_returns = torch.from_numpy(running)
        mean, var, count = self.return_stats.tolist()
        mean, var = merge_moments(mean, var, count, float(returns.mean()), float(returns.var()), returns.size)
        self.return_stats = torch.tensor([mean, var, count + returns.size], dtype=torch.float64)
        return np.clip(rewards / np.sqrt(var + NORM_EPSILON), -NORM_CLIP, NORM_CLIP)

    def update(self, rollout: Rollout) -> dict[str, float]:
        """One policy update from a rollout; returns the metrics to log (``train/...``)."""
        raise NotImplementedError

    def self_imitate(self) -> dict[str, float]:
        """``sil_updates`` self-imitation steps on minibatches of the replay (``self_imitation.py``);
        the mean fraction of each minibatch whose return beat the critic."""
        config, replay, fractions = self.config, self.replay_buffer, []
        for _ in range(config.sil_updates if len(replay) else 0):  # (empty after a resume that had no room)
            observations, actions, returns = replay.sample(config.sil_batch_size, self.generator)
            out, values = self.policy(observations)
            log_probs, _ = self.policy.log_prob_entropy(out, actions, entropy=False)
            loss, count = self_imitation_loss(log_probs, values, returns, config.sil_value_coef)
            gradient_step(self.optimizer, loss, self.policy.parameters(), config.max_grad_norm)
            fractions.append(count / config.sil_batch_size)
        return {"sil_fraction": float(np.mean(fractions))} if fractions else {}

    def update_critic(self, rollout: Rollout) -> dict[str, float]:
        """The critic's regression on the rollout's returns alone (``critic_warmup_steps``), in the
        algorithm's epochs and minibatches (PPO's ``n_epochs`` × ``batch_size``; A2C: one step)."""
        config, policy = self.config, self.policy
        size = len(rollout.returns)
        batch, losses = getattr(config, "batch_size", size), []
        for _ in range(getattr(config, "n_epochs", 1)):
            for indices in torch.randperm(size, generator=self.generator).split(batch):
                values = policy.values(map_obs(itemgetter(indices), rollout.observations), freeze_shared=True)
                loss = nn.functional.mse_loss(values, rollout.returns[indices])
                gradient_step(self.optimizer, loss, policy.parameters(), config.max_grad_norm)
                losses.append(loss.item())
        explained = explained_variance(rollout.values, rollout.returns)
        return {"value_loss": float(np.mean(losses)), "explained_variance": explained, "critic_warmup": 1.0}

    # --- the loop -------------------------------------------------------------------------------
    def _start_worlds(self, worlds: Worlds) -> None:
        if worlds.count != len(self.running_returns):
            self.running_returns = torch.zeros(worlds.count, dtype=torch.float64)
        super()._start_worlds(worlds)
        if self.config.normalize_observations and self.policy.norm.count <= 0:
            self.policy.norm.update(to_tensor(self._last_obs))  # the statistics start from the first batch

    def _learn(self, worlds: Worlds, callback: BaseCallback, target: int) -> None:
        """Collect a rollout, update, until ``target``."""
        self._target = target
        while self.num_timesteps < self._target:
            callback.on_rollout_start()
            rollout = self.collect(worlds, callback)
            if rollout is None:
                break
            callback.on_rollout_end()
            fraction_left = 1.0 - self.num_timesteps / max(self._target, 1)
            config = self.config
            self.learning_rate = config.learning_rate * (fraction_left if config.linear_lr else 1.0)
            self.entropy_coef = config.entropy_coef * (fraction_left if config.linear_entropy else 1.0)
            for group in self.optimizer.param_groups:
                group["lr"] = self.learning_rate
            if self.num_timesteps <= config.critic_warmup_steps:
                metrics = self.update_critic(rollout)
            else:
                metrics = self.update(rollout)
                if self.replay_buffer is not None:
                    metrics.update(self.self_imitate())
            self.policy.norm.update(rollout.observations)
            metrics.update(learning_rate=self.learning_rate, entropy_coef=self.entropy_coef)
            if self.policy.kind == "tanh_gaussian":
                metrics["std"] = self.policy.std()
            self._log_progress(metrics)


def explained_variance(values: torch.Tensor, returns: torch.Tensor) -> float:
    """1 − Var(R − V) / Var(R) (0 when the returns do not vary)."""
    variance = float(returns.var()) if len(returns) > 1 else 0.0
    return 1.0 - float((returns - values).var()) / variance if variance > 0 else 0.0
