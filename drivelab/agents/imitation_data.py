"""Expert demonstrations for imitation (``bc``, ``dagger``): the teacher, the dataset, the collection loop.

The learner sees the run's ``--obs``; the rule-based expert reads the privileged ``waypoints`` and
``affordances``. Both are stateless, so the teacher computes them from the same ``WorldBatch`` the
environment has just observed (``VectorDriveEnv.batch``), one batched ``observe`` per step.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import torch
from gymnasium import spaces

from drivelab.agents.storage import read_arrays, split_meta, write_arrays
from drivelab.agents.worlds import Worlds, map_obs, row
from drivelab.errors import UsageError
from drivelab.perception.affordances import Affordances
from drivelab.perception.waypoints import Waypoints

AGREEMENT_TOLERANCE = 0.1  # an action agrees with the expert's when every component is this close


class Teacher:
    """The rule-based expert, acting from the privileged sensors computed on a ``WorldBatch``.

    :param hyperparams: the expert's own rules (``expert.ExpertConfig``), default its defaults.
    """

    def __init__(self, hyperparams: dict | None = None) -> None:
        from drivelab.agents.expert import RuleBasedExpert
        from drivelab.envs.actions import make_action

        self.sensors = {"waypoints": Waypoints(), "affordances": Affordances()}
        space = spaces.Dict({name: sensor.space for name, sensor in self.sensors.items()})
        with torch.random.fork_rng(devices=[]):  # an OwnAgent seeds torch: keep the caller's stream
            self.expert = RuleBasedExpert(space, make_action("target_speed").space, 0, hyperparams)

    def observe(self, batch) -> dict[str, np.ndarray]:
        """The expert's observations of every world: ``waypoints`` (K, 10, 2), ``affordances`` (K, 8)."""
        return {name: sensor.observe(batch) for name, sensor in self.sensors.items()}

    def actions(self, batch) -> np.ndarray:
        """(K, 2) ``[target speed fraction, steering]`` of the expert in each world of ``batch``."""
        views = self.observe(batch)
        rows = [self.expert.predict(row(views, k))[0] for k in range(batch.num_worlds)]
        return np.stack(rows).astype(np.float32)


def action_agreement(
    predicted: np.ndarray, expert: np.ndarray, tolerance: float = AGREEMENT_TOLERANCE
) -> float:
    """Fraction of the rows (N, A) of ``predicted`` whose every component is within ``tolerance`` of
    the expert's (action units: speed fraction in [0, 1], steering in [-1, 1])."""
    predicted, expert = np.asarray(predicted), np.asarray(expert)
    if len(expert) == 0:
        return float("nan")
    return float(np.mean(np.all(np.abs(predicted - expert) <= tolerance, axis=1)))


