"""Dueling Double DQN with prioritised replay (the MetaDrive study): a sum tree, the prioritised
replay (Schaul et al. 2016), the dueling network (Wang et al. 2016), the double-DQN target (van
Hasselt et al. 2016) and the agent, top to bottom.

The seed's input: ``--obs lidar:stack=3,ego_state:features=10:stack=3`` (240 beams + 10 features,
3 frames = 750 numbers) with the 18-action ``grid`` and its ``safety_dqn`` reward. Any vector
observation works: a Dict of vectors is concatenated in key order.
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

from drivelab.agents.base import MAX_LEARNING_RATE, OwnAgent, gradient_step
from drivelab.agents.buffer_memory import check_buffer_memory
from drivelab.agents.storage import assign_arrays
from drivelab.agents.worlds import Worlds, batch_of_one
from drivelab.errors import UsageError


@dataclass(frozen=True)
class DuelingDDQNConfig:
    """Hyper-parameters (``-H key=value``); replay and exploration defaults mirror drivelab's SB3 DQN.

    :param learning_rate: initial Adam step size, decayed linearly to ``final_learning_rate``.
    :param final_learning_rate: step size at the end of the budget (the seed's linear scheduler).
    :param buffer_size: replay capacity (transitions).
    :param learning_starts: steps of experience before the first update.
    :param batch_size: transitions per update.
    :param gamma: discount.
    :param train_freq: environment steps between updates.
    :param gradient_steps: updates each time.
    :param target_update_interval: steps between hard target copies (used when ``tau`` is 1).
    :param tau: Polyak factor: θ' ← τθ + (1 − τ)θ' every update; 1 means hard copies.
    :param exploration_initial_eps: ε at the start.
    :param exploration_final_eps: ε after ``exploration_fraction`` of the budget.
    :param exploration_fraction: fraction of the budget over which ε decays linearly.
    :param alpha: prioritisation exponent (0 gives uniform replay).
    :param beta_start: importance-sampling exponent at the start, annealed linearly to 1.
    :param priority_eps: added to |δ| so that no transition has zero priority.
    :param max_grad_norm: gradient clipping by global norm.
    :param stream_norm: "batch" (the seed's BatchNorm in the streams) or "layer".
    :param log_interval: environment steps between logger dumps.
    """

    learning_rate: float = 5e-4
    final_learning_rate: float = 5e-5
    buffer_size: int = 15_000
    learning_starts: int = 200
    batch_size: int = 32
    gamma: float = 0.8
    train_freq: int = 1
    gradient_steps: int = 1
    target_update_interval: int = 50
    tau: float = 1.0
    exploration_initial_eps: float = 1.0
    exploration_final_eps: float = 0.05
    exploration_fraction: float = 0.7
    alpha: float = 0.6
    beta_start: float = 0.4
    priority_eps: float = 1e-6
    max_grad_norm: float = 10.0
    stream_norm: str = "batch"
    log_interval: int = 250

    def check(self, algo: str) -> None:
        if min(self.buffer_size, self.train_freq, self.gradient_steps, self.target_update_interval) < 1:
            raise UsageError(
                f"{algo!r} needs buffer_size, train_freq, gradient_steps, target_update_interval >= 1"
            )
        if self.batch_size < 2 or self.learning_starts < 0 or self.log_interval < 1:
            raise UsageError(f"{algo!r} needs batch_size >= 2, learning_starts >= 0 and log_interval >= 1")
        if not 0 < self.tau <= 1 or not 0 < self.gamma <= 1 or not 0 <= self.beta_start <= 1:
            raise UsageError(f"{algo!r} needs 0 < tau <= 1, 0 < gamma <= 1 and 0 <= beta_start <= 1")
        if self.alpha < 0:
            raise UsageError(f"{algo!r} needs alpha >= 0")
        highest = MAX_LEARNING_RATE
        if not 0 < self.learning_rate <= highest or not 0 <= self.final_learning_rate <= highest:
            raise UsageError(
                f"{algo!r} needs 0 < learning_rate <= {MAX_LEARNING_RATE:g} "
                f"and 0 <= final_learning_rate <= {MAX_LEARNING_RATE:g}"
            )
        exploration = (self.exploration_initial_eps, self.exploration_final_eps, self.exploration_fraction)
        if not all(0 <= value <= 1 for value in exploration):
            raise UsageError(f"{algo!r} needs exploration_initial_eps, _final_eps and _fraction in [0, 1]")
        if self.priority_eps <= 0 or self.max_grad_norm <= 0:
            raise UsageError(f"{algo!r} needs priority_eps > 0 and max_grad_norm > 0")
        if self.stream_norm not in ("batch", "layer"):
            raise UsageError(f"{algo!r}: stream_norm must be 'batch' or 'layer', got {self.stream_norm!r}")


# --- sum tree ---------------------------------------------------------------------------------
class SumTree:
    """Leaf priorities under a complete binary tree whose nodes hold the sum of their children.

    Node 1 is the root; node k has children 2k and 2k+1; leaf i is node ``leaves + i``.

    :param capacity: number of leaves used (the tree rounds up to a power of two; the extra
        leaves keep priority 0 and are never drawn).
    """

    def __init__(self, capacity: int) -> None:
        self.capacity = int(capacity)
        self.leaves = 1 << max(self.capacity - 1, 1).bit_length()
        self.nodes = np.zeros(2 * self.leaves, dtype=np.float64)

    @property
    def total(self) -> float:
        return float(self.nodes[1])

    def priorities(self, indices: np.ndarray) -> np.ndarray:
        return self.nodes[self.leaves + np.asarray(indices)]

    def update(self, indices: np.ndarray, priorities: np.ndarray) -> None:
        """Set leaf priorities, then recompute the sums on each leaf's path to the root."""
        for index, priority in zip(np.atleast_1d(indices), np.atleast_1d(priorities), strict=True):
            node = self.leaves + int(index)
            self.nodes[node] = float(priority)
            node //= 2
            while node >= 1:
                self.nodes[node] = self.nodes[2 * node] + self.nodes[2 * node + 1]
                node //= 2

    def find(self, values: np.ndarray) -> np.ndarray:
        """Leaf index holding each cumulative value in [0, total): all values descend together."""
        values = np.array(values, dtype=np.float64)
        node = np.ones(len(values), dtype=np.int64)
        while node[0] < self.leaves:
            left = 2 * node
            go_right = values >= self.nodes[left]
            values = np.where(go_right, values - self.nodes[left], values)
            node = left + go_right
        leaf = node - self.leaves
        # float round-off can land on an empty leaf past the end: fall back to the last used one
        return np.minimum(leaf, self.capacity - 1)


# --- prioritised replay -------------------------------------------------------------------------
class PrioritizedReplayBuffer:
    """A ring buffer of transitions sampled with probability p_i^α / Σ_j p_j^α.

    :param capacity: transitions kept.
    :param observation_size: length of a (flattened) observation.
    :param alpha: prioritisation exponent.
    :param priority_eps: added to |δ| in ``update_priorities``.
    """

    ARRAYS = ("observations", "next_observations", "actions", "rewards", "terminals")  # a row per transition
    SCALARS = ("max_priority", "position", "size")

    def __init__(self, capacity: int, observation_size: int, alpha: float, priority_eps: float) -> None:
        self.capacity, self.alpha, self.priority_eps = int(capacity), float(alpha), float(priority_eps)
        self.observations = np.zeros((self.capacity, observation_size), dtype=np.float32)
        self.next_observations = np.zeros((self.capacity, observation_size), dtype=np.float32)
        self.actions = np.zeros(self.capacity, dtype=np.int64)
        self.rewards = np.zeros(self.capacity, dtype=np.float32)
        self.terminals = np.zeros(self.capacity, dtype=np.float32)
        self.tree = SumTree(self.capacity)
        self.max_priority = 1.0  # stored as p^α; new transitions get the largest seen
        self.position, self.size = 0, 0

    def add_many(self, observations, actions, rewards, next_observations, terminals) -> None:
        """M transitions (K worlds' steps, in world order), each at the largest priority seen."""
        for m in range(len(actions)):
            i = self.position
            self.observations[i], self.next_observations[i] = observations[m], next_observations[m]
            self.actions[i], self.rewards[i], self.terminals[i] = actions[m], rewards[m], float(terminals[m])
            self.position, self.size = (i + 1) % self.capacity, min(self.size + 1, self.capacity)
            self.tree.update(np.array([i]), np.array([self.max_priority]))

    def sample(
        self, batch_size: int, beta: float, rng: np.random.Generator
    ) -> tuple[np.ndarray, dict[str, np.ndarray], np.ndarray]:
        """(indices, batch, importance weights): one draw in each of ``batch_size`` equal slices
        of the total priority (stratified), weights w_i = (N·P(i))^−β / max_j w_j."""
        segment = self.tree.total / batch_size
        indices = self.tree.find((np.arange(batch_size) + rng.random(batch_size)) * segment)
        indices = np.minimum(indices, self.size - 1)  # round-off past the last stored transition
        probabilities = self.tree.priorities(indices) / self.tree.total
        weights = (self.size * probabilities) ** (-beta)
        weights = weights / weights.max()
        batch = {name: getattr(self, name)[indices] for name in self.ARRAYS}
        return indices, batch, weights.astype(np.float32)

    def update_priorities(self, indices: np.ndarray, td_errors: np.ndarray) -> None:
        """p_i = (|δ_i| + ε)^α."""
        priorities = (np.abs(td_errors) + self.priority_eps) ** self.alpha
        self.tree.update(indices, priorities)
        self.max_priority = max(self.max_priority, float(priorities.max()))

    def state_arrays(self) -> dict[str, np.ndarray]:
        """Everything the buffer holds, sum tree included, as arrays (a checkpoint's ``.npz``)."""
        arrays = {name: getattr(self, name) for name in self.ARRAYS}
        scalars = {name: np.asarray(getattr(self, name)) for name in self.SCALARS}
        return {**arrays, **scalars, "tree_nodes": self.tree.nodes}

    def load_state_arrays(self, arrays: dict[str, np.ndarray]) -> None:
        """Restore ``state_arrays`` into this buffer (same capacity and observation size)."""
        assign_arrays(self, arrays, self.ARRAYS + self.SCALARS)
        nodes = {"nodes": arrays["tree_nodes"]} if "tree_nodes" in arrays else {}
        assign_arrays(self.tree, nodes, ("nodes",))


# --- dueling network ----------------------------------------------------------------------------
def _stream(inputs: int, outputs: int, norm: str) -> nn.Sequential:
    """256 → 256 → 128 → outputs with a normalisation + ReLU after each hidden layer."""
    normalisation = nn.BatchNorm1d if norm == "batch" else nn.LayerNorm
    return nn.Sequential(
        nn.Linear(inputs, 256), normalisation(256), nn.ReLU(),
        nn.Linear(256, 128), normalisation(128), nn.ReLU(),
        nn.Linear(128, outputs),
    )  # fmt: skip


class DuelingQNetwork(nn.Module):
    """Q(s, ·) from a shared feature trunk and separate value and advantage streams.

    :param observation_size: input length (750 for the seed's stacked LiDAR + features).
    :param actions: number of discrete actions (18 for the seed's grid).
    :param stream_norm: "batch" or "layer" normalisation in the streams.
    """

    def __init__(self, observation_size: int, actions: int, stream_norm: str = "batch") -> None:
        super().__init__()
        self.features = nn.Sequential(
            nn.Linear(observation_size, 512), nn.LayerNorm(512), nn.ReLU(),
            nn.Linear(512, 512), nn.LayerNorm(512), nn.ReLU(),
            nn.Linear(512, 256), nn.LayerNorm(256), nn.ReLU(),
        )  # fmt: skip
        self.value = _stream(256, 1, stream_norm)
        self.advantage = _stream(256, actions, stream_norm)

    def forward(self, observations: torch.Tensor) -> torch.Tensor:
        features = self.features(observations)
        return dueling_q_values(self.value(features), self.advantage(features))


def dueling_q_values(value: torch.Tensor, advantage: torch.Tensor) -> torch.Tensor:
    """Q(s, a) = V(s) + (A(s, a) − mean_a' A(s, a')) (Wang et al. 2016, eq. 9)."""
    return value + advantage - advantage.mean(dim=1, keepdim=True)


# --- double-DQN target --------------------------------------------------------------------------
def double_dqn_targets(
    rewards: torch.Tensor,
    terminals: torch.Tensor,
    next_q_online: torch.Tensor,
    next_q_target: torch.Tensor,
    gamma: float,
) -> torch.Tensor:
    """y = r + γ·(1 − terminal)·Q_target(s', argmax_a Q_online(s', a)): the online network picks,
    the target network evaluates (van Hasselt et al. 2016, eq. 4)."""
    best = next_q_online.argmax(dim=1, keepdim=True)
    return rewards + gamma * (1.0 - terminals) * next_q_target.gather(1, best).squeeze(1)


# --- the agent ----------------------------------------------------------------------------------
def flatten_batch(batch: Any, space: spaces.Space) -> np.ndarray:
    """K observations (batched, a Dict key by key) as (K, flat size) float32, a Dict's parts
    concatenated in key order; for a float32 Box, a view of ``batch`` (write into a copy)."""
    if isinstance(space, spaces.Dict):
        parts = [np.asarray(batch[key], dtype=np.float32) for key in space.spaces]
        return np.concatenate([part.reshape(len(part), -1) for part in parts], axis=1)
    batch = np.asarray(batch, dtype=np.float32)
    return batch.reshape(len(batch), -1)


def linear(start: float, end: float, progress: float) -> float:
    """start → end as progress goes 0 → 1, constant after."""
    return start + (end - start) * min(max(progress, 0.0), 1.0)


class DuelingDoubleDQN(OwnAgent):
    """The MetaDrive study's Dueling Double DQN agent with prioritised replay."""

    config_class = DuelingDDQNConfig
    log_every: int | None = None  # steps between progress rows for a run's budget (``log_over``)

    def log_over(self, total_steps: int) -> None:
        """Log every ``log_interval`` steps, or often enough for about ten rows over a run of
        ``total_steps`` too short for ten at it (a short run would leave progress.csv empty)."""
        self.log_every = max(1, min(self.config.log_interval, total_steps // 10))

    def _build(self) -> None:
        if not isinstance(self.action_space, spaces.Discrete):
            raise ValueError("dueling_ddqn needs discrete actions")
        config = self.config
        self.observation_size = spaces.flatdim(self.observation_space)
        transition_bytes = 2 * 4 * self.observation_size  # observation and next one, float32
        check_buffer_memory(self.algo, "buffer_size", config.buffer_size, transition_bytes, "replay buffer")
        check_buffer_memory(self.algo, "batch_size", config.batch_size, transition_bytes, "training batch")
        architecture = (self.observation_size, int(self.action_space.n), config.stream_norm)
        self.q_network, self.target_network = DuelingQNetwork(*architecture), DuelingQNetwork(*architecture)
        self.target_network.load_state_dict(self.q_network.state_dict())
        self.target_network.eval()
        self.optimizer = torch.optim.Adam(self.q_network.parameters(), lr=config.learning_rate, foreach=True)
        self.replay_buffer = PrioritizedReplayBuffer(
            config.buffer_size, self.observation_size, config.alpha, config.priority_eps
        )
        self.episode_returns: deque[float] = deque(maxlen=100)

    def _modules(self) -> dict[str, Any]:
        return {name: getattr(self, name) for name in ("q_network", "target_network", "optimizer")}

    def q_values(self, observations: np.ndarray) -> torch.Tensor:
        """Q(s, ·) for a batch of flat observations, BatchNorm on its running statistics."""
        self.q_network.eval()
        with torch.no_grad():
            return self.q_network(torch.as_tensor(observations, dtype=torch.float32))

    def predict(self, obs: Any, deterministic: bool = True) -> tuple[np.ndarray, None]:
        """argmax_a Q(s, a) (ε-greedy with the final ε when not deterministic)."""
        if not deterministic and self.rng.random() < self.config.exploration_final_eps:
            return np.array(self.rng.integers(self.action_space.n)), None
        flat = flatten_batch(batch_of_one(obs), self.observation_space)
        return np.array(int(self.q_values(flat).argmax(dim=1)[0])), None

    def train_step(self, progress: float) -> dict[str, float]:
        """One gradient step on a prioritised batch; refreshes the batch's priorities."""
        config = self.config
        beta = linear(config.beta_start, 1.0, progress)
        indices, batch, weights = self.replay_buffer.sample(config.batch_size, beta, self.rng)
        tensors = {key: torch.as_tensor(value) for key, value in batch.items()}
        with torch.no_grad():
            next_q_online = self.q_values(batch["next_observations"])
            next_q_target = self.target_network(tensors["next_observations"])
            targets = double_dqn_targets(
                tensors["rewards"], tensors["terminals"], next_q_online, next_q_target, config.gamma
            )
        self.q_network.train()
        q_taken = self.q_network(tensors["observations"]).gather(1, tensors["actions"][:, None]).squeeze(1)
        td_errors = targets - q_taken
        # importance-weighted Huber loss: the weights undo the bias of prioritised sampling
        loss = (
            torch.as_tensor(weights) * nn.functional.smooth_l1_loss(q_taken, targets, reduction="none")
        ).mean()
        gradient_step(self.optimizer, loss, self.q_network.parameters(), config.max_grad_norm)
        self.replay_buffer.update_priorities(indices, td_errors.detach().numpy())
        return {"loss": loss.item(), "td_error": td_errors.abs().mean().item(), "beta": beta,
                "q_mean": q_taken.mean().item()}  # fmt: skip

    def update_target(self) -> None:
        """θ' ← τθ + (1 − τ)θ' (τ = 1: a hard copy), buffers (BatchNorm statistics) copied."""
        target_network, q_network, tau = self.target_network, self.q_network, self.config.tau
        with torch.no_grad():
            for target, online in zip(target_network.parameters(), q_network.parameters(), strict=True):
                target.mul_(1.0 - tau).add_(online, alpha=tau)
            for target, online in zip(target_network.buffers(), q_network.buffers(), strict=True):
                target.copy_(online)

    def _learn(self, worlds: Worlds, callback: BaseCallback, target: int) -> None:
        """Act ε-greedily in each of the K worlds, store, learn. ``train_freq``,
        ``target_update_interval`` and ``log_interval`` count transitions of all worlds."""
        config = self.config
        metrics: dict[str, float] = {}
        while self.num_timesteps < target:
            callback.on_rollout_start()  # a safe point: nothing is half-done (contract in base.py)
            progress = self.num_timesteps / max(target, 1)
            explored = progress / config.exploration_fraction if config.exploration_fraction else 1.0
            epsilon = linear(config.exploration_initial_eps, config.exploration_final_eps, explored)
            observations = flatten_batch(self._last_obs, self.observation_space)
            explore = self.rng.random(worlds.count) < epsilon
            actions = np.zeros(worlds.count, dtype=np.int64)
            if not explore.all():
                actions[:] = self.q_values(observations).argmax(dim=1).numpy()
            for k in np.flatnonzero(explore):  # one draw per exploring world, in world order
                actions[k] = self.rng.integers(self.action_space.n)
            new_obs, rewards, terminated, truncated, final_obs, returns = worlds.step(actions)
            before, self.num_timesteps = self.num_timesteps, self.num_timesteps + worlds.count
            callback.update_locals(locals())
            if not callback.on_step():  # before the step changes the replay or the networks
                break
            # a time-limit end is not terminal: its target still bootstraps from the next state
            next_observations = flatten_batch(new_obs, self.observation_space)
            ended = terminated | truncated
            if ended.any():  # into a copy: new_obs holds the new episodes' first observations
                next_observations = next_observations.copy()
                next_observations[ended] = flatten_batch(final_obs, self.observation_space)[ended]
            self.replay_buffer.add_many(observations, actions, rewards, next_observations, terminated)
            self.episode_returns.extend(returns)
            self._last_obs = new_obs
            learning_rate = linear(config.learning_rate, config.final_learning_rate, progress)
            ready = (
                self.num_timesteps > config.learning_starts and self.replay_buffer.size >= config.batch_size
            )
            trainings = _multiples(before, self.num_timesteps, config.train_freq)
            if ready and trainings:
                for group in self.optimizer.param_groups:
                    group["lr"] = learning_rate
                for _ in range(config.gradient_steps * trainings):
                    metrics = self.train_step(progress)
                if config.tau < 1.0:
                    self.update_target()
            if config.tau == 1.0 and _multiples(before, self.num_timesteps, config.target_update_interval):
                self.update_target()
            if _multiples(before, self.num_timesteps, self.log_every or config.log_interval):
                schedule = {"epsilon": epsilon, "learning_rate": learning_rate}
                self._log_progress({**metrics, **schedule})


def _multiples(before: int, after: int, every: int) -> int:
    """How many multiples of ``every`` lie in (before, after]: for one world, 1 when ``after`` is
    one and 0 otherwise (the ``after % every == 0`` test)."""
    return after // every - before // every
