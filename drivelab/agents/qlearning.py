"""Tabular Q-learning with ε-greedy exploration (the CARLA study), behind drivelab's Agent protocol.

It reads a discrete observation (the ``line``, ``lane`` or ``ttc_grid`` sensors) and picks one of a
discrete action set. Defaults are the seed's: α = 0.8, γ = 0.9, ε from 0.9999, multiplied by 0.9998
after every step.
"""

from __future__ import annotations

import io
import json
import math
import zipfile
from dataclasses import asdict, dataclass, fields
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from stable_baselines3.common.logger import Logger

from drivelab.agents.base import parse_hyperparams
from drivelab.agents.storage import MAX_META_BYTES, STATE_OVERHEAD_BYTES, read_arrays, read_member
from drivelab.agents.worlds import Worlds
from drivelab.errors import UsageError

FORMAT = "drivelab-qlearning-1"


@dataclass(frozen=True)
class QLearningConfig:
    """Hyper-parameters (the CARLA study, sections 3.3 and 4.3).

    :param learning_rate: α of the update.
    :param gamma: discount factor γ.
    :param epsilon: initial exploration probability ε.
    :param epsilon_decay: ε is multiplied by this after every step.
    :param epsilon_min: ε never falls below this (the seed has no floor: 0).
    :param initial_q: value every Q(s, a) starts from.
    :param log_interval: episodes between logger dumps.
    """

    learning_rate: float = 0.8
    gamma: float = 0.9
    epsilon: float = 0.9999
    epsilon_decay: float = 0.9998
    epsilon_min: float = 0.0
    initial_q: float = 0.0
    log_interval: int = 10

    def __post_init__(self) -> None:
        self.check("qlearning")

    def check(self, algo: str) -> None:
        """Ranges of the values (their types are checked by ``parse_hyperparams``)."""
        if not 0 < self.learning_rate <= 1 or not 0 <= self.gamma <= 1:
            raise UsageError(f"{algo} needs 0 < learning_rate <= 1 and 0 <= gamma <= 1")
        if not 0 <= self.epsilon_min <= self.epsilon <= 1 or not 0 < self.epsilon_decay <= 1:
            raise UsageError(f"{algo} needs 0 <= epsilon_min <= epsilon <= 1 and 0 < epsilon_decay <= 1")
        if self.log_interval < 1 or not math.isfinite(self.initial_q):
            raise UsageError(f"{algo} needs log_interval >= 1 and a finite initial_q")


def observation_error(space: spaces.Space) -> str | None:
    """Why Q-learning cannot read ``space`` (None when it can): its table is indexed by a discrete
    state, which the ``line``, ``lane`` and ``ttc_grid`` sensors give."""
    if isinstance(space, spaces.Discrete):
        return None
    return (
        "needs a discrete observation (--obs line on follow-line, lane on follow-lane, or ttc_grid), "
        f"got {type(space).__name__}{getattr(space, 'shape', '')}"
    )


# The largest Q-table a discrete sensor and action give: the line state at its most strips (41^4
# states, perception/sensors.py's SIZE_LIMITS) by the 18 grid actions.
MAX_TABLE_CELLS = 41**4 * 18


def _discrete_size(space: spaces.Space, what: str) -> int:
    if not isinstance(space, spaces.Discrete):
        raise UsageError(
            f"qlearning needs a discrete {what} (observations: line, lane, ttc_grid; actions: seed_line, "
            f"seed_lane, meta, grid), got {type(space).__name__}{getattr(space, 'shape', '')}"
        )
    return int(space.n)


def _table_shape(env: gym.Env) -> tuple[int, int]:
    return _discrete_size(env.observation_space, "observation"), _discrete_size(env.action_space, "action")


