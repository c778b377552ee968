"""Training data for the lane-line CNN: camera frames and true line masks rendered on the
follow-lane circuit at random poses (the CARLA study, section 4.1), and the training run that uses
them."""

from __future__ import annotations

import contextlib
import dataclasses
import os
from pathlib import Path

import numpy as np

from drivelab.errors import UsageError
from drivelab.perception.camera import render_camera, render_masks
from drivelab.perception.lane import LANE_CAMERA
from drivelab.perception.lane_cnn import WEIGHTS_PATH, train_lane_cnn
from drivelab.scenarios import get_scenario
from drivelab.sim.reference.highway import HighwayBackend

MAX_LATERAL_M = 1.2  # training poses: offset from the lane centre, uniform in ±this
HEADING_STD_DEG = 4.0  # and heading error, normal
FRAMES_PER_EPISODE = 40  # poses drawn on one reset's lane before the next
# bytes per pixel held at once while training on a frame: the frame (3) and masks (2) as uint8,
# train_lane_cnn's channels-first copy (3) and the float32 inputs (12) and targets (8) made from them
TRAINING_BYTES_PER_PIXEL = 3 + 2 + 3 + 12 + 8


def generate_lane_frames(count: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """``count`` camera frames (N, H, W, 3) uint8 and their left/right masks (N, 2, H, W) uint8 of the
    follow-lane circuit, at random places, lanes, lateral offsets and heading errors."""
    rng = np.random.default_rng(seed)
    backend = HighwayBackend(get_scenario("follow-lane"), "empty", "continuous")
    images = np.empty((count, LANE_CAMERA.height, LANE_CAMERA.width, 3), np.uint8)
    masks = np.empty((count, 2, LANE_CAMERA.height, LANE_CAMERA.width), np.uint8)
    world = None
    for index in range(count):
        if index % FRAMES_PER_EPISODE == 0:  # a new episode: another lane of the circuit
            world = backend.reset(int(rng.integers(2**31 - 1)))
            route = np.asarray(world.route.polyline, dtype=float)
            stations = np.r_[0.0, np.cumsum(np.hypot(*np.diff(route, axis=0).T))]
        station = rng.uniform(0.0, stations[-1] - 1.0)
        segment = int(np.searchsorted(stations, station, side="right")) - 1
        direction = route[segment + 1] - route[segment]
        direction /= np.linalg.norm(direction)
        centre = route[segment] + (station - stations[segment]) * direction
        lateral = rng.uniform(-MAX_LATERAL_M, MAX_LATERAL_M)
        heading = np.arctan2(direction[1], direction[0]) + np.radians(rng.normal(0.0, HEADING_STD_DEG))
        position = centre + lateral * np.array([-direction[1], direction[0]])
        ego = dataclasses.replace(
            world.ego, position=position, heading=float(heading), lateral_offset_m=lateral
        )
        posed = dataclasses.replace(world, ego=ego)
        images[index] = render_camera(posed, LANE_CAMERA)
        masks[index] = render_masks(posed, LANE_CAMERA)[:2]
    return images, masks


def training_memory_bytes(frames: int) -> int:
    """Memory that ``train_lane_detector`` holds for ``frames`` frames (all are kept for every epoch)."""
    return frames * LANE_CAMERA.width * LANE_CAMERA.height * TRAINING_BYTES_PER_PIXEL


def available_memory_bytes() -> int | None:
    """Memory this machine can give a process now (Linux's MemAvailable, else its physical memory;
    None when neither is known)."""
    with contextlib.suppress(OSError, ValueError, IndexError):
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemAvailable:"):
                return int(line.split()[1]) * 1024
    from drivelab.agents.buffer_memory import physical_memory_bytes

    return physical_memory_bytes()


def check_lane_training(frames: int, epochs: int, seed: int, out: str | Path) -> Path:
    """Check ``train_lane_detector``'s arguments before anything is generated: counts and seed in
    range, the frames fit in memory, ``out`` a writable ``.pt`` path. Returns ``out`` as a Path."""
    if frames < 1 or epochs < 1:
        raise UsageError("--frames and --epochs must be >= 1")
    if seed < 0:
        raise UsageError(f"--seed must be >= 0, got {seed}")
    needed, available = training_memory_bytes(frames), available_memory_bytes()
    if available is not None and needed > available:
        raise UsageError(
            f"--frames {frames} needs about {needed / 2**30:.1f} GiB of memory to train on, "
            f"{available / 2**30:.1f} GiB is available; use fewer frames"
        )
    out = Path(out)
    if out.suffix != ".pt" or out.is_dir():
        raise UsageError(f"--out {str(out)!r} must name a .pt file (the lane CNN's weights)")
    from drivelab.training.evaluate import check_output_file

    check_output_file(out, "--out")
    return out


def train_lane_detector(
    frames: int = 1500, epochs: int = 15, seed: int = 0, out: str | Path = WEIGHTS_PATH, log=print
) -> dict:
    """Generate ``frames`` frames with ``seed``, train the lane CNN on them, save its weights to
    ``out`` (whole or not at all) and return the training summary."""
    out = check_lane_training(frames, epochs, seed, out)
    images, masks = generate_lane_frames(frames, seed)
    partial = out.with_name(out.name + ".tmp")
    try:
        summary = train_lane_cnn(images, masks, epochs=epochs, seed=seed, out=partial, log=log)
        os.replace(partial, out)
    except BaseException:
        with contextlib.suppress(OSError):
            partial.unlink()
        raise
    return {**summary, "weights": str(out)}
