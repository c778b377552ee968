"""Follow-lane perception (the CARLA study, section 4): lane lines → lane centre at 4 rows → 5 states.

A detector (the shipped segmentation CNN, ``lane_cnn.py``, or a classical white-pixel one) turns
the camera frame into the ego lane's left and right line masks. In each of 4 rows the lane centre
is the middle of the two lines (or one line shifted by half a lane); the mean centre's offset from
the image centre falls in one of 5 strips, or the lane is lost (state 5).
"""

from __future__ import annotations

import cv2
import numpy as np
from gymnasium import spaces

from drivelab.perception.base import Sensor
from drivelab.perception.camera import PinholeModel, draw_camera
from drivelab.perception.line import row_centres
from drivelab.world.batch import WorldBatch
from drivelab.world.pinhole import LANE_CAMERA, LANE_ROWS_M

LANE_WIDTH_M = 3.5
SEED_IMAGE_WIDTH = 1024  # the seed's f* bands are in pixels of a 1024-wide frame
# State strips: the offset of C from the image centre against the seed's own f* band edges 30 and
# 80 px (of 1024), so that state 2 is "centred", 1/3 "off to one side", 0/4 "far off". Our choice.
STATE_EDGES_SEED_PX = np.array([-80.0, -30.0, 30.0, 80.0])
LOST_STATE = len(STATE_EDGES_SEED_PX) + 1
DETECTORS = ("cnn", "classical")


def white_mask(image_rgb: np.ndarray, horizon_row: float) -> np.ndarray:
    """Bright, unsaturated pixels below the horizon: painted lines. Images (..., H, W, 3) uint8 →
    bool (..., H, W); a pixel's colour conversion does not depend on its neighbours, so K frames
    convert as one tall image."""
    shape = image_rgb.shape
    hsv = cv2.cvtColor(np.ascontiguousarray(image_rgb).reshape(-1, shape[-2], 3), cv2.COLOR_RGB2HSV)
    hsv = hsv.reshape(shape)
    white = (hsv[..., 1] < 60) & (hsv[..., 2] > 180)
    white[..., : int(np.clip(np.ceil(horizon_row), 0, shape[-3])), :] = False
    return white


def classical_lane_masks(image_rgb: np.ndarray, model: PinholeModel = LANE_CAMERA) -> np.ndarray:
    """Left and right line masks bool, (2, H, W) for one frame (H, W, 3) or (K, 2, H, W) for K frames:
    per row, the run of white pixels nearest to the image centre on each side. No learning, no
    memory: a dash gap lets the next line over stand in."""
    white = white_mask(image_rgb, model.horizon_row)  # (..., H, W)
    width = white.shape[-1]
    columns = np.arange(width)
    centre = model.centre[0]
    starts = white & ~np.concatenate([np.zeros_like(white[..., :1]), white[..., :-1]], axis=-1)
    run_id = np.cumsum(starts, axis=-1) * white  # runs numbered 1, 2, … along each row, 0 off-line
    left_col = np.where(white & (columns < centre), columns, -1).max(axis=-1)
    right_col = np.where(white & (columns > centre), columns, width).min(axis=-1)
    left_at = np.take_along_axis(run_id, np.clip(left_col, 0, width - 1)[..., None], axis=-1)[..., 0]
    right_at = np.take_along_axis(run_id, np.clip(right_col, 0, width - 1)[..., None], axis=-1)[..., 0]
    left_run = np.where(left_col >= 0, left_at, 0)[..., None]
    right_run = np.where(right_col < width, right_at, 0)[..., None]
    left = (run_id == left_run) & (left_run > 0)
    right = (run_id == right_run) & (right_run > 0) & ~left
    return np.stack([left, right], axis=-3)


def lane_centres(masks: np.ndarray, rows: np.ndarray, half_lane_px: np.ndarray) -> np.ndarray:
    """Lane-centre columns at ``rows`` from left/right masks (..., 2, H, W) → (..., len(rows)) (nan
    where neither line is seen)."""
    left, right = row_centres(masks[..., 0, :, :], rows), row_centres(masks[..., 1, :, :], rows)
    both = (left + right) / 2
    return np.where(
        np.isnan(left), right - half_lane_px, np.where(np.isnan(right), left + half_lane_px, both)
    )


