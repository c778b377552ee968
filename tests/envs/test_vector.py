"""VectorDriveEnv: K worlds stepped together give exactly the episodes of K separate DriveEnvs, and
the vector env meets gymnasium's and SB3's conventions (pickling: tests/envs/test_pickle.py)."""

import gymnasium
import numpy as np
import pytest
from gymnasium.utils.env_checker import data_equivalence
from gymnasium.vector import AutoresetMode
from stable_baselines3 import PPO

import drivelab
from drivelab.agents.sb3_env import SB3VecEnv
from drivelab.envs import gym_id
from drivelab.envs.core import DriveEnv, make_vec
from drivelab.envs.vector import VectorDriveEnv
from drivelab.envs.video import MAP_CAMERA, ROAD_CAMERA, draw_scene
from drivelab.errors import UsageError
from tests.batch_worlds import assert_same_observations

KWARGS = {"obs": "kinematics", "traffic": "regular", "duration_s": 6}


def _same_metrics(a: dict, b: dict) -> bool:
    """Episode metrics equal, NaN (no route completion on a road without an end) equal to NaN."""
    return a.keys() == b.keys() and all(
        a[key] == b[key] or a[key] != a[key] and b[key] != b[key] for key in a
    )


def _row(observations, k):
    if isinstance(observations, dict):
        return {name: value[k] for name, value in observations.items()}
    return observations[k]


@pytest.mark.parametrize(
    "scenario, backend, mode, obs",
    [
        ("highway", "fast", "same_step", "kinematics"),
        ("highway", "fast", "next_step", "kinematics,lidar:beams=32:stack=2"),
        ("roundabout", "fast", "same_step", "kinematics"),
        ("intersection", "fast", "next_step", "kinematics:features=presence+x+y+vx+vy+cos_d+sin_d+accel"),
        ("merge", "highway", "same_step", "kinematics"),
    ],
)
def test_k_worlds_give_the_episodes_of_k_separate_envs(scenario, backend, mode, obs):
    """Same seeds, same actions: every world's observations, rewards, ends, infos and episode
    metrics equal those of its own DriveEnv, across autoresets (episodes of 6 s end inside 40
    steps, at different steps in different worlds)."""
    k = 4
    kwargs = {**KWARGS, "obs": obs, "backend": backend}
    vector = VectorDriveEnv(k, scenario=scenario, autoreset_mode=mode, **kwargs)
    singles = [DriveEnv(scenario, **kwargs) for _ in range(k)]
    observations, infos = vector.reset(seed=10)
    for i, env in enumerate(singles):
        single_obs, single_info = env.reset(seed=10 + i)
        assert_same_observations(_row(observations, i), single_obs)
        assert infos["episode_seed"][i] == single_info["episode_seed"]
    rng = np.random.default_rng(0)
    ends, restarting = 0, np.zeros(k, dtype=bool)
    for _ in range(40):
        actions = rng.integers(vector.single_action_space.n, size=k)
        observations, rewards, terminations, truncations, infos = vector.step(actions)
        for i, env in enumerate(singles):
            if restarting[i]:  # NEXT_STEP: this step reset world i instead of stepping it
                single_obs, info = env.reset()
                assert (rewards[i], terminations[i], truncations[i]) == (0.0, False, False)
                assert all(float(value[i]) == 0.0 for value in infos["reward_terms"].values())
                assert infos["episode_seed"][i] == info["episode_seed"]
                assert_same_observations(_row(observations, i), single_obs)
                continue
            single_obs, reward, terminated, truncated, info = env.step(int(actions[i]))
            assert (terminated, truncated) == (terminations[i], truncations[i])
            assert reward == rewards[i]
            assert info["reward_terms"] == {name: float(v[i]) for name, v in infos["reward_terms"].items()}
            if terminated or truncated:
                ends += 1
                assert _same_metrics(infos["episode_metrics"][i], info["episode_metrics"])
                if mode == "same_step":
                    assert data_equivalence(infos["final_obs"][i], single_obs)
                    assert _same_metrics(infos["final_info"][i]["episode_metrics"], info["episode_metrics"])
                    single_obs, _ = env.reset()
            assert_same_observations(_row(observations, i), single_obs)
        restarting = (terminations | truncations) if mode == "next_step" else restarting
    assert ends >= k  # every world finished at least one episode


def test_gymnasium_vector_wrappers_take_the_next_step_env():
    """gymnasium's NormalizeObservation and FlattenObservation refuse SAME_STEP vector envs."""
    vector = VectorDriveEnv(3, scenario="highway", obs="kinematics,ego_state", duration_s=2)
    assert vector.metadata["autoreset_mode"] == AutoresetMode.NEXT_STEP
    wrapped = gymnasium.wrappers.vector.NormalizeObservation(
        gymnasium.wrappers.vector.FlattenObservation(vector)
    )
    observations, _ = wrapped.reset(seed=0)
    assert observations.shape == (3, 35 + 5)
    for _ in range(12):
        observations, rewards, *_ = wrapped.step(wrapped.action_space.sample())
    assert np.isfinite(observations).all() and rewards.shape == (3,)


