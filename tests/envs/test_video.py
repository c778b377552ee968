"""Videos for people (envs/video.py): a frame per simulation frame without changing the episode,
the landscape and map cameras, the overlay strip, side-by-side, and the CLI writing a video."""

import numpy as np
import pytest
from typer.testing import CliRunner

from drivelab.cli import app
from drivelab.envs.actions import MetaAction
from drivelab.envs.core import DriveEnv
from drivelab.envs.vector import VectorDriveEnv
from drivelab.envs.video import (
    MAP_CAMERA,
    ROAD_CAMERA,
    STRIP_HEIGHT,
    Caption,
    EpisodeRecorder,
    action_text,
    camera_view,
    draw_strip,
    video_fps,
)
from drivelab.training.evaluate import run_episodes
from drivelab.training.seeds import evaluation_seeds

ACTIONS = {"highway": [3, 0, 1, 2, 4, 1], "town": [[0.8, 0.0], [1.0, 0.1], [0.5, -0.1], [0.0, 0.0]]}


def _play(vector: VectorDriveEnv, actions, recorded: bool) -> list:
    """Every step's (observations, rewards, terminated, truncated, events) of ``actions``
    (the same for all worlds), with the frame hook on (frames kept) or off."""
    frames: list = []
    vector.simulator.on_frame = frames.append if recorded else None
    # seeded: a world that ends restarts from its generator's next seed (NEXT_STEP autoreset)
    observations, _ = vector.reset(seed=0, options={"episode_seeds": evaluation_seeds(vector.num_envs)})
    steps = [observations]
    for action in actions:
        out = vector.step(np.stack([np.asarray(action)] * vector.num_envs))
        events = vector.batch.events
        steps.append((*out[:4], events.collided.copy(), events.off_road.copy(), events.arrived.copy()))
    vector.simulator.on_frame = None
    assert len(frames) == (vector.simulator.frames * len(actions) if recorded else 0)
    return steps


@pytest.mark.parametrize(
    ("scenario", "obs", "actions"),
    [
        ("highway", "kinematics", ACTIONS["highway"]),
        ("town", "waypoints,measurements", ACTIONS["town"]),
        ("blocks", "lidar", ACTIONS["highway"][:4]),
    ],
)
def test_recording_frame_by_frame_leaves_the_episode_bit_identical(scenario, obs, actions):
    action = "target_speed" if scenario == "town" else "meta"
    quiet = _play(VectorDriveEnv(2, scenario=scenario, obs=obs, action=action), actions, recorded=False)
    loud = _play(VectorDriveEnv(2, scenario=scenario, obs=obs, action=action), actions, recorded=True)
    for a, b in zip(quiet, loud, strict=True):
        for x, y in zip(
            a if isinstance(a, tuple) else (a,), b if isinstance(b, tuple) else (b,), strict=True
        ):
            if isinstance(x, dict):
                for key in x:
                    np.testing.assert_array_equal(x[key], y[key])
            else:
                np.testing.assert_array_equal(x, y)  # bit for bit


def test_a_recorded_episode_has_one_frame_per_simulation_frame():
    env = DriveEnv("highway", obs="kinematics")
    policy = lambda obs: 1  # noqa: E731
    _, kept = run_episodes(policy, env, 1, record_first=True)
    plain, _ = run_episodes(policy, env, 1)
    per_step = env.simulator.frames
    assert per_step > 1 and len(kept) == 1 + per_step * plain[0]["length"]
    assert video_fps(env) == env.simulator.policy_frequency_hz * per_step  # plays in real time
    height, width = kept[0].shape[:2]
    assert (height, width) == (
        ROAD_CAMERA.size_hw[0] + STRIP_HEIGHT,
        ROAD_CAMERA.size_hw[1],
    ) and width > 2 * height
    assert len({frame.tobytes() for frame in kept[: per_step + 1]}) == per_step + 1  # the traffic moves