def state_of(centre_column: float | np.ndarray, width: int) -> int | np.ndarray:
    """5 strips of the lane centre's offset (seed pixels), or ``LOST_STATE`` where it is nan;
    a float gives an int, an array (K,) gives (K,) states."""
    column = np.asarray(centre_column, dtype=float)
    offset = (np.nan_to_num(column) - (width - 1) / 2) * SEED_IMAGE_WIDTH / width
    states = np.where(np.isnan(column), LOST_STATE, np.searchsorted(STATE_EDGES_SEED_PX, offset))
    return int(states) if states.ndim == 0 else states


class LaneState(Sensor):
    """Discrete follow-lane state from the camera: ``Discrete(6)`` (5 strips + lost).

    :param detector: ``"cnn"`` (the shipped segmentation network) or ``"classical"``.
    :param weights: a ``.pt`` file of the CNN's weights (default: the shipped ones).
    """

    name = "lane"
    help = "the CARLA study's follow-lane state: lane centre by the lane CNN (or classical), 5 strips + lost"

    def __init__(self, *, detector: str = "cnn", weights: str | None = None) -> None:
        if detector not in DETECTORS:
            raise ValueError(f"unknown lane detector {detector!r} (choose from {', '.join(DETECTORS)})")
        self.detector, self.model = detector, LANE_CAMERA
        self.rows = np.round(self.model.row_of_distance(np.array(LANE_ROWS_M))).astype(int)
        depth = self.model.to_camera(np.stack([LANE_ROWS_M, np.zeros(4), np.zeros(4)], axis=1))[:, 2]
        self.half_lane_px = self.model.focal_px * LANE_WIDTH_M / 2 / depth
        self.network = None
        if detector == "cnn":
            from drivelab.perception.lane_cnn import load_lane_cnn

            self.network = load_lane_cnn(weights)
        self._space = spaces.Discrete(LOST_STATE + 1)
        # (K, 4) lane centre columns found at the last observe, for plots and tests
        self.centres = np.full((0, len(LANE_ROWS_M)), np.nan)
        self.frames = np.zeros((0, self.model.height, self.model.width, 3), dtype=np.uint8)

    def scenario_problem(self, scenario) -> str | None:
        """Its strips and its one-line fallback (half of ``LANE_WIDTH_M``) are calibrated to the
        3.5 m lanes of the CARLA study's follow-lane circuit (``scenario.keep_lane``); on other roads
        (4 m highway lanes, follow-line's single 7 m lane) its states mean something else."""
        if not scenario.keep_lane:
            return "its states are calibrated to the 3.5 m lanes of the follow-lane circuit"
        return None

    def masks(self, image_rgb: np.ndarray) -> np.ndarray:
        """The detector's left/right line masks bool: (2, H, W) for a camera frame (H, W, 3),
        (K, 2, H, W) for K frames."""
        if self.network is not None:
            return self.network.segment(image_rgb)
        return classical_lane_masks(image_rgb, self.model)

    def _observe(self, batch: WorldBatch, out: np.ndarray) -> None:
        if len(self.frames) != batch.num_worlds:
            self.frames = np.empty((batch.num_worlds, *self.frames.shape[1:]), dtype=np.uint8)
        draw_camera(batch, self.model, self.frames)  # (K, H, W, 3)
        self.centres = lane_centres(self.masks(self.frames), self.rows, self.half_lane_px)  # (K, 4)
        found = np.isfinite(self.centres)
        # mean of the centres found (nan where none): the sum of a row's found values, in row order
        with np.errstate(invalid="ignore", divide="ignore"):
            mean = np.where(found, self.centres, 0.0).sum(axis=1) / found.sum(axis=1)
        out[...] = state_of(mean, self.model.width)
