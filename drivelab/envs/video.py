"""Videos for people: every simulation frame, a landscape view, and what the agent did.

``EpisodeRecorder`` wraps one world of an env (a ``DriveEnv``, or world ``k`` of a
``VectorDriveEnv``): while it steps, the compiled simulator runs its frames one call each and hands
the batch after every frame to the recorder (``FastSimulator.on_frame``: the same episode, bit for
bit, see ``run_frames``), so a video has ``frames per step`` frames per policy step and plays
at the simulation frequency (highway-env's ``_automatic_rendering`` idea). highway-env's reference
backend has no frame hook: there, one frame per policy step.

Each frame is the scene drawn by ``perception/birdeye.draw_birdeye`` from a camera of its own:

- along the road (highway-env's scenarios and the circuits): landscape, the ego a third of the
  way in from the left, its lane's direction pointing right;
- the map from above (the town, the block maps): north up (world x right, world y down, as on
  the simulators' screens), a wider view, the lights' stop bars and a ring to find the ego by;

above a strip that writes the time, the speed (m/s and km/h), the action, the step's reward, the
return so far and the events (crash, off-road, arrival, red light, blocked, off route). With
``side_by_side`` (the default when the agent sees an image: camera, birdeye or topdown) the
agent's own image, scaled up, stands left of the scene.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from functools import lru_cache

import cv2
import numpy as np

from drivelab.errors import UsageError
from drivelab.perception.birdeye import draw_birdeye
from drivelab.perception.topdown import LanePolygons, View
from drivelab.world.batch import EVENT_FLAGS, WorldBatch
from drivelab.world.scenario import Scenario

STRIP_HEIGHT = 48  # the overlay strip under the scene, two lines of text
STRIP_BACKGROUND = (24, 24, 28)
TEXT = (235, 235, 235)
# the strip's event badges and their colours, in the order of batch.events' flags (EVENT_FLAGS)
EVENT_COLOURS = {"CRASH": (235, 60, 50), "OFF-ROAD": (240, 150, 40), "ARRIVED": (70, 200, 90)}
EVENT_COLOURS |= {"RED LIGHT": (235, 60, 50), "BLOCKED": (240, 150, 40), "OFF ROUTE": (240, 150, 40)}
EVENT_NAMES = dict(zip(EVENT_FLAGS, EVENT_COLOURS, strict=True))  # flag → badge
EGO_RING = (255, 235, 60)
IMAGE_SENSORS = ("camera", "birdeye", "topdown")  # the observations side-by-side shows
# topdown's channels in colour: road, route, past ego positions, traffic now, traffic before
TOPDOWN_COLOURS = ((80, 80, 84), (70, 90, 200), (60, 200, 70), (230, 230, 230), (110, 110, 160))
TOPDOWN_LIGHTS = {85: (40, 200, 60), 170: (240, 200, 30), 255: (230, 30, 30)}


@dataclass(frozen=True)
class Camera:
    """A video camera: image size, resolution, and where it looks.

    :param along_road: turn with the ego's lane (its direction drawn to the right); else north up.
    :param ego_column: the ego's place across the image, a fraction of its width from the left.
    """

    size_hw: tuple[int, int]
    pixels_per_meter: float
    along_road: bool
    ego_column: float = 0.5


ROAD_CAMERA = Camera((256, 720), 7.0, along_road=True, ego_column=1 / 3)  # 103 m x 37 m
MAP_CAMERA = Camera((432, 720), 3.0, along_road=False)  # 240 m x 144 m, north up


def camera_for(scenario: Scenario) -> Camera:
    """The map from above for the town and the block maps, else the view along the road."""
    return MAP_CAMERA if scenario.camera == "map" else ROAD_CAMERA


def camera_view(batch: WorldBatch, camera: Camera) -> View:
    """The camera of each of the K worlds as a birdeye ``View``: its centre (K, 2) and the world
    direction it draws upwards (K,) (``to_pixels``: a view of heading h draws h − π/2 upwards
    … h to the right, and y down when h = 0)."""
    ego = batch.ego
    direction = ego.lane_heading if camera.along_road else np.zeros(batch.num_worlds)
    ahead_m = (0.5 - camera.ego_column) * camera.size_hw[1] / camera.pixels_per_meter
    centre = ego.position + ahead_m * np.column_stack([np.cos(direction), np.sin(direction)])
    return View(centre, direction - np.pi / 2, camera.size_hw, camera.pixels_per_meter)


def draw_scene(batch: WorldBatch, camera: Camera, out: np.ndarray | None = None) -> np.ndarray:
    """The K worlds' scenes (K, H, W, 3) uint8 seen by ``camera`` (into ``out`` when given).

    The map camera copies each frame's road from its map's ``Backdrop`` (the road drawn once) and
    draws only what moves over it; its view moves in whole pixels (``map_view``)."""
    if out is None:
        out = np.empty((batch.num_worlds, *camera.size_hw, 3), dtype=np.uint8)
    if camera.along_road:
        draw_birdeye(batch, out, camera.pixels_per_meter, camera_view(batch, camera))
        return out
    view = map_view(batch, camera)
    for k in range(batch.num_worlds):
        if not backdrop(batch, k, camera).copy_into(out[k], view.positions[k]):  # off its map
            one = View(view.positions[k : k + 1], view.headings[k : k + 1], view.size_hw, view.ppm)
            draw_birdeye(batch.select(np.array([k])), out[k : k + 1], view.ppm, one, layers="road")
    draw_birdeye(batch, out, camera.pixels_per_meter, view, layers="moving")
    ring_egos(batch, out, view)
    return out


def ring_egos(batch: WorldBatch, out: np.ndarray, view: View) -> None:
    """A ring around each ego of ``out`` (K, H, W, 3): a small ego in a large map."""
    centre = view.pixels(batch.ego.position[:, None])[:, 0]
    radius = int(round(4.0 * view.ppm))
    for image, (column, row) in zip(out, np.round(centre).astype(int), strict=True):
        cv2.circle(image, (int(column), int(row)), radius, EGO_RING, 2, cv2.LINE_AA)


class Backdrop:
    """A map's road layer (grass, lanes, markings, crossings: ``draw_birdeye(layers="road")``)
    drawn once over the whole map, and a frame margin around it, at a north-up camera's scale.

    A frame of that camera whose centre falls on a whole pixel of the backdrop is the backdrop's
    window around it, then the moving layer: a long video draws its map once, not every frame.
    """

    def __init__(self, batch: WorldBatch, k: int, camera: Camera) -> None:
        self.road, self.camera = batch.road_of(k), camera
        vertices = self.road.derived(LanePolygons, LanePolygons).vertices
        low, high = vertices.min(axis=0), vertices.max(axis=0)
        centre = (low + high) / 2
        probe = View(centre, -np.pi / 2, (2, 2), camera.pixels_per_meter)  # north up, as the camera
        span = np.abs(np.subtract(*probe.pixels_of(0, np.stack([low, high]))))  # (columns, rows) covered
        height, width = (np.ceil(span[::-1]).astype(int) + np.array(camera.size_hw) + 4).tolist()
        self.view = View(centre, -np.pi / 2, (height, width), camera.pixels_per_meter)
        self.image = np.empty((1, height, width, 3), dtype=np.uint8)
        one = batch.select(np.array([k]))
        draw_birdeye(one, self.image, camera.pixels_per_meter, self.view, layers="road")
        self.image = self.image[0]

    def copy_into(self, image: np.ndarray, centre: np.ndarray) -> bool:
        """Copy the window of the frame centred at ``centre`` (on whole pixels of the backdrop:
        ``map_view``) into ``image``; False (nothing copied) when it is not all on the backdrop."""
        column, row = self.view.pixels_of(0, centre)
        height, width = self.camera.size_hw
        # the backdrop's pixel under the frame's top-left one
        row, column = int(round(row - (height / 2 - 0.5))), int(round(column - (width / 2 - 0.5)))
        if min(row, column) < 0 or row + height > len(self.image) or column + width > self.image.shape[1]:
            return False
        image[:] = self.image[row : row + height, column : column + width]
        return True


_BACKDROPS: list[Backdrop] = []  # the latest few (block maps change every episode)


def backdrop(batch: WorldBatch, k: int, camera: Camera) -> Backdrop:
    """World ``k``'s map's backdrop for ``camera``, drawn at its first use."""
    road = batch.road_of(k)
    for found in _BACKDROPS:
        if found.road is road and found.camera == camera:
            return found
    made = Backdrop(batch, k, camera)
    _BACKDROPS.insert(0, made)
    del _BACKDROPS[4:]
    return made


def map_view(batch: WorldBatch, camera: Camera) -> View:
    """The north-up camera of each world (``camera_view``), its centre moved by at most half a
    pixel each way so that the frame's pixels are whole pixels of its map's backdrop: a frame is
    then a window of it."""
    view = camera_view(batch, camera)
    centres = view.positions.copy()
    half = np.array(camera.size_hw[::-1]) / 2 - 0.5  # the centre's (column, row) in a frame
    for k in range(batch.num_worlds):
        pixel = backdrop(batch, k, camera).view.pixels_of(0, centres[k])
        # pixels of a north-up view: column = … + x·ppm, row = … + y·ppm (x right, y down)
        centres[k] += (np.round(pixel - half) + half - pixel) / camera.pixels_per_meter
    return View(centres, view.headings, view.size_hw, view.ppm)


# --- the strip --------------------------------------------------------------------------------
class Glyphs:
    """Pillow's default font at one size, each word drawn once: a line of text is its words'
    coverage masks laid side by side at their advances, blended in one go (what Pillow's
    ``ImageDraw.text`` draws, without laying out and rasterising every frame: a strip's words and
    numbers repeat from frame to frame)."""

    LIMIT = 4096  # words kept

    def __init__(self, size: int) -> None:
        from PIL import ImageFont

        self.font = ImageFont.load_default(size=size)
        self.height = size + size // 2  # room for descenders
        self.space = self.font.getlength(" ")
        self.masks: dict[str, tuple[np.ndarray, float]] = {}

    def word(self, word: str) -> tuple[np.ndarray, float]:
        """``word``'s coverage (height, w) uint8 and its advance in pixels."""
        found = self.masks.get(word)
        if found is None:
            from PIL import Image, ImageDraw

            if len(self.masks) >= self.LIMIT:
                self.masks.clear()
            width = max(int(np.ceil(self.font.getbbox(word)[2])), 1)
            picture = Image.new("L", (width, self.height))
            ImageDraw.Draw(picture).text((0, 0), word, fill=255, font=self.font)
            found = self.masks[word] = (np.asarray(picture), self.font.getlength(word))
        return found

    def width(self, text: str) -> float:
        words = text.split(" ")
        return sum(self.word(word)[1] for word in words if word) + self.space * (len(words) - 1)

    def draw(self, image: np.ndarray, xy: tuple[float, int], text: str, colour) -> None:
        """Write ``text`` on ``image`` (H, W, 3) uint8 in place, its top-left at ``xy``."""
        left, top = int(round(xy[0])), xy[1]
        coverage = np.zeros((self.height, max(image.shape[1] - left, 0)), dtype=np.uint8)
        x = 0.0
        for word in text.split(" "):
            if word:
                mask, advance = self.word(word)
                column = int(round(x))
                part = coverage[: mask.shape[0], column : column + mask.shape[1]]
                np.maximum(part, mask[: part.shape[0], : part.shape[1]], out=part)
                x += advance
            x += self.space
        coverage = coverage[:, : int(np.ceil(x)) + self.height]  # blend only the columns it covers
        band = image[top : top + self.height, left : left + coverage.shape[1]]
        alpha = coverage[: len(band), :, None].astype(np.float32) / 255.0
        band[:] = (band * (1.0 - alpha) + np.asarray(colour, dtype=np.float32) * alpha + 0.5).astype(np.uint8)


