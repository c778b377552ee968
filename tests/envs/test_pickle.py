"""Environments pickle with the standard library (multiprocessing, Ray and SB3's SubprocVecEnv rely
on it), and an unpickled copy goes on exactly as the original would."""

import pickle

import gymnasium
import numpy as np
import pytest

from drivelab.envs.vector import VectorDriveEnv
from drivelab.scenarios import FAST_SCENARIOS as SUPPORTED
from drivelab.scenarios import REFERENCE_SCENARIOS, SCENARIOS
from tests.batch_worlds import assert_same_observations

ENV_IDS = sorted(env_id for env_id in gymnasium.registry if env_id.startswith("drivelab/"))
CASES = [
    (env_id, backend)
    for env_id in ENV_IDS
    for backend in ("highway", "fast")
    if gymnasium.spec(env_id).kwargs["scenario"]
    in (REFERENCE_SCENARIOS if backend == "highway" else SUPPORTED)
]


def test_every_scenario_has_a_case():
    """The table below covers every registered scenario, and the fast backend where it runs."""
    scenarios = {gymnasium.spec(env_id).kwargs["scenario"] for env_id, _ in CASES}
    assert scenarios == set(SCENARIOS)
    assert {b for _, b in CASES} == {"highway", "fast"}


@pytest.mark.parametrize("env_id, backend", CASES)
def test_env_round_trips_through_pickle_mid_episode(env_id, backend):
    env = gymnasium.make(env_id, backend=backend, obs="kinematics,lidar:beams=16", duration_s=20)
    env.reset(seed=3)
    env.action_space.seed(0)
    for _ in range(2):
        env.step(env.action_space.sample())
    copy = pickle.loads(pickle.dumps(env))
    assert type(copy.unwrapped.simulator) is type(env.unwrapped.simulator)
    for _ in range(4):
        action = env.action_space.sample()
        original, restored = env.step(action), copy.step(action)
        assert_same_observations(original[0], restored[0])
        assert original[1:4] == restored[1:4]  # reward, terminated, truncated
        if original[2] or original[3]:
            break


@pytest.mark.parametrize("backend", ["fast", "highway"])
def test_vector_env_round_trips_through_pickle(backend):
    vector = VectorDriveEnv(2, scenario="merge", backend=backend, obs="kinematics")
    vector.reset(seed=5)
    vector.action_space.seed(1)
    vector.step(vector.action_space.sample())
    copy = pickle.loads(pickle.dumps(vector))
    for _ in range(3):
        actions = vector.action_space.sample()
        original, restored = vector.step(actions), copy.step(actions)
        assert_same_observations(original[0], restored[0])
        for a, b in zip(original[1:4], restored[1:4], strict=True):
            np.testing.assert_array_equal(a, b)