class Demonstrations:
    """Labelled states: the learner's observations (N, …) (a dict of arrays for a Dict space), the
    expert's actions (N, A), the DAgger iteration that visited each (N,) and a validation mask (N,),
    in arrays that grow by doubling.

    :param observation_space: the learner's observation space (one world).
    :param action_size: A.
    :param validation_fraction: each added sample goes to validation with this probability.
    :param rng: the generator of that draw.
    """

    def __init__(
        self,
        observation_space: spaces.Space,
        action_size: int,
        validation_fraction: float = 0.1,
        rng: np.random.Generator | None = None,
    ) -> None:
        self.observation_space, self.action_size = observation_space, int(action_size)
        self.validation_fraction = float(validation_fraction)
        self.rng = rng if rng is not None else np.random.default_rng(0)
        self._clear()

    def _clear(self) -> None:
        self.size = 0
        space = self.observation_space
        parts = space.spaces if isinstance(space, spaces.Dict) else space
        self._observations = map_obs(lambda sub: np.zeros((0, *sub.shape), dtype=sub.dtype), parts)
        self._actions = np.zeros((0, self.action_size), dtype=np.float32)
        self._iterations = np.zeros(0, dtype=np.int64)
        self._validation = np.zeros(0, dtype=bool)

    def __len__(self) -> int:
        return self.size

    # views of the filled part
    @property
    def observations(self) -> np.ndarray | dict[str, np.ndarray]:
        return map_obs(lambda array: array[: self.size], self._observations)

    @property
    def actions(self) -> np.ndarray:
        return self._actions[: self.size]

    @property
    def iterations(self) -> np.ndarray:
        return self._iterations[: self.size]

    @property
    def validation(self) -> np.ndarray:
        return self._validation[: self.size]

    def add(self, observations: Any, actions: np.ndarray, iteration: int = 1) -> None:
        """Append a batch: ``observations`` (B, …) (dict of arrays for a Dict space), ``actions`` (B, A)."""
        actions = np.asarray(actions, dtype=np.float32).reshape(-1, self.action_size)
        count = len(actions)
        validation = self.rng.random(count) < self.validation_fraction
        self._append(observations, actions, np.full(count, iteration, dtype=np.int64), validation)

    def _append(self, observations, actions, iterations, validation) -> None:
        count, end = len(actions), self.size + len(actions)
        if end > len(self._actions):
            capacity = max(end, 2 * len(self._actions), 256)
            self._observations = map_obs(lambda array: _grown(array, capacity), self._observations)
            self._actions = _grown(self._actions, capacity)
            self._iterations = _grown(self._iterations, capacity)
            self._validation = _grown(self._validation, capacity)
        rows = slice(self.size, end)
        if isinstance(self._observations, dict):
            for key, array in self._observations.items():
                array[rows] = np.asarray(observations[key]).reshape(count, *array.shape[1:])
        else:
            self._observations[rows] = np.asarray(observations).reshape(count, *self._observations.shape[1:])
        self._actions[rows], self._iterations[rows], self._validation[rows] = actions, iterations, validation
        self.size = end

    def split(self) -> tuple[np.ndarray, np.ndarray]:
        """(training indices, validation indices) of the samples held."""
        mask = self.validation
        return np.flatnonzero(~mask), np.flatnonzero(mask)

    def select(self, indices: np.ndarray) -> Any:
        """The observations of rows ``indices`` (an array, or a dict of arrays)."""
        return map_obs(lambda array: array[indices], self._observations)

    # --- files: npz of plain arrays ----------------------------------------------------------------
    def state_arrays(self) -> dict[str, np.ndarray]:
        """Every array (``obs`` or ``obs.<key>``, ``actions``, ``iterations``, ``validation``)."""
        labels = {"actions": self.actions, "iterations": self.iterations, "validation": self.validation}
        observations = self.observations
        if isinstance(observations, dict):
            return {**{f"obs.{key}": value for key, value in observations.items()}, **labels}
        return {"obs": observations, **labels}

    def load_state_arrays(self, arrays: dict[str, np.ndarray]) -> None:
        """Replace the samples held by those of ``state_arrays`` (shapes checked against the space)."""
        space = self.observation_space
        keys = list(space.spaces) if isinstance(space, spaces.Dict) else None
        observations = {key: arrays[f"obs.{key}"] for key in keys} if keys else arrays["obs"]
        for key, sub in (space.spaces if keys else {"": space}).items():
            array = observations[key] if keys else observations
            if array.shape[1:] != sub.shape:
                raise ValueError(
                    f"demonstrations of shape {array.shape[1:]} for a space of shape {sub.shape}"
                )
        actions = np.asarray(arrays["actions"], dtype=np.float32)
        if actions.ndim != 2 or actions.shape[1] != self.action_size:
            raise ValueError(
                f"demonstrated actions of shape {actions.shape} for {self.action_size} components"
            )
        self._clear()
        self._append(observations, actions, arrays["iterations"], arrays["validation"])

    def save(self, path: str | Path) -> None:
        """An ``.npz`` file of the arrays (the validation fraction as JSON metadata)."""
        write_arrays(path, self.state_arrays(), {"validation_fraction": self.validation_fraction})

    @classmethod
    def load(cls, path: str | Path, observation_space: spaces.Space, action_size: int) -> Demonstrations:
        """Demonstrations saved by ``save`` (read with ``allow_pickle=False``)."""
        arrays, meta = split_meta(read_arrays(path))
        data = cls(observation_space, action_size, meta.get("validation_fraction", 0.1))
        data.load_state_arrays(arrays)
        return data