_glyphs = lru_cache(maxsize=4)(Glyphs)  # one per font size, its words kept


@dataclass(frozen=True)
class Caption:
    """What the strip under a frame says."""

    time_s: float
    speed_mps: float
    action: str
    reward: float | None  # None on an episode's first frame
    episode_return: float
    events: tuple[str, ...] = ()
    episode: int = 0


def draw_strip(strip: np.ndarray, caption: Caption) -> None:
    """Write ``caption`` on ``strip`` (S, W, 3) uint8, in place (Pillow's default font)."""
    strip[:] = STRIP_BACKGROUND
    glyphs = _glyphs(15)
    reward = "-" if caption.reward is None else f"{caption.reward:+.3f}"
    first = (
        f"episode {caption.episode + 1}   t {caption.time_s:5.1f} s   "
        f"speed {caption.speed_mps:5.1f} m/s  {caption.speed_mps * 3.6:5.1f} km/h"
    )
    second = f"action {caption.action}   reward {reward}   return {caption.episode_return:+.2f}"
    glyphs.draw(strip, (8, 5), first, TEXT)
    glyphs.draw(strip, (8, 26), second, TEXT)
    right = strip.shape[1] - 8
    for event in reversed(caption.events):  # right-aligned badges
        width = int(round(glyphs.width(event))) + 12
        cv2.rectangle(strip, (right - width, 6), (right, 40), EVENT_COLOURS.get(event, (200, 60, 50)), -1)
        glyphs.draw(strip, (right - width + 6, 14), event, (255, 255, 255))
        right -= width + 6