def test_make_vec_takes_the_vector_entry_point_with_the_auto_backend():
    vector = gymnasium.make_vec(gym_id("highway"), num_envs=3, vectorization_mode="vector_entry_point")
    assert isinstance(vector, VectorDriveEnv) and vector.num_envs == 3
    assert type(vector.simulator).__name__ == "FastSimulator"
    observations, _ = vector.reset(seed=1)
    assert observations.shape == (3, 35)
    default = gymnasium.make_vec(gym_id("merge"), num_envs=2)  # the entry point is the default
    assert isinstance(default, VectorDriveEnv)


def test_the_reference_backend_batches_in_subprocesses():
    vector = make_vec("town", num_envs=2, obs="waypoints", traffic="empty", backend="highway")
    try:
        assert isinstance(vector, gymnasium.vector.AsyncVectorEnv)
        observations, _ = vector.reset(seed=0)
        assert observations.shape == (2, 10, 2)
    finally:
        vector.close()


def test_render_gives_one_frame_per_world_and_sb3_get_images():
    vector = VectorDriveEnv(2, scenario="highway", render_mode="rgb_array", autoreset_mode="same_step")
    vector.reset(seed=0)
    frames = vector.render()
    assert len(frames) == 2 and frames[0].shape == (256, 720, 3) and frames[0].dtype == np.uint8
    assert not np.array_equal(frames[0], frames[1])  # two different worlds
    # the videos' scene: the camera along the road, as EpisodeRecorder draws it
    scene = draw_scene(vector.batch.select(np.array([1])), ROAD_CAMERA)[0]
    np.testing.assert_array_equal(frames[1], scene)
    venv = SB3VecEnv(vector)
    images = venv.get_images()
    assert len(images) == 2 and np.array_equal(images[0], frames[0])
    tiled = venv.render(mode="rgb_array")
    assert tiled.ndim == 3 and tiled.shape[2] == 3


def test_gymnasium_record_video_and_sb3_vec_video_recorder(tmp_path):
    pytest.importorskip("moviepy")
    from stable_baselines3.common.vec_env import VecVideoRecorder

    vector = VectorDriveEnv(2, scenario="highway", render_mode="rgb_array", duration_s=2)
    recorded = gymnasium.wrappers.vector.RecordVideo(
        vector, str(tmp_path / "gym"), step_trigger=lambda t: t == 0
    )
    recorded.reset(seed=0)
    for _ in range(4):
        recorded.step(recorded.action_space.sample())
    recorded.close()
    assert list((tmp_path / "gym").glob("*.mp4"))
    venv = VecVideoRecorder(
        SB3VecEnv(VectorDriveEnv(2, scenario="highway", render_mode="rgb_array", autoreset_mode="same_step")),
        str(tmp_path / "sb3"),
        record_video_trigger=lambda t: t == 0,
        video_length=3,
    )
    venv.reset()
    for _ in range(4):
        venv.step(np.array([1, 1]))
    venv.close()
    assert list((tmp_path / "sb3").glob("*.mp4"))


def test_partial_reset_starts_only_the_masked_worlds():
    vector = VectorDriveEnv(3, scenario="highway", obs="kinematics")
    first, _ = vector.reset(seed=0)
    vector.step(np.array([1, 1, 1]))
    kept = vector.observations.copy()
    again, infos = vector.reset(options={"reset_mask": np.array([False, True, False])})
    np.testing.assert_array_equal(again[[0, 2]], kept[[0, 2]])
    assert infos["_episode_seed"].tolist() == [False, True, False]
    assert not np.array_equal(again[1], first[1])  # world 1 drew its next episode seed


def test_sb3_ppo_trains_on_the_vec_env():
    venv = SB3VecEnv(
        make_vec("highway", num_envs=4, autoreset_mode="same_step", **{**KWARGS, "duration_s": 4})
    )
    model = PPO("MlpPolicy", venv, n_steps=16, batch_size=32, n_epochs=1, seed=0, device="cpu")
    model.learn(64)
    assert model.num_timesteps == 64
    venv.seed(3)
    venv.reset()
    venv.step_async(np.array([1, 1, 1, 1]))
    obs, rewards, dones, infos = venv.step_wait()
    assert obs.shape == (4, *venv.observation_space.shape) and len(infos) == 4
    assert venv.get_attr("duration_s") == [4.0] * 4


def test_sb3_adapter_needs_same_step_autoreset():
    with pytest.raises(ValueError, match="SAME_STEP"):
        SB3VecEnv(VectorDriveEnv(2, scenario="highway"))


@pytest.mark.parametrize("bad", [0, -1, 2.5, True])
def test_bad_num_envs(bad):
    with pytest.raises(UsageError, match="num_envs must be an integer >= 1"):
        VectorDriveEnv(bad, scenario="highway")


@pytest.mark.parametrize("make", [VectorDriveEnv, lambda n, **kw: DriveEnv(**kw)])
def test_unknown_render_mode(make):
    with pytest.raises(UsageError, match="render_mode must be None or 'rgb_array' \\(got 'human'\\)"):
        make(2, scenario="highway", render_mode="human")


def test_render_draws_the_town_as_its_videos_do():
    """The town and the block maps are drawn as a map from above, north up (the videos' camera),
    not a strip along the road."""
    env = drivelab.make("town", obs="kinematics", action="continuous")
    env.reset(seed=3)
    frame = env.render()
    assert frame.shape == (432, 720, 3)
    np.testing.assert_array_equal(frame, draw_scene(env.vector.batch, MAP_CAMERA)[0])
    env.close()
