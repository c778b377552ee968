"""drivelab's Python API for trained agents: ``drivelab.load`` and the ``Model`` it returns.

    import drivelab

    model = drivelab.load("highway-ppo")  # a shipped agent (``drivelab zoo``), or "runs/NAME"
    env = model.make_env()                # the environment it was trained and is evaluated on
    obs, info = env.reset(seed=0)
    action, _ = model.predict(obs)        # greedy, as ``drivelab evaluate``

A model is read as every drivelab command reads a run: nothing is unpickled (``agents/storage.py``).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from gymnasium import spaces

from drivelab.config import RunConfig


class Model:
    """A trained agent of a run directory or of the zoo, with stable-baselines3's ``predict``.

    :ivar agent: the agent itself (an SB3 model, or drivelab's own agent class).
    :ivar config: the run's resolved config (``config.yaml``).
    :ivar run_dir: the run directory it was loaded from (a shipped agent's folder in the package).
    :ivar name: the shipped agent's name, or None for a run directory.
    :ivar observation_space: with ``action_space``, the spaces of ``make_env()``'s environment."""

    def __init__(self, agent: Any, config: RunConfig, run_dir: Path, name: str | None, env) -> None:
        self.agent, self.config, self.run_dir, self.name = agent, config, run_dir, name
        self.observation_space: spaces.Space = env.observation_space
        self.action_space: spaces.Space = env.action_space

    @property
    def algo(self) -> str:
        """The algorithm's name (``drivelab envs`` lists them)."""
        return self.config.algo

    @property
    def num_timesteps(self) -> int:
        """Environment steps the agent was trained for."""
        return int(self.agent.num_timesteps)

    def predict(
        self,
        observation: Any,
        state: Any = None,
        episode_start: Any = None,
        deterministic: bool = True,
    ) -> tuple[np.ndarray, Any]:
        """(action, state) for an observation, or for a batch of them (a leading axis), as
        stable-baselines3's ``predict`` but greedy by default (as ``drivelab evaluate``). drivelab
        has no recurrent policies: the returned state is None."""
        from drivelab.agents.registry import get_algo

        if get_algo(self.config.algo).family == "sb3":
            return self.agent.predict(
                observation, state=state, episode_start=episode_start, deterministic=deterministic
            )
        if not _is_batch(observation, self.observation_space):
            return np.asarray(self.agent.predict(observation, deterministic=deterministic)[0]), None
        actions = [
            self.agent.predict(one, deterministic=deterministic)[0]
            for one in _unbatch(observation, self.observation_space)
        ]
        return np.stack([np.asarray(action) for action in actions]), None

    def make_env(self, **overrides: Any):
        """A new ``DriveEnv`` of the run's evaluation environment; ``overrides``: other
        ``drivelab.make`` keyword arguments (``render_mode="rgb_array"``), which must leave the
        spaces as they are."""
        from drivelab.envs.core import DriveEnv

        return DriveEnv(**{**self.config.eval_env_kwargs(), **overrides})

    def __repr__(self) -> str:
        where = f"zoo agent {self.name!r}" if self.name else f"run {str(self.run_dir)!r}"
        return f"<drivelab.Model {self.algo} on {self.config.env}, {self.num_timesteps} steps, {where}>"


def _is_batch(observation: Any, space: spaces.Space) -> bool:
    """Whether ``observation`` is a batch of observations of ``space`` (one more leading axis)."""
    if isinstance(space, spaces.Dict):
        key = next(iter(space.spaces))
        return _is_batch(observation[key], space.spaces[key])
    shape = np.shape(observation)
    if isinstance(space, spaces.Discrete):
        return len(shape) == 1
    return space.shape is not None and len(shape) == len(space.shape) + 1


def _unbatch(observation: Any, space: spaces.Space) -> list[Any]:
    """A batch of observations as a list of single ones (dicts key by key)."""
    if isinstance(space, spaces.Dict):
        count = len(observation[next(iter(space.spaces))])
        return [
            {key: np.asarray(value)[index] for key, value in observation.items()} for index in range(count)
        ]
    return list(np.asarray(observation))


def load(target: str | Path) -> Model:
    """The trained agent of a run directory or of a shipped agent named by ``drivelab zoo`` (an
    existing directory of that name wins): its final model, else its latest verified checkpoint.
    Refused with the ``UsageError`` the commands print for anything else, a model that does not
    match its config.yaml, a run being trained now and a run in the old pickle format. Nothing is
    unpickled."""
    from drivelab.training.zoo import load_trained

    trained = load_trained(target)
    return Model(trained.agent, trained.config, trained.run_dir, trained.name, trained.env)
