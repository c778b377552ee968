"""Same seed and same actions give identical observations, rewards and metrics."""

import numpy as np

import drivelab


def _rollout(seed: int, actions):
    env = drivelab.make(
        "highway",
        obs="kinematics,lidar:noise_std=0.05,topdown",
        action="grid",
        reward="metadrive_course",
        traffic="regular",
        duration_s=6,
    )
    obs, _ = env.reset(seed=seed)
    trace = [obs]
    for action in actions:
        obs, reward, terminated, truncated, info = env.step(action)
        trace.append((obs, reward, info["reward_terms"], info.get("episode_metrics")))
        if terminated or truncated:
            break
    return trace


def _equal(a, b):
    if isinstance(a, dict):
        return a.keys() == b.keys() and all(_equal(a[k], b[k]) for k in a)
    if isinstance(a, (tuple, list)):
        return len(a) == len(b) and all(_equal(x, y) for x, y in zip(a, b, strict=True))
    if isinstance(a, np.ndarray):
        return np.array_equal(a, b)
    if isinstance(a, float) and np.isnan(a):
        return np.isnan(b)
    return a == b


def test_same_seed_same_actions_identical():
    actions = [7, 8, 7, 10, 8, 7, 1, 16] * 4
    first, second = _rollout(3, actions), _rollout(3, actions)
    assert _equal(first, second)
    assert first[-1][3] is not None  # the episode ended and reported metrics


def test_different_seed_differs():
    actions = [7] * 5
    assert not _equal(_rollout(3, actions), _rollout(4, actions))
