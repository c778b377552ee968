"""Training data for the lane-line CNN: camera frames and true line masks rendered on the follow-lane
circuit at random poses (seed 004, section 4.1), and the training run that uses them.

This lives in ``training/`` because it drives the simulator (a highway-env backend builds the
circuit); ``perception/lane_cnn.py`` only defines the network and trains it on given arrays.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

from drivelab.envs.backends.highway import HighwayBackend
from drivelab.envs.scenarios import get_scenario
from drivelab.perception.camera import render_camera, render_masks
from drivelab.perception.lane import LANE_CAMERA
from drivelab.perception.lane_cnn import WEIGHTS_PATH, train_lane_cnn

MAX_LATERAL_M = 1.2  # training poses: offset from the lane centre, uniform in ±this
HEADING_STD_DEG = 4.0  # and heading error, normal
FRAMES_PER_EPISODE = 40  # poses drawn on one reset's lane before the next


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


def train_lane_detector(
    frames: int = 1500, epochs: int = 15, seed: int = 0, out: str | Path = WEIGHTS_PATH, log=print
) -> dict:
    """Generate ``frames`` frames with ``seed``, train the lane CNN on them (``train_lane_cnn``),
    save its weights to ``out`` and return the training summary."""
    images, masks = generate_lane_frames(frames, seed)
    return train_lane_cnn(images, masks, epochs=epochs, seed=seed, out=out, log=log)