class QLearning:
    """A Q-table over (state, action) learnt with the one-step Q-learning update (the CARLA study, eq. 1).

    :param env: a gymnasium environment with Discrete observation and action spaces.
    :param seed: seeds the exploration generator.
    :param config: hyper-parameters.
    :param log_dir: a run directory: every ``learn`` ends by writing the three-panel plot and the
        Q-table there (``write_run_artifacts``).
    """

    def __init__(self, env: gym.Env | None, seed: int = 0, config: QLearningConfig | None = None, *,
                 n_states: int | None = None, n_actions: int | None = None,
                 log_dir: str | Path | None = None) -> None:  # fmt: skip
        self.config = config or QLearningConfig()
        self.log_dir = Path(log_dir) if log_dir is not None else None
        self.env = env
        if env is not None:
            n_states, n_actions = _table_shape(env)
        if n_states is None or n_actions is None:
            raise ValueError("QLearning needs an env or both n_states and n_actions")
        self.q_table = np.full((n_states, n_actions), self.config.initial_q, dtype=np.float64)
        self.epsilon = self.config.epsilon
        self.num_timesteps = 0
        self.episode_returns: list[float] = []
        self.episode_lengths: list[int] = []
        self.seed = seed
        self.rng = np.random.default_rng(seed)
        self.logger = Logger(folder=None, output_formats=[])  # silent until a run sets one
        self._obs: int | None = None
        self._episode_return, self._episode_length = 0.0, 0

    # --- the Agent protocol -------------------------------------------------------------------
    def get_env(self) -> gym.Env | None:
        return self.env

    def set_env(self, env: gym.Env) -> None:
        _discrete_size(env.observation_space, "observation")
        self.env, self._obs = env, None

    def set_logger(self, logger: Logger) -> None:
        self.logger = logger

    def predict(self, observation: Any, state: Any = None, episode_start: Any = None,
                deterministic: bool = True) -> tuple[np.ndarray, None]:  # fmt: skip
        """The greedy action (``deterministic``) or an ε-greedy one for a state index."""
        state_index = int(np.asarray(observation).reshape(-1)[0])
        if deterministic:
            return np.asarray(int(np.argmax(self.q_table[state_index]))), None
        return np.asarray(self._explore(state_index)), None

    def _explore(self, state_index: int) -> int:
        """ε-greedy: a uniform random action with probability ε, else a greedy one (ties at random)."""
        if self.rng.random() < self.epsilon:
            return int(self.rng.integers(self.q_table.shape[1]))
        row = self.q_table[state_index]
        return int(self.rng.choice(np.flatnonzero(row == row.max())))

    def update(self, state: int, action: int, reward: float, next_state: int, terminal: bool) -> float:
        """One Q-learning update; returns the TD error.

        the CARLA study, eq. 1: Q(s, a) ← Q(s, a) + α [r + γ max_a' Q(s', a') − Q(s, a)], without the
        bootstrap term when the episode ended in a terminal state (not at a time limit).
        """
        target = reward if terminal else reward + self.config.gamma * float(self.q_table[next_state].max())
        error = target - self.q_table[state, action]
        self.q_table[state, action] += self.config.learning_rate * error
        return float(error)

    def learn(self, total_timesteps: int, callback: Any = None, reset_num_timesteps: bool = True,
              progress_bar: bool = False) -> QLearning:  # fmt: skip
        """Train for ``total_timesteps`` more environment steps (SB3's meaning; with
        ``reset_num_timesteps`` the step counter and ε restart from zero and ε0)."""
        if self.env is None:
            raise UsageError("this Q-learning agent has no environment to learn in")
        if reset_num_timesteps:
            self.num_timesteps, self.epsilon = 0, self.config.epsilon
        end = self.num_timesteps + int(total_timesteps)
        if callback is not None:
            callback.init_callback(self)
            callback.on_training_start(locals(), globals())
        worlds = Worlds(self.env)  # one world: the table learns from one stream of transitions
        if self._obs is None:
            self._obs = int(worlds.reset()[0])
            self._episode_return, self._episode_length = 0.0, 0
        while self.num_timesteps < end:
            state = self._obs
            action = self._explore(state)
            new_obs, rewards, terminated, truncated, final_obs, _ = worlds.step(np.array([action]))
            reward, done = float(rewards[0]), bool(terminated[0] or truncated[0])
            self.update(state, action, reward, int(final_obs[0]), bool(terminated[0]))
            self.num_timesteps += 1
            self.epsilon = max(self.config.epsilon_min, self.epsilon * self.config.epsilon_decay)
            self._episode_return += reward
            self._episode_length += 1
            if done:
                self._end_episode()
            self._obs = int(new_obs[0])  # after a reset when the episode ended
            if callback is not None:
                # the names SB3's callbacks read from an algorithm's rollout loop
                dones, infos = np.array([done]), worlds.infos  # noqa: F841
                callback.update_locals(locals())
                if not callback.on_step():
                    break
        if callback is not None:
            callback.on_training_end()
        if self.log_dir is not None and self.log_dir.is_dir():
            write_run_artifacts(self, self.log_dir)
        return self

    def _end_episode(self) -> None:
        self.episode_returns.append(self._episode_return)
        self.episode_lengths.append(self._episode_length)
        self.logger.record("rollout/episode_return", self._episode_return)
        self.logger.record("rollout/episode_length", self._episode_length)
        self.logger.record("train/epsilon", self.epsilon)
        self.logger.record("train/states_visited", int(np.count_nonzero(np.any(self.q_table != 0, axis=1))))
        self.logger.record("time/episodes", len(self.episode_returns))
        if len(self.episode_returns) % self.config.log_interval == 0:
            self.logger.dump(step=self.num_timesteps)
        self._episode_return, self._episode_length = 0.0, 0

    # --- persistence --------------------------------------------------------------------------
    def epsilon_history(self) -> np.ndarray:
        """ε before each step taken so far (ε0 · decay^t, floored at ε_min)."""
        steps = np.arange(self.num_timesteps)
        return np.maximum(self.config.epsilon * self.config.epsilon_decay**steps, self.config.epsilon_min)

    def save(self, path: str | Path) -> None:
        """A zip with ``q_table.npy``, ``state.json`` (hyper-parameters, ε, counters, the exploration
        generator) and ``episodes.npz`` (per-episode returns and lengths)."""
        state = {
            "format": FORMAT,
            "config": asdict(self.config),
            "epsilon": self.epsilon,
            "num_timesteps": self.num_timesteps,
            "seed": self.seed,
            "rng": self.rng.bit_generator.state,
        }
        table, episodes = io.BytesIO(), io.BytesIO()
        np.save(table, self.q_table)
        np.savez(episodes, returns=np.asarray(self.episode_returns), lengths=np.asarray(self.episode_lengths))
        with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as archive:
            archive.writestr("state.json", json.dumps(state))
            archive.writestr("q_table.npy", table.getvalue())
            archive.writestr("episodes.npz", episodes.getvalue())

    @classmethod
    def load(
        cls, path: str | Path, env: gym.Env | None = None, log_dir: str | Path | None = None
    ) -> QLearning:
        """An agent saved by ``save``; training continues exactly (same ε, counters, generator).
        Only JSON and numeric arrays are read: an object array (a pickle) is refused."""
        with zipfile.ZipFile(path) as archive:
            state = json.loads(read_member(archive, "state.json", MAX_META_BYTES))
            if not isinstance(state, dict) or state.get("format") != FORMAT:
                raise ValueError(f"{path} is not a drivelab Q-learning model")
            # bounded by what the table and the episode log (8-byte numbers) can be
            shape = None if env is None else _table_shape(env)
            cells = MAX_TABLE_CELLS if shape is None else shape[0] * shape[1]
            table = read_member(archive, "q_table.npy", 8 * cells + STATE_OVERHEAD_BYTES)
            q_table = np.load(io.BytesIO(table), allow_pickle=False)
            steps = state.get("num_timesteps")
            log_limit = 16 * (steps if isinstance(steps, int) and steps >= 0 else 0) + STATE_OVERHEAD_BYTES
            episodes = read_arrays(read_member(archive, "episodes.npz", log_limit))
        known = {f.name for f in fields(QLearningConfig)}
        config = QLearningConfig(**{k: v for k, v in state["config"].items() if k in known})
        agent = cls(None, state["seed"], config, n_states=q_table.shape[0], n_actions=q_table.shape[1],
                    log_dir=log_dir)  # fmt: skip
        if env is not None:
            if shape != q_table.shape:
                raise UsageError(f"Q-table {q_table.shape} does not fit this environment's spaces")
            agent.env = env
        agent.q_table = q_table
        agent.epsilon, agent.num_timesteps = float(state["epsilon"]), int(state["num_timesteps"])
        agent.rng.bit_generator.state = state["rng"]
        agent.episode_returns = episodes["returns"].tolist()
        agent.episode_lengths = [int(n) for n in episodes["lengths"]]
        return agent