def test_the_recorder_steps_as_env_step_does():
    recorded, plain = DriveEnv("highway", obs="kinematics"), DriveEnv("highway", obs="kinematics")
    recorder = EpisodeRecorder(recorded)
    for env in (recorded, plain):
        env.reset(options={"episode_seed": 5})
    recorder.first_frame()
    rewards = []
    for action in ACTIONS["highway"]:
        (obs, reward, terminated, truncated, info), frames = recorder.step(action)
        expected = plain.step(action)
        np.testing.assert_array_equal(obs, expected[0])
        assert (reward, terminated, truncated) == expected[1:4] and len(frames) == recorded.simulator.frames
        rewards.append(reward)
        if terminated or truncated:  # the episode is over: a further step needs a reset
            break
    assert recorder.episode_return == pytest.approx(sum(rewards))


def test_cameras_look_along_the_road_and_north_up():
    env = VectorDriveEnv(1, scenario="highway")
    env.reset(options={"episode_seeds": evaluation_seeds(1)})
    batch = env.batch
    heading = batch.ego.lane_heading[0]
    road = camera_view(batch, ROAD_CAMERA)
    ahead = batch.ego.position[0] + 10.0 * np.array([np.cos(heading), np.sin(heading)])
    ego_px, ahead_px = road.pixels_of(0, np.stack([batch.ego.position[0], ahead]))
    assert ahead_px[0] - ego_px[0] == pytest.approx(10.0 * ROAD_CAMERA.pixels_per_meter)  # ahead: right
    assert ahead_px[1] == pytest.approx(ego_px[1])
    assert ego_px[0] == pytest.approx(ROAD_CAMERA.size_hw[1] / 3 - 0.5)  # a third in from the left
    top = camera_view(batch, MAP_CAMERA)
    ego_px, east, south = top.pixels_of(0, batch.ego.position[0] + np.array([[0, 0], [5.0, 0], [0, 5.0]]))
    np.testing.assert_allclose(east - ego_px, [5.0 * MAP_CAMERA.pixels_per_meter, 0], atol=1e-9)  # x right
    np.testing.assert_allclose(south - ego_px, [0, 5.0 * MAP_CAMERA.pixels_per_meter], atol=1e-9)  # y down
    np.testing.assert_allclose(ego_px, np.array(MAP_CAMERA.size_hw[::-1]) / 2 - 0.5)  # centred


def test_the_strip_writes_speed_action_reward_and_events():
    def strip(**changes):
        values = {"time_s": 1.0, "speed_mps": 20.0, "action": "IDLE", "reward": 0.5, "episode_return": 3.0}
        image = np.zeros((STRIP_HEIGHT, 720, 3), dtype=np.uint8)
        draw_strip(image, Caption(**{**values, **changes}))
        return image

    base = strip()
    assert (base != base[0, 0]).any()  # text is drawn
    for change in ({"speed_mps": 30.0}, {"action": "FASTER"}, {"reward": -1.0}, {"events": ("CRASH",)}):
        assert (strip(**change) != base).any(), change
    crash = strip(events=("CRASH",))
    assert (np.abs(crash.astype(int) - (235, 60, 50)).sum(axis=2) == 0).any()  # the red badge


def test_side_by_side_puts_the_agents_image_left_of_the_scene():
    env = DriveEnv("highway", obs="birdeye,kinematics")
    env.reset(options={"episode_seed": 3})
    frame = EpisodeRecorder(env).first_frame()  # auto: the observation holds an image
    scene_h, scene_w = ROAD_CAMERA.size_hw
    assert frame.shape == (scene_h + STRIP_HEIGHT, scene_h + scene_w, 3)  # the square image at the height
    np.testing.assert_array_equal(frame[0, 0], env.vector.observations["birdeye"][0, 0, 0])  # nearest pixel
    only = EpisodeRecorder(env, side_by_side=False).first_frame()
    assert only.shape == (scene_h + STRIP_HEIGHT, scene_w, 3)
    np.testing.assert_array_equal(frame[:scene_h, -scene_w:], only[:scene_h])  # the same scene
    with pytest.raises(Exception, match="side-by-side needs an image"):
        EpisodeRecorder(DriveEnv("highway", obs="kinematics"), side_by_side=True)


