"""stable-baselines3 algorithms behind drivelab's Agent protocol."""

from __future__ import annotations

from pathlib import Path

import gymnasium as gym
from gymnasium import spaces
from stable_baselines3 import A2C, DQN, PPO, SAC
from stable_baselines3.common.base_class import BaseAlgorithm

from drivelab.agents.sb3_params import check_sb3_hyperparams
from drivelab.errors import UsageError

SB3_CLASSES: dict[str, type[BaseAlgorithm]] = {"dqn": DQN, "ppo": PPO, "a2c": A2C, "sac": SAC}

# Defaults follow highway-env's documented SB3 examples (scripts/sb3_highway_*.py) where they
# exist; the rest are SB3's own. ``--hyperparams`` / YAML ``hyperparams`` override any key.
DEFAULT_HYPERPARAMS: dict[str, dict] = {
    "dqn": {
        "policy_kwargs": {"net_arch": [256, 256]},
        "learning_rate": 5e-4,
        "buffer_size": 15_000,
        "learning_starts": 200,
        "batch_size": 32,
        "gamma": 0.8,
        "train_freq": 1,
        "gradient_steps": 1,
        "target_update_interval": 50,
        "exploration_fraction": 0.7,
    },
    "ppo": {
        "policy_kwargs": {"net_arch": {"pi": [256, 256], "vf": [256, 256]}},
        "n_steps": 256,
        "batch_size": 64,
        "n_epochs": 10,
        "learning_rate": 5e-4,
        "gamma": 0.8,
    },
    "a2c": {"n_steps": 16, "learning_rate": 7e-4, "gamma": 0.8},
    "sac": {"buffer_size": 50_000, "learning_starts": 200, "batch_size": 64, "gamma": 0.9},
}


def policy_for(space: spaces.Space) -> str:
    """SB3 policy name for an observation space: Dict → MultiInput, image → Cnn, else Mlp."""
    if isinstance(space, spaces.Dict):
        return "MultiInputPolicy"
    if len(space.shape) == 3 and space.dtype.name == "uint8":
        return "CnnPolicy"
    return "MlpPolicy"


def seed_network_kwargs(algo: str, space: spaces.Space) -> dict:
    """policy_kwargs that give SB3 PPO/A2C seed 003's network: its CNN on an image, its fusion
    network on image + vectors, linear heads on the 256 features (as our own agents), actor and
    critic encoders shared for PPO and separate for A2C (as the seed)."""
    from drivelab.agents.networks import FusionExtractor, SeedCnnExtractor, observation_kind

    kind = observation_kind(space)
    if algo not in ("ppo", "a2c") or kind not in ("image", "image+vector"):
        raise UsageError(
            f"features_extractor=seed needs ppo or a2c on an image or image+vector observation, "
            f"got {algo!r} on {kind!r}"
        )
    extractor = SeedCnnExtractor if kind == "image" else FusionExtractor
    return {
        "features_extractor_class": extractor,
        "net_arch": [],
        "share_features_extractor": algo == "ppo",
        "normalize_images": True,
    }


def build_sb3(algo: str, env: gym.Env, seed: int, hyperparams: dict, log_dir: Path | None) -> BaseAlgorithm:
    """A fresh SB3 model for ``env``. ``features_extractor``: "sb3" (SB3's own networks, default)
    or "seed" (seed 003's CNN / fusion network, ``seed_network_kwargs``). ``device``: "cpu" (the
    default), "cuda" or "auto". Every value is checked first (``sb3_params``)."""
    kwargs = check_sb3_hyperparams(algo, {"device": "cpu", **DEFAULT_HYPERPARAMS[algo], **hyperparams})
    extractor = kwargs.pop("features_extractor", "sb3")
    if extractor == "seed":
        kwargs["policy_kwargs"] = {**seed_network_kwargs(algo, env.observation_space),
                                   **hyperparams.get("policy_kwargs", {})}  # fmt: skip
    elif extractor != "sb3":
        raise UsageError(f"features_extractor must be 'sb3' or 'seed', got {extractor!r}")
    return SB3_CLASSES[algo](
        policy_for(env.observation_space), env, seed=seed, verbose=0, **kwargs
    )


def load_sb3(algo: str, path: Path, env: gym.Env | None) -> BaseAlgorithm:
    """Load a saved SB3 model (``env`` may be None for acting only)."""
    return SB3_CLASSES[algo].load(path, env=env, device="cpu")
