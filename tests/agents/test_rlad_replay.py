"""RLAD's replay: each frame stored once, stacks rebuilt across episode boundaries, memory."""

import io

import numpy as np
import torch

from drivelab.agents.rlad.replay import UNKNOWN_LABEL, FrameReplayBuffer, label_index
from drivelab.agents.storage import read_arrays
from drivelab.envs.core import DriveEnv

OBS = "camera:width=24:height=24:stack=3,waypoints,measurements:stack=3"


def _record(obs, info):
    frame = np.moveaxis(obs["camera"][..., -3:], -1, 0)
    return frame, obs["waypoints"], obs["measurements"], label_index(info.get("traffic_light"))


def _arrays_to_bytes(arrays):
    """Arrays as the bytes of an ``.npz`` file (``np.savez``, uncompressed as drivelab writes them)."""
    buffer = io.BytesIO()
    np.savez(buffer, **arrays)
    return buffer.getvalue()


def _channels_first(camera):
    return np.moveaxis(camera, -1, 0)


def test_stacks_are_rebuilt_as_the_camera_made_them_across_episode_ends():
    env = DriveEnv("town", obs=OBS, action="target_speed", reward="roach", traffic="empty", duration_s=1.6)
    replay = FrameReplayBuffer(100, (3, 24, 24), 3, (10, 2), 6, 2)
    rng = np.random.default_rng(0)
    obs, info = env.reset(seed=0)
    replay.start_episode(*_record(obs, info))
    seen, ends = [], []
    for _ in range(20):  # episodes of 8 steps: two truncations and a new episode each time
        action = rng.uniform([0.0, -0.2], [1.0, 0.2]).astype(np.float32)
        next_obs, reward, terminated, truncated, info = env.step(action)
        replay.add(action, reward, terminated, *_record(next_obs, info))
        seen.append((obs, next_obs, action, reward, terminated, info["traffic_light"]))
        ends.append(truncated)
        if terminated or truncated:
            next_obs, info = env.reset()
            replay.start_episode(*_record(next_obs, info))
        obs = next_obs
    assert sum(ends) >= 2
    batch = replay.batch(np.arange(20))
    for i, (obs, next_obs, action, reward, terminated, _) in enumerate(seen):
        np.testing.assert_array_equal(batch["images"][i], _channels_first(obs["camera"]))
        np.testing.assert_array_equal(batch["next_images"][i], _channels_first(next_obs["camera"]))
        np.testing.assert_array_equal(batch["waypoints"][i], obs["waypoints"])
        np.testing.assert_array_equal(batch["next_measurements"][i], next_obs["measurements"])
        np.testing.assert_array_equal(batch["actions"][i], action)
        assert batch["rewards"][i] == np.float32(reward) and batch["terminated"][i] == float(terminated)
    # an episode's first stack is its reset frame three times, never the last episode's frames
    first = ends.index(True) + 1
    images = batch["images"][first]
    np.testing.assert_array_equal(images[:3], images[6:])
    assert not np.array_equal(images, batch["next_images"][first - 1])
    # labels: the observation's own (the reset's from the reset info, later ones from step info)
    assert batch["labels"][1] == label_index(seen[0][5])
    assert UNKNOWN_LABEL not in batch["labels"]


def _fill(replay, steps, episode_length, rng, frame_shape):
    replay.start_episode(rng.integers(0, 256, frame_shape, dtype=np.uint8), np.zeros((10, 2)), np.zeros(6), 0)
    for step in range(steps):
        frame = rng.integers(0, 256, frame_shape, dtype=np.uint8)
        done = (step + 1) % episode_length == 0
        replay.add(np.zeros(2), 0.0, done, frame, np.zeros((10, 2)), np.zeros(6), 1)
        if done:
            replay.start_episode(frame, np.zeros((10, 2)), np.zeros(6), 0)


def test_memory_is_within_ten_percent_of_the_unique_frames():
    rng = np.random.default_rng(1)
    replay = FrameReplayBuffer(300, (3, 84, 84), 3, (10, 2), 6, 2)
    _fill(replay, 1000, 40, rng, (3, 84, 84))
    assert replay.size >= 0.95 * replay.capacity
    ratio = replay.nbytes / replay.unique_frame_bytes()
    assert 1.0 <= ratio <= 1.1
    naive = replay.size * 2 * 3 * replay.frames[0].nbytes  # obs and next_obs stacks of 3 frames
    assert replay.nbytes < naive / 5


