"""The circuits' compiled step (envs/fused.py) against the pipeline it replaces.

Each test runs two envs of the same configuration side by side, one with the compiled step and
one with it switched off (``vector._fused = None``: the pipeline of simulator, rules, reward
terms, metrics, sensor and infos), from the same seeds with the same actions, resets included.
The simulation is the same compiled code in both, so positions, events and terminations must be
equal exactly. The observations and rewards may differ in rounding only: the compiled step takes
the cosine and sine of the ego's heading (and ``steering_power``'s power) from libm, the pipeline
from numpy, which on CPUs with AVX-512 dispatches SIMD versions that can differ in the last bit.
A value of magnitude ≤ 1e3 built from a handful of such operations is within 1e-9 of the other.
"""

from __future__ import annotations

import pickle

import numpy as np
import pytest

from drivelab.envs.core import DriveEnv
from drivelab.envs.vector import VectorDriveEnv

CIRCUITS = ("follow-line", "follow-lane")
REWARD_ATOL = 1e-9
OBS_ATOL = 1e-6  # float32 observations: one float32 ulp of a value in [-1, 1] is ≤ 1.2e-7


def _pair(make):
    """Two envs of ``make`` (DriveEnvs or VectorDriveEnvs): the compiled step's, the pipeline's."""
    fused, pipeline = make(), make()
    assert getattr(fused, "vector", fused)._fused is not None
    getattr(pipeline, "vector", pipeline)._fused = None
    return fused, pipeline


def _same_world(a, b) -> None:
    assert np.array_equal(a.ego.position, b.ego.position)
    for name in ("heading", "speed_mps", "lane_id", "lateral_offset_m", "on_road"):
        assert getattr(a.ego, name) == getattr(b.ego, name), name
    assert a.time_s == b.time_s
    assert a.route.progress_m == b.route.progress_m
    assert a.events == b.events


def _same_info(a: dict, b: dict) -> None:
    assert a.keys() == b.keys()
    for key in a:
        if key == "reward_terms":
            assert a[key].keys() == b[key].keys()
            for name in a[key]:
                assert a[key][name] == pytest.approx(b[key][name], abs=REWARD_ATOL), name
        elif key == "episode_metrics":
            assert a[key].keys() == b[key].keys()
            for name, value in a[key].items():
                if name == "return":
                    assert value == pytest.approx(b[key][name], abs=1e-6)
                else:
                    assert value == b[key][name], name
        else:
            assert a[key] == b[key], key
            assert type(a[key]) is type(b[key]), key


@pytest.mark.parametrize("scenario", CIRCUITS)
def test_drive_env_steps_as_the_pipeline(scenario):
    fused, pipeline = _pair(lambda: DriveEnv(scenario, action="continuous"))
    fused.action_space.seed(3)
    episodes = 0
    obs_a, info_a = fused.reset(seed=11)
    obs_b, info_b = pipeline.reset(seed=11)
    for step in range(400):
        action = fused.action_space.sample()
        obs_a, reward_a, term_a, trunc_a, info_a = fused.step(action)
        obs_b, reward_b, term_b, trunc_b, info_b = pipeline.step(action)
        np.testing.assert_allclose(obs_a, obs_b, rtol=0, atol=OBS_ATOL)
        assert obs_a.dtype == obs_b.dtype and obs_a.shape == obs_b.shape
        assert reward_a == pytest.approx(reward_b, abs=REWARD_ATOL)
        assert (term_a, trunc_a) == (term_b, trunc_b)
        assert type(reward_a) is float and type(term_a) is bool and type(trunc_a) is bool
        _same_info(info_a, info_b)
        if step % 7 == 0:
            _same_world(fused.world, pipeline.world)
        if term_a or trunc_a:
            episodes += 1
            fused.reset(seed=step)
            pipeline.reset(seed=step)
    assert episodes >= 3  # random actions leave the road: resets were part of it


