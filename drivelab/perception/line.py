"""Follow-line perception (the CARLA study, section 3): the yellow line's centre at 4 rows → a discrete state.

The camera frame is thresholded around yellow in HSV, then opened (eroded and dilated); in each of
4 rows the line's centre is the mean column of the pixels kept, and falls in one of ``strips``
equal vertical strips or is missing. The state encodes the 4 answers in base ``strips + 1``; the
last state, every row missing, is "line lost".
"""

from __future__ import annotations

import cv2
import numpy as np
from gymnasium import spaces

from drivelab.perception.base import Sensor
from drivelab.perception.camera import draw_camera
from drivelab.world.batch import WorldBatch
from drivelab.world.pinhole import LINE_CAMERA, LINE_ROWS_M

# OpenCV hue runs 0–180: yellow is about 30; saturated and bright, unlike road, grass and sky
YELLOW_LOW, YELLOW_HIGH = np.array([20, 120, 120]), np.array([40, 255, 255])


def yellow_mask(image_rgb: np.ndarray, kernel_px: int = 3) -> np.ndarray:
    """HSV threshold on yellow, then erosion and dilation with a ``kernel_px`` square (uint8 0/255):
    frames (..., H, W, 3) → masks (..., H, W). The threshold is per pixel, so K frames go through it
    as one tall image; the opening looks at neighbours, so it runs frame by frame."""
    shape = image_rgb.shape
    hsv = cv2.cvtColor(np.ascontiguousarray(image_rgb).reshape(-1, shape[-2], 3), cv2.COLOR_RGB2HSV)
    masks = cv2.inRange(hsv, YELLOW_LOW, YELLOW_HIGH).reshape(-1, *shape[-3:-1])
    kernel = np.ones((kernel_px, kernel_px), np.uint8)
    for mask in masks:
        cv2.dilate(cv2.erode(mask, kernel), kernel, dst=mask)
    return masks.reshape(shape[:-1])


def row_centres(mask: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """Mean column of the mask's pixels in each of ``rows`` (nan where a row has none): masks
    (..., H, W) → centres (..., len(rows))."""
    selected = mask[..., rows, :] > 0
    counts = selected.sum(axis=-1)
    columns = np.arange(mask.shape[-1])
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(counts > 0, (selected * columns).sum(axis=-1) / counts, np.nan)


def strip_of(centres: np.ndarray, width: int, strips: int) -> np.ndarray:
    """Strip index (0 = leftmost) of each centre column, ``strips`` for a missing one."""
    index = np.floor(np.nan_to_num(centres, nan=-1.0) / width * strips).astype(int)
    return np.where(np.isnan(centres), strips, np.clip(index, 0, strips - 1))


def encode_state(values: np.ndarray, base: int) -> int | np.ndarray:
    """Row values (..., rows), nearest row first → integers (...) in base ``base`` (the nearest row
    is the lowest digit); one row vector gives a Python int."""
    values = np.asarray(values)
    codes = np.sum(values * base ** np.arange(values.shape[-1]), axis=-1)
    return int(codes) if values.ndim == 1 else codes


class LineState(Sensor):
    """Discrete follow-line state from the camera: ``Discrete((strips + 1) ** 4)``.

    :param strips: number of equidistant vertical strips (the seed's ``n``; it does not give it).
    :param kernel_px: size of the erosion/dilation square.
    """

    name = "line"
    help = "the CARLA study's follow-line state: yellow line centre at 4 rows, each in 5 strips or lost"

    def __init__(self, *, strips: int = 5, kernel_px: int = 3) -> None:
        if strips < 2 or kernel_px < 1:
            raise ValueError("line needs strips >= 2 and kernel_px >= 1")
        self.strips, self.kernel_px = int(strips), int(kernel_px)
        self.model = LINE_CAMERA
        self.rows = np.round(self.model.row_of_distance(np.array(LINE_ROWS_M))).astype(int)
        self._space = spaces.Discrete((self.strips + 1) ** len(LINE_ROWS_M))
        # (K, 4) line centre columns found at the last observe, for plots and tests
        self.centres = np.full((0, len(LINE_ROWS_M)), np.nan)
        self.frames = np.zeros((0, self.model.height, self.model.width, 3), dtype=np.uint8)

    def scenario_problem(self, scenario) -> str | None:
        """It looks for the yellow guide line, painted only where ``scenario.guide_line``
        (follow-line); elsewhere every frame is the constant "lost" state."""
        if not scenario.guide_line:
            return "it reads the yellow guide line, which only the follow-line circuit has painted"
        return None

    @property
    def lost_state(self) -> int:
        return self._space.n - 1

    def detect(self, image_rgb: np.ndarray) -> np.ndarray:
        """Line centre columns at the 4 rows of a camera frame (H, W, 3) → (4,), or of frames
        (K, H, W, 3) → (K, 4) (nan where not seen)."""
        return row_centres(yellow_mask(image_rgb, self.kernel_px), self.rows)

    def _observe(self, batch: WorldBatch, out: np.ndarray) -> None:
        if len(self.frames) != batch.num_worlds:
            self.frames = np.empty((batch.num_worlds, *self.frames.shape[1:]), dtype=np.uint8)
        draw_camera(batch, self.model, self.frames)  # (K, H, W, 3)
        self.centres = row_centres(yellow_mask(self.frames, self.kernel_px), self.rows)  # (K, 4)
        out[...] = encode_state(strip_of(self.centres, self.model.width, self.strips), self.strips + 1)