def test_transitions_whose_frames_were_overwritten_are_not_sampled():
    rng = np.random.default_rng(2)
    replay = FrameReplayBuffer(50, (3, 4, 4), 3, (10, 2), 6, 2)
    _fill(replay, 400, 2, rng, (3, 4, 4))  # 3 records per 2 transitions: the ring is the limit
    indices = replay.sampleable()
    assert 0 < len(indices) < replay.capacity
    oldest = replay.stacks[indices, 0]
    assert oldest.min() >= replay.written - replay.records
    batch = replay.sample(64, rng)
    assert batch["images"].shape == (64, 9, 4, 4) and set(batch["labels"]) <= {0, 1}


def _filled(frame_device=None, steps=40, episode=9):
    """A replay of small random frames, the same for every ``frame_device``."""
    rng = np.random.default_rng(3)
    replay = FrameReplayBuffer(30, (3, 6, 6), 3, (10, 2), 6, 2, frame_device=frame_device)

    def record():
        frame = rng.integers(0, 256, (3, 6, 6), dtype=np.uint8)
        return frame, rng.normal(size=(10, 2)), rng.normal(size=6), int(rng.integers(-1, 3))

    replay.start_episode(*record())
    for step in range(steps):
        replay.add(rng.uniform(-1, 1, 2), float(rng.normal()), False, *record())
        if step % episode == episode - 1:
            replay.start_episode(*record())
    return replay


def test_frames_kept_in_a_tensor_give_the_same_batches_and_save_as_numpy():
    host, tensor = _filled(), _filled(frame_device="cpu")
    assert isinstance(host.frames, np.ndarray) and isinstance(tensor.frames, torch.Tensor)
    assert host.nbytes == tensor.nbytes and host.unique_frame_bytes() == tensor.unique_frame_bytes()
    one, two = host.sample(16, np.random.default_rng(1)), tensor.sample(16, np.random.default_rng(1))
    for key in one:
        np.testing.assert_array_equal(one[key], np.asarray(two[key]), err_msg=key)
    assert isinstance(two["images"], torch.Tensor) and two["images"].shape == (16, 9, 6, 6)
    arrays = tensor.state_arrays()
    assert all(isinstance(array, np.ndarray) and array.dtype != object for array in arrays.values())
    loaded = FrameReplayBuffer(30, (3, 6, 6), 3, (10, 2), 6, 2)  # frames on the host
    loaded.load_state_arrays(read_arrays(_arrays_to_bytes(arrays)))
    assert isinstance(loaded.frames, np.ndarray) and loaded.frame_device is None
    np.testing.assert_array_equal(loaded.frames, tensor.frames.numpy())
    counters = ("written", "position", "stored")
    assert [getattr(loaded, name) for name in counters] == [getattr(tensor, name) for name in counters]
    np.testing.assert_array_equal(loaded.current, tensor.current)
    loaded.move_frames("cpu")
    assert isinstance(loaded.frames, torch.Tensor) and torch.equal(loaded.frames, tensor.frames)
    again = loaded.sample(16, np.random.default_rng(1))
    np.testing.assert_array_equal(np.asarray(again["next_images"]), one["next_images"])
    loaded.move_frames(None)
    assert isinstance(loaded.frames, np.ndarray)
    np.testing.assert_array_equal(loaded.sample(16, np.random.default_rng(1))["images"], one["images"])


def test_device_frames_are_allocated_at_the_first_write_and_old_pickles_load():
    empty = FrameReplayBuffer(30, (3, 6, 6), 3, (10, 2), 6, 2, frame_device="cpu")
    assert isinstance(empty.frames, np.ndarray)  # an agent loaded only to act reserves nothing
    empty.start_episode(np.ones((3, 6, 6), np.uint8), np.zeros((10, 2)), np.zeros(6), 0)
    assert isinstance(empty.frames, torch.Tensor) and int(empty.frames[0].sum()) == 3 * 6 * 6
    old = _filled()
    state = dict(old.__dict__)
    del state["frame_device"]  # a replay.pkl written before frame_device existed
    revived = FrameReplayBuffer.__new__(FrameReplayBuffer)
    revived.__setstate__(state)
    assert revived.frame_device is None
    np.testing.assert_array_equal(revived.sample(4, np.random.default_rng(0))["images"],
                                  old.sample(4, np.random.default_rng(0))["images"])  # fmt: skip
