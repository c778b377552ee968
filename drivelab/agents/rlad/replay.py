"""RLAD's replay buffer: every camera frame stored once, stacks rebuilt by index.

Consecutive stacked observations share all but their newest frame, so each environment step
writes one *observation record* (newest frame, waypoints, measurements, traffic-light label) into
a ring, and a transition keeps the record numbers of its observation's stack and of its next
observation's newest record. ``start_episode`` pads the stack with the reset observation, so no
stack mixes two episodes; a time-limit end is not terminal. The ring holds ``capacity`` plus 5 %
slack records; with very short episodes the ring, not ``capacity``, bounds how many transitions
are sampleable.

Frames may live on the networks' device (``frame_device``, allocated at the first write): a
batch's stacks are then gathered there, with no copy to the GPU per update. A checkpoint holds
the buffer as numpy arrays (``state_arrays``).
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import torch

from drivelab.agents.storage import assign_arrays

LIGHT_CLASSES = ("none", "green", "red_or_yellow")  # DriveEnv.traffic_light_label's values
UNKNOWN_LABEL = -1  # no label given: left out of the auxiliary loss
RECORD_SLACK = 0.05


def label_index(label: str | None) -> int:
    """Class index of a traffic-light label, ``UNKNOWN_LABEL`` for None."""
    return UNKNOWN_LABEL if label is None else LIGHT_CLASSES.index(label)


class FrameReplayBuffer:
    """Transitions over a ring of observation records that holds each frame once.

    :param capacity: transitions kept.
    :param frame_shape: one frame, channels first (3, H, W), uint8.
    :param stack: frames per observation K.
    :param waypoints_shape: waypoints of one observation, e.g. (10, 2).
    :param measurements_size: measurement values of one observation, e.g. 6.
    :param action_size: action dimensions.
    :param frame_device: keep the frames in a torch tensor on this device (None: a numpy array).
    """

    def __init__(
        self,
        capacity: int,
        frame_shape: tuple[int, ...],
        stack: int,
        waypoints_shape: tuple[int, ...],
        measurements_size: int,
        action_size: int,
        frame_device: torch.device | str | None = None,
    ) -> None:
        self.capacity, self.stack = int(capacity), int(stack)
        self.records = self.capacity + max(int(self.capacity * RECORD_SLACK), self.stack + 1)
        self.frame_device = None if frame_device is None else torch.device(frame_device)
        self.frames: np.ndarray | torch.Tensor = np.zeros((self.records, *frame_shape), dtype=np.uint8)
        self.waypoints = np.zeros((self.records, *waypoints_shape), dtype=np.float32)
        self.measurements = np.zeros((self.records, measurements_size), dtype=np.float32)
        self.labels = np.full(self.records, UNKNOWN_LABEL, dtype=np.int8)
        self.stacks = np.zeros((self.capacity, self.stack), dtype=np.int64)  # absolute record numbers
        self.next_newest = np.zeros(self.capacity, dtype=np.int64)
        self.actions = np.zeros((self.capacity, action_size), dtype=np.float32)
        self.rewards = np.zeros(self.capacity, dtype=np.float32)
        self.terminated = np.zeros(self.capacity, dtype=np.bool_)
        self.written = 0  # records written so far
        self.position, self.stored = 0, 0
        self.current: np.ndarray | None = None  # record numbers of the current observation's stack
        self.on_allocate: Callable[[], None] | None = None  # called once the device frames exist

    # --- writing -------------------------------------------------------------------------------
    def _write(self, frame: np.ndarray, waypoints, measurements, label: int) -> int:
        number, slot = self.written, self.written % self.records
        if self.frame_device is not None and not isinstance(self.frames, torch.Tensor):
            self._frames_to(self.frame_device)  # the first write: allocate on the device
        self.frames[slot] = frame if self.frame_device is None else torch.as_tensor(frame)
        self.waypoints[slot] = waypoints
        self.measurements[slot], self.labels[slot] = measurements, label
        self.written += 1
        return number

    def start_episode(self, frame: np.ndarray, waypoints, measurements, label: int) -> None:
        """The first observation of an episode: its stack is this frame K times."""
        self.current = np.full(self.stack, self._write(frame, waypoints, measurements, label))

    def add(
        self, action, reward: float, terminated: bool, frame: np.ndarray, waypoints, measurements, label: int
    ) -> None:
        """A transition from the current observation; ``frame`` etc. are the next observation's newest."""
        if self.current is None:
            raise RuntimeError("call start_episode before add")
        number = self._write(frame, waypoints, measurements, label)
        i = self.position
        self.stacks[i], self.next_newest[i] = self.current, number
        self.actions[i], self.rewards[i], self.terminated[i] = action, reward, terminated
        self.current = np.append(self.current[1:], number)
        self.position, self.stored = (i + 1) % self.capacity, min(self.stored + 1, self.capacity)

    # --- reading -------------------------------------------------------------------------------
    def sampleable(self) -> np.ndarray:
        """Indices of the transitions whose records are all still in the ring."""
        oldest = self.stacks[: self.stored, 0]
        return np.flatnonzero(oldest >= self.written - self.records)

    @property
    def size(self) -> int:
        return len(self.sampleable())

    def stacked_frames(self, stacks: np.ndarray) -> np.ndarray | torch.Tensor:
        """Record numbers (B, K) → frame stacks (B, 3K, H, W), oldest frame first (a tensor on
        ``frame_device`` when the frames live there)."""
        slots = stacks % self.records
        if isinstance(self.frames, torch.Tensor):
            slots = torch.as_tensor(slots, device=self.frames.device)
        frames = self.frames[slots]  # (B, K, 3, H, W)
        return frames.reshape(len(stacks), -1, *frames.shape[-2:])

    def batch(self, indices: np.ndarray) -> dict[str, np.ndarray | torch.Tensor]:
        """Transitions ``indices`` with their observation and next-observation stacks rebuilt."""
        stacks = self.stacks[indices]
        next_stacks = np.concatenate([stacks[:, 1:], self.next_newest[indices, None]], axis=1)
        newest, next_newest = stacks[:, -1] % self.records, next_stacks[:, -1] % self.records
        return {
            "images": self.stacked_frames(stacks),
            "waypoints": self.waypoints[newest],
            "measurements": self.measurements[newest],
            "labels": self.labels[newest].astype(np.int64),
            "actions": self.actions[indices],
            "rewards": self.rewards[indices],
            "terminated": self.terminated[indices].astype(np.float32),
            "next_images": self.stacked_frames(next_stacks),
            "next_waypoints": self.waypoints[next_newest],
            "next_measurements": self.measurements[next_newest],
        }

    def sample(self, batch_size: int, rng: np.random.Generator) -> dict[str, np.ndarray | torch.Tensor]:
        """``batch_size`` transitions drawn uniformly (with replacement) from the sampleable ones."""
        candidates = self.sampleable()
        return self.batch(candidates[rng.integers(len(candidates), size=batch_size)])

    # --- saving and placement ------------------------------------------------------------------
    ARRAYS = ("frames", "waypoints", "measurements", "labels", "stacks", "next_newest", "actions", "rewards",
              "terminated")  # fmt: skip
    SCALARS = ("written", "position", "stored")

    def state_arrays(self) -> dict[str, np.ndarray]:
        """Everything the buffer holds as numpy arrays (a checkpoint's ``.npz``); ``current`` (the
        open episode's stack) is empty when no episode has started."""
        arrays = {name: getattr(self, name) for name in self.ARRAYS}
        if isinstance(self.frames, torch.Tensor):
            arrays["frames"] = self.frames.cpu().numpy()
        current = np.zeros(0, dtype=np.int64) if self.current is None else self.current
        scalars = {name: np.asarray(getattr(self, name), dtype=np.int64) for name in self.SCALARS}
        return {**arrays, **scalars, "current": current}

    def load_state_arrays(self, arrays: dict[str, np.ndarray]) -> None:
        """Restore ``state_arrays`` into this buffer (same capacity, shapes and stack), its frames
        placed on ``frame_device``."""
        assign_arrays(self, arrays, self.ARRAYS + self.SCALARS)
        current = arrays.get("current")
        if current is None or current.dtype != np.int64 or current.shape not in ((0,), (self.stack,)):
            raise ValueError("the replay's 'current' stack does not fit this buffer")
        self.current = current.copy() if len(current) else None
        self.move_frames(self.frame_device)

    def __setstate__(self, state: dict) -> None:
        """Pickles of earlier drivelab versions (``drivelab convert-run`` reads them; some predate
        ``frame_device``)."""
        self.__dict__.update({"frame_device": None, "on_allocate": None, **state})

    def move_frames(self, device: torch.device | str | None) -> None:
        """Keep the frames on ``device`` from now on (None: the host, as numpy)."""
        self.frame_device = None if device is None else torch.device(device)
        if self.frame_device is None:
            if isinstance(self.frames, torch.Tensor):
                self.frames = self.frames.cpu().numpy()
        elif self.written > 0 or isinstance(self.frames, torch.Tensor):
            self._frames_to(self.frame_device)

    def _frames_to(self, device: torch.device) -> None:
        self.frames = torch.as_tensor(self.frames, device=device)
        if self.on_allocate is not None:
            self.on_allocate()

    # --- memory --------------------------------------------------------------------------------
    @property
    def observations(self) -> dict[str, np.ndarray]:
        """The observation arrays (run.py sizes the buffer by them before checkpointing it)."""
        return {"frames": self.frames, "waypoints": self.waypoints, "measurements": self.measurements}

    @property
    def nbytes(self) -> int:
        """Bytes of every array the buffer holds."""
        return int(sum(getattr(self, name).nbytes for name in self.ARRAYS))

    def unique_frame_bytes(self) -> int:
        """Bytes of the distinct frames the sampleable transitions reference."""
        indices = self.sampleable()
        numbers = np.unique(np.concatenate([self.stacks[indices].ravel(), self.next_newest[indices]]))
        return int(len(numbers) * self.frames[0].nbytes)
