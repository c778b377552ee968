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
from drivelab.agents.networks import TanhGaussianActorCritic


def compute_gae(
    rewards: np.ndarray,
    values: np.ndarray,
    episode_ends: np.ndarray,
    last_value: float,
    gamma: float,
    gae_lambda: float,
) -> tuple[np.ndarray, np.ndarray]:
    """Generalised advantage estimation (Schulman et al. 2016, eq. 11-16), backwards in time.

    δ_t = r_t + γ·V(s_{t+1})·(1 − end_t) − V(s_t);  A_t = δ_t + γλ·(1 − end_t)·A_{t+1}.
    ``episode_ends[t]`` is 1 when the episode ended at step t (a time-limit end is bootstrapped by
    the caller, who adds γ·V(final observation) to its reward). Returns (advantages, returns = A + V).

    :param rewards: (T,) rewards.
    :param values: (T,) V(s_t).
    :param episode_ends: (T,) 1.0 where the episode ended after step t.
    :param last_value: V of the observation after the last step.
    """
    advantages = np.zeros(len(rewards), dtype=np.float32)
    next_advantage, next_value = 0.0, float(last_value)
    for t in reversed(range(len(rewards))):
        not_end = 1.0 - float(episode_ends[t])
        delta = rewards[t] + gamma * next_value * not_end - values[t]
        next_advantage = delta + gamma * gae_lambda * not_end * next_advantage
        advantages[t] = next_advantage
        next_value = values[t]
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

    def _value(self, obs: Any) -> float:
        with torch.no_grad():
            return float(self.policy(observation_to_tensor(batch_of_one(obs), self.observation_space))[1][0])

    def collect(self, callback: BaseCallback) -> Rollout | None:
        """``n_steps`` transitions (fewer at the step budget); None when the callback stops training."""
        config, env = self.config, self.env
        observations, unsquashed, log_probs, values, rewards, ends = [], [], [], [], [], []
        steps = min(config.n_steps, self._target - self.num_timesteps)
        for _ in range(steps):
            with torch.no_grad():
                tensor = observation_to_tensor(batch_of_one(self._last_obs), self.observation_space)
                action, log_prob, value = self.policy.sample(tensor, generator=self.generator)
            new_obs, reward, terminated, truncated, info = env.step(torch.tanh(action)[0].numpy())
            self.num_timesteps += 1
            if truncated and not terminated:  # time limit: bootstrap from the state it stopped in
                reward += config.gamma * self._value(new_obs)
            observations.append(self._last_obs)
            unsquashed.append(action[0].numpy())
            log_probs.append(float(log_prob[0]))
            values.append(float(value[0]))
            rewards.append(float(reward))
            ends.append(float(terminated or truncated))
            if "episode" in info:
                self.episode_returns.append(float(info["episode"]["r"]))
            if terminated or truncated:
                new_obs, _ = env.reset()
            self._last_obs = new_obs
            callback.update_locals(locals())
            if not callback.on_step():
                return None
        advantages, returns = compute_gae(
            np.array(rewards), np.array(values), np.array(ends),
            self._value(self._last_obs), config.gamma, config.gae_lambda,
        )  # fmt: skip
        if isinstance(self.observation_space, spaces.Dict):
            stacked = {key: np.stack([o[key] for o in observations]) for key in self.observation_space.spaces}
        else:
            stacked = np.stack(observations)
        return Rollout(
            observation_to_tensor(stacked, self.observation_space),
            torch.as_tensor(np.array(unsquashed)),
            torch.as_tensor(log_probs, dtype=torch.float32),
            torch.as_tensor(values, dtype=torch.float32),
            torch.as_tensor(advantages),
            torch.as_tensor(returns),
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
        if self._last_obs is None:
            self._last_obs, _ = self.env.reset()
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