def events_of(batch: WorldBatch, k: int, end_of_step: bool) -> tuple[str, ...]:
    """World ``k``'s events as the strip names them. Between a step's frames only what the frame
    itself shows (a collision, leaving the road); at a step's end also what the rules judge once
    per step (arrival, a red light run, blocked, off route)."""
    flags = EVENT_FLAGS if end_of_step else ("collided", "off_road")
    return tuple(EVENT_NAMES[flag] for flag in flags if getattr(batch.events, flag)[k])


def action_text(adapter, action) -> str:
    """A short description of one world's ``action`` for the strip."""
    values = np.asarray(action).reshape(-1)
    if adapter.name == "meta":
        return adapter.names[int(values[0])]
    table = getattr(adapter, "table", None)
    if table is not None:  # a discrete table of [acceleration, steering] rows
        accel, steer = table[int(values[0])]
        return f"#{int(values[0])} (accel {accel:+.2f}, steer {steer:+.2f})"
    if adapter.name == "target_speed":
        return f"target {values[0] * adapter.max_speed_mps:4.1f} m/s, steer {values[1]:+.2f}"
    if adapter.name == "continuous":
        return f"steer {values[0]:+.2f}, accel {values[1]:+.2f}"
    return " ".join(f"{v:+.2f}" for v in values)


