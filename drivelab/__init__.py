"""drivelab: train, compare and dissect reinforcement-learning driving agents."""

from __future__ import annotations

__version__ = "0.1.0"

from drivelab import _numba_cache

_numba_cache.configure()  # before any kernel is decorated: numba's cache per version of the sources

import drivelab.envs  # noqa: E402, F401  (registers the gymnasium ids)


def make(scenario: str, **kwargs):
    """Build a DriveEnv: ``drivelab.make("highway", obs=["lidar", "topdown"], seed=0)``.

    ``scenario`` is a name or its gymnasium id (``"drivelab/Highway-v0"``); the keyword arguments
    are ``gymnasium.make``'s (see DriveEnv), ``config={...}`` a highway-env config dict:
    ``drivelab.make("highway", config={"observation": {"type": "Kinematics"}, "lanes_count": 4})``."""
    from drivelab.envs.core import DriveEnv

    return DriveEnv(scenario=scenario, **kwargs)


def load(target):
    """The trained agent of a run directory or of a shipped agent (``drivelab zoo``), with
    stable-baselines3's ``predict``: ``drivelab.load("highway-ppo").predict(obs)`` → (action,
    state). See ``drivelab.api.Model``; nothing is unpickled."""
    from drivelab.api import load as load_model

    return load_model(target)