def build_qlearning(algo: str, env: gym.Env, seed: int, hyperparams: dict, log_dir: Path | None) -> QLearning:
    """A fresh agent for ``env`` (the registry's builder signature); unknown keys, wrong types and
    values out of range fail."""
    known = {f.name for f in fields(QLearningConfig)}
    unknown = sorted(set(hyperparams) - known)
    if unknown:
        raise UsageError(
            f"unknown qlearning hyperparameter(s) {', '.join(unknown)} (known: {', '.join(sorted(known))})"
        )
    return QLearning(env, seed, parse_hyperparams(QLearningConfig, algo, hyperparams), log_dir=log_dir)


def load_qlearning(algo: str, path: Path, env: gym.Env | None, hyperparams: dict | None = None,
                   seed: int | None = None) -> QLearning:  # fmt: skip
    """A saved agent (the registry's loader signature); ``hyperparams`` and ``seed`` (the run's
    config) must be those it was saved with. Loaded from a run's ``checkpoints/`` to go on
    training, it writes its plot and Q-table into that run directory after each ``learn``."""
    path = Path(path)
    run_dir = path.parent.parent if path.parent.name == "checkpoints" else None
    agent = QLearning.load(path, env, log_dir=run_dir)
    if hyperparams is not None and agent.config != QLearningConfig(**hyperparams):
        raise ValueError("the model was saved with other hyperparameters than the run's config")
    if seed is not None and int(seed) != agent.seed:
        raise ValueError("the model was saved with another seed than the run's config")
    return agent


def write_run_artifacts(agent: QLearning, run_dir: str | Path) -> list[Path]:
    """Write the seed's three-panel plot and the Q-table (``.npy`` and ``.csv``) into ``run_dir``."""
    from drivelab.agents.qlearning_plots import plot_qlearning

    run_dir = Path(run_dir)
    np.save(run_dir / "q_table.npy", agent.q_table)
    header = "state," + ",".join(f"action_{a}" for a in range(agent.q_table.shape[1]))
    rows = np.column_stack([np.arange(len(agent.q_table)), agent.q_table])
    fmt = ["%d"] + ["%.6g"] * agent.q_table.shape[1]
    np.savetxt(run_dir / "q_table.csv", rows, delimiter=",", header=header, comments="", fmt=fmt)
    plot = plot_qlearning(agent.epsilon_history(), agent.episode_returns, agent.episode_lengths,
                          run_dir / "qlearning_curves.png")  # fmt: skip
    return [run_dir / "q_table.npy", run_dir / "q_table.csv", plot]