# --- what the agent sees ------------------------------------------------------------------------
def image_sensor(sensors) -> object | None:
    """The first sensor of ``sensors`` that gives an image (camera, birdeye, topdown), else None."""
    return next((s for s in sensors if getattr(s, "sensor", s).name in IMAGE_SENSORS), None)


def observation_image(sensor, observation: np.ndarray) -> np.ndarray:
    """One world's image observation of ``sensor`` as RGB (H, W, 3) uint8: a camera or birdeye
    frame as it is, topdown's channels in colour (the newest frame of a stack)."""
    inner = getattr(sensor, "sensor", sensor)  # a FrameStack's sensor
    frames = getattr(sensor, "frames", 1)
    observation = np.asarray(observation)
    if inner.name != "topdown":
        return np.ascontiguousarray(observation[..., -3:])  # RGB stacks along the last axis
    channels = observation[-observation.shape[0] // frames :]  # (C, S, S), the newest frame
    image = np.full((*channels.shape[1:], 3), 16, dtype=np.uint8)
    for channel, colour in zip(channels[:5], TOPDOWN_COLOURS, strict=False):
        image[channel > 0] = colour
    image[channels[3] > 0] = TOPDOWN_COLOURS[3]  # traffic now above traffic before
    if len(channels) > 5:  # the lights channel
        for level, colour in TOPDOWN_LIGHTS.items():
            image[channels[5] == level] = colour
    return image


def side_by_side(left: np.ndarray, scene: np.ndarray) -> np.ndarray:
    """``left`` scaled (nearest pixel) to ``scene``'s height, then ``scene``: (H, W_left + W, 3)."""
    height = scene.shape[0]
    width = max(1, int(round(left.shape[1] * height / left.shape[0])))
    scaled = cv2.resize(left, (width, height), interpolation=cv2.INTER_NEAREST)
    return np.concatenate([scaled, scene], axis=1)


# --- recording ----------------------------------------------------------------------------------
def video_fps(env) -> float:
    """The frame rate of ``env``'s recorded videos (a DriveEnv or VectorDriveEnv): its simulation
    frequency on the compiled core (a frame per simulation frame), its policy frequency on
    highway-env's reference backend (no frame hook), so that a video plays in real time."""
    simulator = getattr(env, "vector", env).simulator
    frames_per_step = int(simulator.frames) if hasattr(simulator, "on_frame") else 1
    return float(simulator.policy_frequency_hz) * frames_per_step


class EpisodeRecorder:
    """Frames of world ``world`` of ``env`` for people (see the module docstring).

    Use ``first_frame()`` after each reset and ``step(action)`` instead of ``env.step``: it steps
    the env with the frame hook on and returns the step's result with its frames.

    :param env: a ``DriveEnv`` or a ``VectorDriveEnv``.
    :param side_by_side: put the agent's image observation left of the scene; None: when it
        has one (camera, birdeye, topdown).
    :param camera: default the scenario's (``camera_for``).
    """

    def __init__(
        self, env, side_by_side: bool | None = None, camera: Camera | None = None, world: int = 0
    ) -> None:
        self.vector = getattr(env, "vector", env)
        self.env, self.world = env, world
        self.camera = camera or camera_for(self.vector.scenario)
        self.sensor = image_sensor(self.vector.sensors)
        if side_by_side and self.sensor is None:
            names = ", ".join(s.name for s in self.vector.sensors)
            raise UsageError(
                f"side-by-side needs an image observation (camera, birdeye, topdown); got {names}"
            )
        self.side_by_side = self.sensor is not None if side_by_side is None else side_by_side
        self.hooked = hasattr(self.vector.simulator, "on_frame")  # the compiled core's hook
        self.fps = video_fps(env)
        self.episode = -1
        self.episode_return = 0.0
        self._scene = np.empty((1, *self.camera.size_hw, 3), dtype=np.uint8)

    def first_frame(self, episode: int | None = None) -> np.ndarray:
        """The frame of the episode just reset (its return starts at 0); ``episode``: its index
        (default: the one after the last)."""
        self.episode = self.episode + 1 if episode is None else episode
        self.episode_return = 0.0
        batch = self.vector.batch
        return self._frame(batch, self._caption(batch, "-", None, ()))

    def step(self, action) -> tuple[tuple, list[np.ndarray]]:
        """``env.step(action)`` frame by frame: (the step's result, its frames: one per
        simulation frame, the last the step's end state)."""
        batches: list[WorldBatch] = []
        seen = self._agent_image()  # what the agent acted on, shown through the step
        simulator = self.vector.simulator
        if self.hooked:
            simulator.on_frame = batches.append
        try:
            result = self.env.step(action)
        finally:
            if self.hooked:
                simulator.on_frame = None
        reward = float(np.asarray(result[1]).reshape(-1)[self.world if np.ndim(result[1]) else 0])
        self.episode_return += reward
        own_action = np.asarray(action)[self.world] if self.env is self.vector else action
        text = action_text(self.vector.adapter, own_action)
        batches = batches[:-1] + [self.vector.batch]  # the last frame: the step's end, judged
        frames = []
        for index, batch in enumerate(batches):
            end = index == len(batches) - 1
            caption = self._caption(batch, text, reward, events_of(batch, self._row(batch), end))
            before_end_s = (len(batches) - 1 - index) / self.fps
            frames.append(self._frame(batch, replace(caption, time_s=caption.time_s - before_end_s), seen))
        return result, frames

    def _row(self, batch: WorldBatch) -> int:
        return self.world if batch.num_worlds > 1 else 0

    def _caption(self, batch: WorldBatch, action: str, reward: float | None, events) -> Caption:
        k = self._row(batch)
        return Caption(
            time_s=float(self.vector.batch.time_s[k]),
            speed_mps=float(batch.ego.speed_mps[k]),
            action=action,
            reward=reward,
            episode_return=self.episode_return,
            events=events,
            episode=self.episode,
        )

    def _agent_image(self) -> np.ndarray | None:
        if not self.side_by_side or self.vector.observations is None:
            return None
        observations = self.vector.observations
        if isinstance(observations, dict):
            observations = observations[self.sensor.name]
        return observation_image(self.sensor, observations[self.world])

    def _frame(self, batch: WorldBatch, caption: Caption, seen: np.ndarray | None = None) -> np.ndarray:
        k = self._row(batch)
        one = batch if batch.num_worlds == 1 else batch.select(np.array([k]))
        scene = draw_scene(one, self.camera, self._scene)[0]
        if self.side_by_side:
            scene = side_by_side(self._agent_image() if seen is None else seen, scene)
        frame = np.empty((scene.shape[0] + STRIP_HEIGHT, scene.shape[1], 3), dtype=np.uint8)
        frame[: scene.shape[0]] = scene
        draw_strip(frame[scene.shape[0] :], caption)
        return frame
