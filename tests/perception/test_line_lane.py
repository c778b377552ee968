"""Line and lane perception: state encoding with known values, and detection on rendered frames
of the follow-line circuit against the true line position."""

import numpy as np
import pytest

from drivelab.envs.core import DriveEnv
from drivelab.perception.camera import GuideSegments, render_camera
from drivelab.perception.lane import LOST_STATE, LaneState, classical_lane_masks, lane_centres, state_of
from drivelab.perception.line import LINE_CAMERA, LINE_ROWS_M, LineState, encode_state, strip_of
from drivelab.rewards.terms import crossing_columns
from drivelab.world.batch import WorldBatch


def _crossing_columns(world, segments: np.ndarray, model, distances_m) -> np.ndarray:
    """:func:`crossing_columns` of one world with segments (M, 2, 2): (D,) columns."""
    segments = np.asarray(segments, dtype=float).reshape(1, -1, 2, 2)
    return crossing_columns(WorldBatch.stack([world]), segments, model, distances_m)[0]


def test_strips_and_encoding():
    np.testing.assert_array_equal(
        strip_of(np.array([0.0, 31.9, 32.0, 159.0, np.nan]), 160, 5), [0, 0, 1, 4, 5]
    )
    assert encode_state([1, 2, 0, 5], base=6) == 1 + 2 * 6 + 0 + 5 * 216
    assert LineState().lost_state == encode_state([5, 5, 5, 5], 6) == 6**4 - 1


def test_lane_state_strips():
    # offsets against the seed's 1024-px bands 30 / 80: 160 px wide, centre 79.5
    assert state_of(79.5, 160) == 2
    assert state_of(79.5 + 6.0, 160) == 3  # 6 px = 38 seed px
    assert state_of(79.5 - 13.0, 160) == 0  # 83 seed px
    assert state_of(float("nan"), 160) == LOST_STATE == 5


@pytest.fixture(scope="module")
def line_frames():
    env = DriveEnv(
        "follow-line",
        obs="line",
        action="seed_line",
        reward="line_follow",
        traffic="empty",
        backend="highway",
    )
    rng, worlds = np.random.default_rng(0), []
    for seed in range(3):
        env.reset(seed=seed)
        for _ in range(8):
            worlds.append(env.world)
            _, _, terminated, truncated, _ = env.step(int(rng.integers(5)))
            if terminated or truncated:
                break
    return worlds


def test_line_detector_within_one_strip(line_frames):
    sensor = LineState()
    visible = detected = 0
    for world in line_frames:
        sensor.observe(world)
        guide = world.road.derived(GuideSegments, GuideSegments).segments
        truth = _crossing_columns(world, guide, LINE_CAMERA, LINE_ROWS_M)
        seen = np.isfinite(truth) & (np.abs(truth - 80) < 70)  # away from the image border
        centres = sensor.centres[0]  # the one world's (4,) row centres
        both = seen & np.isfinite(centres)
        found = strip_of(centres[both], 160, 5)
        assert np.all(np.abs(found - strip_of(truth[both], 160, 5)) <= 1)
        assert np.all(np.abs(centres[both] - truth[both]) < 160 / 5)
        visible, detected = visible + int(seen.sum()), detected + int(both.sum())
    # in sharp bends the far row's line is foreshortened below the 3 px opening and can be missed
    assert visible >= 40 and detected >= 0.9 * visible


def test_line_lost_without_a_line():
    from tests.worlds import world

    sensor = LineState()
    assert sensor.observe(world()) == sensor.lost_state  # grass and sky only
    assert np.isnan(sensor.centres).all()


def test_lane_classical_detector_on_a_centred_frame():
    env = DriveEnv("follow-lane", obs="lane:detector=classical", backend="highway", action="seed_lane",
                   reward="lane_follow", traffic="empty", seed=0)  # fmt: skip
    sensor = env.sensors[0]
    assert isinstance(sensor, LaneState) and sensor.space.n == 6
    masks = classical_lane_masks(render_camera(env.world, sensor.model))
    assert masks.shape == (2, 120, 160) and masks[0].any() and masks[1].any()
    # left-line pixels lie left of right-line pixels in every row that has both
    rows = np.flatnonzero(masks[0].any(axis=1) & masks[1].any(axis=1))
    left_max = np.array([np.flatnonzero(masks[0][r]).max() for r in rows])
    right_min = np.array([np.flatnonzero(masks[1][r]).min() for r in rows])
    assert np.all(left_max < right_min)


def test_shipped_lane_cnn_on_held_out_frames(tmp_path):
    from drivelab.errors import UsageError
    from drivelab.perception.lane_cnn import WEIGHTS_PATH, iou, train_lane_cnn
    from drivelab.perception.sensors import make_sensor
    from drivelab.training.lane_dataset import generate_lane_frames

    assert WEIGHTS_PATH.stat().st_size < 2 * 2**20
    images, truth = generate_lane_frames(8, seed=777)
    assert images.shape == (8, 120, 160, 3) and truth.shape == (8, 2, 120, 160)
    cnn, classical = LaneState(detector="cnn"), LaneState(detector="classical")
    predicted = np.stack([cnn.masks(image) for image in images])
    assert predicted.shape == truth.shape and predicted.dtype == bool
    assert iou(predicted[:, 0], truth[:, 0] > 0) > 0.25 and iou(predicted[:, 1], truth[:, 1] > 0) > 0.25
    for masks, true_masks in zip(predicted, truth, strict=True):
        states = [
            state_of(float(np.nanmean(lane_centres(m, cnn.rows, cnn.half_lane_px))), 160)
            for m in (masks, true_masks)
        ]
        assert abs(states[0] - states[1]) <= 1
    assert classical.masks(images[0]).shape == (2, 120, 160)
    # retraining writes loadable weights; missing weights are a usage error
    summary = train_lane_cnn(images[:4], truth[:4], epochs=1, out=tmp_path / "w.pt", log=lambda _: None)
    assert len(summary["losses"]) == 1 and LaneState(weights=str(tmp_path / "w.pt")).network is not None
    with pytest.raises(UsageError, match="lane CNN weights not found"):
        make_sensor(f"lane:weights={tmp_path / 'missing.pt'}")
