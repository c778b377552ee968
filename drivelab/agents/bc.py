"""Behaviour cloning of the rule-based expert (``--algo bc``): supervised learning of the expert's
actions from the learner's own observation.

The expert (``expert.py``) reads privileged sensors; the learner reads the run's ``--obs``, e.g.
``topdown:lights=true,waypoints,measurements``. Training runs in rounds: ``round_steps`` steps of
demonstrations from the K training worlds (``imitation_data.py``) join the dataset, then ``epochs``
passes of minibatch Adam over all of it. The policy is our PPO's tanh-Gaussian actor-critic
(``networks.py``), so a cloned policy's weights load into ``ppo_own`` for fine-tuning.
Behaviour cloning is DAgger with β = 1 at every iteration (``dagger.py``).
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch
from gymnasium import spaces
from stable_baselines3.common.callbacks import BaseCallback
from torch import nn

from drivelab.agents.base import MAX_LEARNING_RATE, OwnAgent, gradient_step, observation_to_tensor
from drivelab.agents.expert import ExpertConfig, check_expert_env
from drivelab.agents.imitation_data import Demonstrations, Teacher, action_agreement, collect, stack_steps
from drivelab.agents.networks import TanhGaussianActorCritic, squashed_log_prob
from drivelab.agents.worlds import Worlds, batch_of_one, vector_env_of
from drivelab.errors import UsageError

LOSSES = ("mse", "nll")
ATANH_LIMIT = 1.0 - 1e-4  # expert actions at ±1 (full speed) are clipped before atanh for the NLL


@dataclass(frozen=True)
class BCConfig:
    """Hyper-parameters (``-H key=value``).

    :param learning_rate: Adam step size.
    :param batch_size: minibatch size.
    :param epochs: passes over the whole dataset after each round of demonstrations.
    :param round_steps: environment steps of demonstrations between two training phases.
    :param validation_fraction: share of the samples held out for the validation loss.
    :param loss: "mse" (squared error of tanh μ) or "nll" (tanh-Gaussian negative log-likelihood).
    :param max_grad_norm: gradient clipping by global norm.
    :param log_std_init: initial log σ (σ ≈ 0.37: a PPO fine-tuning starts near the cloned policy).
    :param expert_cruise_speed_mps: the teacher's ``cruise_speed_mps`` (``expert.ExpertConfig``).
    :param expert_lateral_accel_mps2: the teacher's ``lateral_accel_mps2``.
    :param expert_slip_aware: the teacher's ``slip_aware``; its ``max_speed_mps`` is the run's
        target_speed action's.
    """

    learning_rate: float = 1e-3
    batch_size: int = 256
    epochs: int = 2
    round_steps: int = 2000
    validation_fraction: float = 0.1
    loss: str = "mse"
    max_grad_norm: float = 1.0
    log_std_init: float = -1.0
    expert_cruise_speed_mps: float = ExpertConfig.cruise_speed_mps
    expert_lateral_accel_mps2: float = ExpertConfig.lateral_accel_mps2
    expert_slip_aware: bool = ExpertConfig.slip_aware

    def check(self, algo: str) -> None:
        if min(self.batch_size, self.epochs, self.round_steps) < 1:
            raise UsageError(f"{algo!r} needs batch_size, epochs and round_steps >= 1")
        if not 0 < self.learning_rate <= MAX_LEARNING_RATE or self.max_grad_norm <= 0:
            raise UsageError(
                f"{algo!r} needs 0 < learning_rate <= {MAX_LEARNING_RATE:g} and max_grad_norm > 0"
            )
        if not 0 <= self.validation_fraction < 1:
            raise UsageError(f"{algo!r} needs 0 <= validation_fraction < 1")
        if self.loss not in LOSSES:
            raise UsageError(f"{algo!r} loss must be one of {', '.join(LOSSES)}, got {self.loss!r}")
        if min(self.expert_cruise_speed_mps, self.expert_lateral_accel_mps2) <= 0:
            raise UsageError(
                f"{algo!r} needs a positive expert_cruise_speed_mps and expert_lateral_accel_mps2"
            )


def imitation_loss(
    policy: TanhGaussianActorCritic, obs: Any, expert: torch.Tensor, kind: str
) -> torch.Tensor:
    """The loss of a minibatch: ``mse`` = mean((tanh μ(s) − a*)²); ``nll`` = −mean log π(a*|s)
    for the tanh-Gaussian π (a* clipped into (−1, 1) for the inverse tanh).

    :param obs: batched observation tensors (B, …).
    :param expert: the expert's actions (B, A).
    """
    mean, _ = policy(obs)
    if kind == "mse":
        return nn.functional.mse_loss(torch.tanh(mean), expert)
    unsquashed = torch.atanh(expert.clamp(-ATANH_LIMIT, ATANH_LIMIT))
    return -squashed_log_prob(policy.distribution(mean), unsquashed).mean()


class BehaviourCloning(OwnAgent):
    """A learner that imitates the rule-based expert on its own observation (module docstring)."""

    config_class = BCConfig

    def _build(self) -> None:
        if not isinstance(self.action_space, spaces.Box) or self.action_space.shape != (2,):
            raise UsageError(f"{self.algo} imitates the expert's --action target_speed")
        teacher = {
            "cruise_speed_mps": self.config.expert_cruise_speed_mps,
            "lateral_accel_mps2": self.config.expert_lateral_accel_mps2,
            "slip_aware": self.config.expert_slip_aware,
        }
        if self.env is not None:
            vector = vector_env_of(self.env)
            teacher["max_speed_mps"] = getattr(vector.adapter, "max_speed_mps", ExpertConfig.max_speed_mps)
            check_expert_env(vector, teacher["max_speed_mps"], self.algo)
        self.policy = TanhGaussianActorCritic(
            self.observation_space, 2, shared_encoder=True, log_std_init=self.config.log_std_init
        )
        self.optimizer = torch.optim.Adam(self.policy.parameters(), lr=self.config.learning_rate)
        self.teacher = Teacher(teacher)
        self.replay_buffer = Demonstrations(
            self.observation_space, 2, self.config.validation_fraction, self.rng
        )
        self._n_updates = 0  # training phases done = DAgger iterations done
        self.episode_returns: deque[float] = deque(maxlen=100)

    @property
    def demonstrations(self) -> Demonstrations:
        """The labelled states gathered so far (checkpointed by run.py as the replay buffer)."""
        return self.replay_buffer

    def _modules(self) -> dict[str, Any]:
        return {"policy": self.policy, "optimizer": self.optimizer}

    def _state(self) -> dict[str, Any]:
        return {**super()._state(), "rounds": torch.tensor(self._n_updates)}

    def _set_state(self, state: dict[str, Any]) -> None:
        super()._set_state(state)
        self._n_updates = int(state["rounds"])

    # --- acting -----------------------------------------------------------------------------------
    def act(self, obs: Any, deterministic: bool = True) -> np.ndarray:
        """Actions (B, 2) for a batch of observations (B, …), clipped to the action space."""
        with torch.no_grad():
            tensor = observation_to_tensor(obs, self.observation_space)
            unsquashed, _, _ = self.policy.sample(tensor, deterministic, self.generator)
        actions = torch.tanh(unsquashed).numpy()
        return np.clip(actions, self.action_space.low, self.action_space.high)

    def predict(self, obs: Any, state=None, episode_start=None, deterministic: bool = True):
        """(tanh μ, or tanh of a sample when not deterministic, clipped; None) for one observation."""
        return self.act(batch_of_one(obs), deterministic)[0], None

    # --- DAgger's mixture ----------------------------------------------------------------------------
    def beta(self, iteration: int) -> float:
        """β of iteration ``iteration`` (1-based): the probability the expert acts. Cloning: always 1."""
        return 1.0

    # --- learning ---------------------------------------------------------------------------------
    def evaluate_on(self, indices: np.ndarray) -> dict[str, float]:
        """Loss and action agreement (``imitation_data.action_agreement``) on the samples ``indices``."""
        if len(indices) == 0:
            return {"loss": float("nan"), "agreement": float("nan")}
        data, losses, predicted = self.demonstrations, [], []
        with torch.no_grad():
            for chunk in np.array_split(indices, max(1, -(-len(indices) // 1024))):
                obs = observation_to_tensor(data.select(chunk), self.observation_space)
                expert = torch.as_tensor(data.actions[chunk])
                losses.append(float(imitation_loss(self.policy, obs, expert, self.config.loss)) * len(chunk))
                predicted.append(self.act(data.select(chunk)))
        agreement = action_agreement(np.concatenate(predicted), data.actions[indices])
        return {"loss": sum(losses) / len(indices), "agreement": agreement}

    def fit(self) -> dict[str, float]:
        """``epochs`` passes of minibatch Adam over the training samples; the mean training loss of
        the last pass, and the loss and agreement on the validation samples."""
        config, data = self.config, self.demonstrations
        training, validation = data.split()
        losses: list[float] = []
        for _ in range(config.epochs):
            losses = []
            order = training[torch.randperm(len(training), generator=self.generator).numpy()]
            for start in range(0, len(order), config.batch_size):
                rows = np.sort(order[start : start + config.batch_size])
                obs = observation_to_tensor(data.select(rows), self.observation_space)
                loss = imitation_loss(self.policy, obs, torch.as_tensor(data.actions[rows]), config.loss)
                gradient_step(self.optimizer, loss, self.policy.parameters(), config.max_grad_norm)
                losses.append(loss.item())
        held_out = self.evaluate_on(validation)
        return {
            "loss": float(np.mean(losses)) if losses else float("nan"),
            "validation_loss": held_out["loss"],
            "validation_agreement": held_out["agreement"],
            "dataset_size": len(data),
        }

    def _learn(self, worlds: Worlds, callback: BaseCallback, target: int) -> None:
        """Rounds: round i drives the K worlds with the mixture βᵢ (``beta``), labels every visited
        state with the expert's action, adds them to the dataset, then trains on all of it. The
        dataset and the weights change only after the round's last ``on_step``, so each round start
        is a safe point for the checkpoints."""

        def on_step(obs: Any) -> bool:
            self.num_timesteps += worlds.count
            self._last_obs = obs
            callback.update_locals(locals())
            return callback.on_step()

        while self.num_timesteps < target:
            callback.on_rollout_start()
            iteration = self._n_updates + 1
            beta = self.beta(iteration)
            steps = min(self.config.round_steps, target - self.num_timesteps)
            observations, labels, _, finished = collect(
                worlds, self.teacher, self._last_obs, -(-steps // worlds.count), beta,
                learner=self.act, rng=self.rng, on_step=on_step, episode_returns=self.episode_returns,
            )  # fmt: skip
            if not finished:
                break
            callback.on_rollout_end()
            self.demonstrations.add(
                stack_steps(observations, self.observation_space), np.concatenate(labels), iteration
            )
            metrics = self.fit()
            self._n_updates = iteration
            self._log_progress({**metrics, "beta": beta, "iteration": iteration})