def _grown(array: np.ndarray, capacity: int) -> np.ndarray:
    return np.pad(array, [(0, capacity - len(array))] + [(0, 0)] * (array.ndim - 1))


def collect(
    worlds: Worlds,
    teacher: Teacher,
    obs: Any,
    steps: int,
    beta: float = 1.0,
    learner: Callable[[Any], np.ndarray] | None = None,
    rng: np.random.Generator | None = None,
    on_step: Callable[[Any], bool] | None = None,
    episode_returns: list[float] | None = None,
) -> tuple[list, list, Any, bool]:
    """Drive ``steps`` steps of all K worlds from the batched observations ``obs`` (K, …),
    labelling each visited state.

    Each world's action is the expert's with probability ``beta``, else ``learner``'s (DAgger's
    mixture policy πᵢ = βᵢ·π* + (1 − βᵢ)·π̂ᵢ, drawn per world and step from ``rng``); the label is
    always the expert's. ``on_step(obs)`` runs after every step; returning False stops at once.
    The returns of the episodes that end are appended to ``episode_returns`` when given.

    :param learner: batched observations (K, …) → actions (K, A); not called when ``beta`` is 1.
    :returns: (observations per step (K, …), expert actions per step (K, A), the observation after
        the last step, whether it ran to the end).
    """
    observations, labels = [], []
    rng = rng if rng is not None else np.random.default_rng(0)
    for _ in range(steps):
        expert = teacher.actions(worlds.batch)
        actions = expert
        if beta < 1.0:
            from_learner = rng.random(worlds.count) >= beta
            if from_learner.any():
                actions = np.where(from_learner[:, None], learner(obs), expert).astype(np.float32)
        observations.append(map_obs(np.copy, obs))
        labels.append(expert)
        obs, _, _, _, _, returns = worlds.step(actions)
        if episode_returns is not None:
            episode_returns += returns
        if on_step is not None and not on_step(obs):
            return observations, labels, obs, False
    return observations, labels, obs, True


def stack_steps(observations: list, space: spaces.Space) -> Any:
    """Per-step batches [(K, …)] → one (steps·K, …) array (a dict of them for a Dict space)."""
    if isinstance(space, spaces.Dict):
        return {key: np.concatenate([o[key] for o in observations]) for key in space.spaces}
    return np.concatenate(observations)


def generate_demonstrations(
    steps: int,
    num_worlds: int = 8,
    seed: int = 0,
    obs: str | list = "topdown:lights=true,waypoints,measurements",
    traffic: str = "regular",
    validation_fraction: float = 0.1,
    expert_hyperparams: dict | None = None,
    **env_kwargs: Any,
) -> Demonstrations:
    """The expert driving ``num_worlds`` town worlds on the compiled core for ``steps`` steps in all,
    each state recorded with the learner's observation ``obs`` and labelled with the expert's action.

    :param env_kwargs: further ``VectorDriveEnv`` keywords (``backend``, ``duration_s``, ...).
    """
    from drivelab.agents.sb3_env import SB3VecEnv
    from drivelab.envs.vector import VectorDriveEnv

    if steps < 1 or num_worlds < 1:
        raise UsageError("generate_demonstrations needs steps >= 1 and num_worlds >= 1")
    env_kwargs.setdefault("scenario", "town")
    vector = VectorDriveEnv(
        num_worlds, obs=obs, action="target_speed", traffic=traffic, autoreset_mode="same_step", **env_kwargs
    )
    env = SB3VecEnv(vector)
    env.seed(seed)
    worlds, teacher = Worlds(env), Teacher(expert_hyperparams)
    data = Demonstrations(
        vector.single_observation_space, 2, validation_fraction, np.random.default_rng(seed)
    )
    observations, labels, _, _ = collect(worlds, teacher, worlds.reset(), -(-steps // num_worlds))
    data.add(stack_steps(observations, vector.single_observation_space), np.concatenate(labels))
    env.close()
    return data
