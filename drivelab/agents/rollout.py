"""On-policy plumbing shared by our A2C and PPO: rollouts, GAE, and the learning loop around an update.

Each iteration collects ``n_steps`` transitions with the current tanh-Gaussian policy, computes
advantages with GAE, then hands the batch to the algorithm's ``update`` (``a2c.py``, ``ppo.py``).
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch
from gymnasium import spaces
from stable_baselines3.common.callbacks import BaseCallback

from drivelab.agents.base import OwnAgent, batch_of_one, observation_to_tensor
from drivelab.agents.buffer_memory import check_buffer_memory, observation_bytes
from drivelab.agents.networks import TanhGaussianActorCritic
from drivelab.agents.worlds import Worlds


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
    """One batch of on-policy experience, as tensors ready for the update."""

    observations: Any  # tensor or dict of tensors, (T, ...)
    unsquashed_actions: torch.Tensor  # (T, action_size): pre-tanh u, so log π needs no atanh
    log_probs: torch.Tensor  # (T,)
    values: torch.Tensor  # (T,)
    advantages: torch.Tensor  # (T,)
    returns: torch.Tensor  # (T,)


class OnPolicyAgent(OwnAgent):
    """A tanh-Gaussian actor-critic trained from rollouts; subclasses implement ``update``.

    The config class must have ``n_steps``, ``gamma``, ``gae_lambda``, ``learning_rate``,
    ``shared_encoder`` and ``log_std_init``.
    """

    shared_encoder = True

    def _build(self) -> None:
        if not isinstance(self.action_space, spaces.Box):
            raise ValueError(f"{self.algo} needs continuous actions")
        # a rollout keeps n_steps observations of each world, as they come and as float32 tensors
        worlds = getattr(self.env, "num_envs", 1)
        observation = observation_bytes(self.observation_space) + observation_bytes(self.observation_space, 4)
        check_buffer_memory(
            self.algo, "n_steps", self.config.n_steps * worlds, observation, "rollout (n_steps × worlds)"
        )
        self.policy = TanhGaussianActorCritic(
            self.observation_space,
            self.action_space.shape[0],
            shared_encoder=self.config.shared_encoder,
            log_std_init=self.config.log_std_init,
        )
        self.optimizer = torch.optim.Adam(
            self.policy.parameters(), lr=self.config.learning_rate, eps=1e-5, foreach=True
        )
        self._last_obs = None
        self.episode_returns: deque[float] = deque(maxlen=100)

    def _state(self) -> dict[str, Any]:
        return {"policy": self.policy.state_dict(), "optimizer": self.optimizer.state_dict()}

    def _set_state(self, state: dict[str, Any]) -> None:
        self.policy.load_state_dict(state["policy"])
        self.optimizer.load_state_dict(state["optimizer"])

    def predict(self, obs: Any, deterministic: bool = True) -> tuple[np.ndarray, None]:
        """tanh(μ) when deterministic, else tanh of a sample."""
        with torch.no_grad():
            tensor = observation_to_tensor(batch_of_one(obs), self.observation_space)
            unsquashed, _, _ = self.policy.sample(tensor, deterministic, self.generator)
        return torch.tanh(unsquashed)[0].numpy(), None

    def _values(self, batch: Any) -> np.ndarray:
        """V of a batch of observations (K, ...) as float64 (K,)."""
        with torch.no_grad():
            tensor = observation_to_tensor(batch, self.observation_space)
            return self.policy(tensor)[1].double().numpy()

    def collect(self, callback: BaseCallback) -> Rollout | None:
        """``n_steps`` steps of each of the env's K worlds (fewer at the step budget), stored
        CleanRL's way as (n_steps, K) and flattened time-major for the update; None when the
        callback stops training. The env is one gymnasium env (K = 1) or an SB3 ``VecEnv`` of K
        worlds that resets a finished world in the step that ended it."""
        config, worlds = self.config, Worlds(self.env)
        count = worlds.count
        observations, unsquashed, log_probs, values, rewards, ends = [], [], [], [], [], []
        steps = min(config.n_steps, -(-(self._target - self.num_timesteps) // count))
        for _ in range(steps):
            with torch.no_grad():
                tensor = observation_to_tensor(self._last_obs, self.observation_space)
                action, log_prob, value = self.policy.sample(tensor, generator=self.generator)
            stepped = worlds.step(torch.tanh(action).numpy())
            new_obs, reward, terminated, truncated, final_obs, returns = stepped
            self.num_timesteps += count
            bootstrap = truncated & ~terminated  # time limit: bootstrap from the state it stopped in
            if bootstrap.any():
                reward = reward + config.gamma * np.where(bootstrap, self._values(final_obs), 0.0)
            observations.append(self._last_obs)
            unsquashed.append(action.numpy())
            log_probs.append(log_prob.numpy())
            values.append(value.double().numpy())
            rewards.append(reward)
            ends.append((terminated | truncated).astype(np.float64))
            self.episode_returns.extend(returns)
            self._last_obs = new_obs
            callback.update_locals(locals())
            if not callback.on_step():
                return None
        advantages, returns = compute_gae(
            np.array(rewards), np.array(values), np.array(ends),
            self._values(self._last_obs), config.gamma, config.gae_lambda,
        )  # fmt: skip
        flat = lambda arrays: np.concatenate(arrays)  # noqa: E731  (T of (K, ...)) → (T·K, ...) time-major
        if isinstance(self.observation_space, spaces.Dict):
            stacked = {key: flat([o[key] for o in observations]) for key in self.observation_space.spaces}
        else:
            stacked = flat(observations)
        return Rollout(
            observation_to_tensor(stacked, self.observation_space),
            torch.as_tensor(flat(unsquashed)),
            torch.as_tensor(flat(log_probs), dtype=torch.float32),
            torch.as_tensor(flat(values), dtype=torch.float32),
            torch.as_tensor(advantages.reshape(-1)),
            torch.as_tensor(returns.reshape(-1)),
        )

    def update(self, rollout: Rollout) -> dict[str, float]:
        """One policy update from a rollout; returns the metrics to log (``train/...``)."""
        raise NotImplementedError

    def learn(
        self,
        total_timesteps: int,
        callback: BaseCallback | None = None,
        reset_num_timesteps: bool = True,
        progress_bar: bool = False,
    ) -> OnPolicyAgent:
        """Collect and update until ``total_timesteps`` more steps were taken (see the contract in base)."""
        started = self._start_learning(total_timesteps, reset_num_timesteps)
        self._target, self._start_steps, start_time = started
        self._last_obs = Worlds(self.env).start(self._last_obs, self.observation_space)
        callback = self._start_callback(callback)
        callback.on_training_start(locals(), globals())
        while self.num_timesteps < self._target:
            callback.on_rollout_start()
            rollout = self.collect(callback)
            if rollout is None:
                break
            callback.on_rollout_end()
            # linear learning-rate decay to 0 over the whole budget, as SB3's linear schedules
            fraction_left = 1.0 - self.num_timesteps / max(self._target, 1)
            learning_rate = self.config.learning_rate * (fraction_left if self.config.linear_lr else 1.0)
            for group in self.optimizer.param_groups:
                group["lr"] = learning_rate
            metrics = self.update(rollout)
            metrics.update(learning_rate=learning_rate, std=self.policy.log_std.exp().mean().item())
            self._log_progress(metrics, self._start_steps, start_time)
        callback.on_training_end()
        return self