def test_town_topdown_side_by_side_and_map_view():
    env = DriveEnv("town", obs="topdown:lights=true,waypoints", action="target_speed", traffic="empty")
    env.reset(options={"episode_seed": 1})
    recorder = EpisodeRecorder(env)
    frame = recorder.first_frame()
    scene_h, scene_w = MAP_CAMERA.size_hw
    assert frame.shape == (scene_h + STRIP_HEIGHT, scene_h + scene_w, 3)  # 84 x 84 scaled to the height
    _, frames = recorder.step([0.5, 0.0])
    assert len(frames) == env.simulator.frames and recorder.fps == video_fps(env)


def test_cli_enjoy_writes_a_gif(tmp_path, monkeypatch):
    from drivelab.training import zoo

    monkeypatch.chdir(tmp_path)
    path = tmp_path / "drive.gif"
    result = CliRunner().invoke(app, ["enjoy", "highway-ppo", "--episodes", "1", "--video", str(path)])
    assert result.exit_code == 0, result.output
    assert path.is_file() and path.stat().st_size > 0 and "frames)" in result.output
    assert zoo.resolve("highway-ppo")[1] == "highway-ppo"


@pytest.mark.parametrize("scenario", ["town", "blocks"])
def test_the_map_camera_draws_its_road_once_and_moves_in_whole_pixels(scenario):
    """A map-camera frame is its map's backdrop window plus the moving layer: the same image as
    drawing the road layer at that view, but for anti-aliasing rounding at polygon edges; the view
    is the ego-centred camera moved by at most half a pixel."""
    from drivelab.envs.video import backdrop, draw_scene, map_view, ring_egos
    from drivelab.perception.birdeye import draw_birdeye

    env = VectorDriveEnv(2, scenario=scenario, traffic="regular")
    env.reset(options={"episode_seeds": evaluation_seeds(2)})
    for _ in range(3):
        env.step(np.stack([env.single_action_space.sample()] * 2))
    batch = env.batch
    frames = draw_scene(batch, MAP_CAMERA)
    view = map_view(batch, MAP_CAMERA)
    shift = (view.positions - camera_view(batch, MAP_CAMERA).positions) * MAP_CAMERA.pixels_per_meter
    assert np.abs(shift).max() <= 0.5 + 1e-9
    for k in range(2):  # its window starts on a whole pixel of the backdrop
        made = backdrop(batch, k, MAP_CAMERA)
        half = np.array(MAP_CAMERA.size_hw[::-1]) / 2 - 0.5
        column, row = made.view.pixels_of(0, view.positions[k]) - half
        assert column == pytest.approx(round(column), abs=1e-6) and row == pytest.approx(round(row), abs=1e-6)
    direct = np.empty_like(frames)
    draw_birdeye(batch, direct, MAP_CAMERA.pixels_per_meter, view, layers="road")
    draw_birdeye(batch, direct, MAP_CAMERA.pixels_per_meter, view, layers="moving")
    ring_egos(batch, direct, view)
    differ = np.abs(frames.astype(int) - direct.astype(int)).max(axis=-1)
    # measured: 0.012 % of the pixels differ, by at most 52 levels: anti-aliased edges whose
    # fixed-point vertices round differently from the two origins; a misplaced object would differ
    # by its full contrast over many pixels
    assert (differ > 0).mean() < 0.001 and differ.max() <= 64


def test_the_strip_names_the_meta_action_each_action_space_means():
    assert action_text(MetaAction(), 4) == "SLOWER"
    assert action_text(MetaAction(lateral=False), 0) == "SLOWER"  # the intersection's three
    assert action_text(MetaAction(lateral=False), 2) == "FASTER"