@pytest.mark.parametrize("autoreset_mode", ["next_step", "same_step"])
@pytest.mark.parametrize("scenario", CIRCUITS)
def test_vector_env_steps_as_the_pipeline(scenario, autoreset_mode):
    fused, pipeline = _pair(
        lambda: VectorDriveEnv(3, scenario, action="continuous", autoreset_mode=autoreset_mode)
    )
    rng = np.random.default_rng(5)
    fused.reset(seed=21)
    pipeline.reset(seed=21)
    ended = 0
    for _ in range(150):
        actions = rng.uniform(-1, 1, size=(3, 2)).astype(np.float32)
        obs_a, rewards_a, term_a, trunc_a, infos_a = fused.step(actions)
        obs_b, rewards_b, term_b, trunc_b, infos_b = pipeline.step(actions)
        np.testing.assert_allclose(obs_a, obs_b, rtol=0, atol=OBS_ATOL)
        np.testing.assert_allclose(rewards_a, rewards_b, rtol=0, atol=REWARD_ATOL)
        assert np.array_equal(term_a, term_b) and np.array_equal(trunc_a, trunc_b)
        assert infos_a.keys() == infos_b.keys()
        for key in ("speed_mps", "crashed", "off_road", "arrived", "episode_seed", "traffic_light"):
            if key in infos_a:
                assert np.array_equal(infos_a[key], infos_b[key]), key
        for name, values in infos_a["reward_terms"].items():
            np.testing.assert_allclose(values, infos_b["reward_terms"][name], rtol=0, atol=REWARD_ATOL)
        if "final_obs" in infos_a:
            for k in np.flatnonzero(infos_a["_final_obs"]):
                np.testing.assert_allclose(infos_a["final_obs"][k], infos_b["final_obs"][k], atol=OBS_ATOL)
        ended += int(np.count_nonzero(term_a | trunc_a))
        batch_a, batch_b = fused.batch, pipeline.batch
        assert np.array_equal(batch_a.ego.position, batch_b.ego.position)
        assert np.array_equal(batch_a.route.progress_m, batch_b.route.progress_m)
        assert np.array_equal(batch_a.events.off_road, batch_b.events.off_road)
    assert ended >= 3


def test_any_weights_of_the_circuit_terms():
    """Every term the compiled step knows, weighted and in an order of the user's."""
    reward = {"steering_power": -2.0, "lane_keeping": 0.5, "speed_mps": 0.1, "line_centring": 1.5}
    fused, pipeline = _pair(lambda: DriveEnv("follow-line", action="seed_line", reward=reward))
    assert tuple(fused.vector._fused.names) == tuple(reward)
    fused.reset(seed=2)
    pipeline.reset(seed=2)
    for step in range(120):
        action = step % 5
        _, reward_a, term_a, trunc_a, info_a = fused.step(action)
        _, reward_b, term_b, trunc_b, info_b = pipeline.step(action)
        assert reward_a == pytest.approx(reward_b, abs=REWARD_ATOL)
        _same_info(info_a, info_b)
        if term_a or trunc_a:
            fused.reset(seed=step)
            pipeline.reset(seed=step)


def test_the_batch_is_the_step_s_whenever_it_is_read():
    """A step's WorldBatch, made when first read, is that step's even when read after later steps
    (it is a value: its arrays are not the next step's)."""
    env = VectorDriveEnv(2, "follow-lane", action="continuous")
    reference = VectorDriveEnv(2, "follow-lane", action="continuous")
    reference._fused = None
    env.reset(seed=4)
    reference.reset(seed=4)
    actions = np.array([[0.1, 0.6], [-0.05, 0.4]], dtype=np.float32)
    env.step(actions)
    reference.step(actions)
    first = env.batch  # made now
    expected = reference.batch
    env.step(actions)
    env.step(actions)
    assert np.array_equal(first.ego.position, expected.ego.position)
    assert np.array_equal(first.time_s, expected.time_s)
    assert np.array_equal(first.route.progress_m, expected.route.progress_m)
    assert env.batch.time_s[0] > first.time_s[0]


@pytest.mark.parametrize(
    ("options", "used"),
    [
        ({}, True),
        ({"obs": "kinematics:vehicles_count=3"}, True),
        ({"action": "seed_lane"}, True),
        ({"obs": "lane"}, False),  # another sensor: the pipeline
        ({"obs": "kinematics:stack=2"}, False),  # a frame stack
        ({"reward": "lane_follow,collision=1"}, False),  # a term the compiled step does not have
        ({"backend": "highway"}, False),
    ],
)
def test_the_compiled_step_is_taken_where_it_covers_the_configuration(options, used):
    env = VectorDriveEnv(1, "follow-lane", **options)
    assert (env._fused is not None) is used


def test_recording_frames_steps_through_the_pipeline():
    env = DriveEnv("follow-line", action="continuous")
    env.reset(seed=0)
    assert env.vector._fused.ready()
    env.simulator.on_frame = lambda batch: None
    assert not env.vector._fused.ready()


def test_other_scenarios_have_no_compiled_step():
    assert VectorDriveEnv(1, "highway")._fused is None


def test_a_stepped_env_pickles_and_goes_on_as_the_original():
    env = DriveEnv("follow-lane", action="continuous")
    env.reset(seed=8)
    action = np.array([0.05, 0.5], dtype=np.float32)
    env.step(action)
    copy = pickle.loads(pickle.dumps(env))
    for _ in range(5):
        obs_a, reward_a, *ends_a, _ = env.step(action)
        obs_b, reward_b, *ends_b, _ = copy.step(action)
        assert np.array_equal(obs_a, obs_b) and reward_a == reward_b and ends_a == ends_b
