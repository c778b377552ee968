"""Draw one picture per scenario for the documentation, with drivelab's own video renderer.

    .venv/bin/python docs/make_pictures.py            # every scenario
    .venv/bin/python docs/make_pictures.py town racetrack

Each picture is the frame drivelab's videos show (``drivelab.envs.video.EpisodeRecorder``) after a
few idle steps of the scenario's first evaluation episode, written to ``docs/images/<scenario>.png``.
The pictures are committed; run this again when the renderer or a scenario changes. The block
maps' page uses the committed gallery of ``benchmarks/pg_maps.py`` as well.
"""

from __future__ import annotations

import sys
from pathlib import Path

import cv2
import numpy as np

import drivelab
from drivelab.envs.video import EpisodeRecorder

OUT = Path(__file__).resolve().parent / "images"
EPISODE_SEED = 2**31  # the first episode of every scenario's fixed evaluation set
STEPS = 4  # policy steps before the picture: the traffic has moved off its spawn points
MAX_BYTES = 150_000  # the committed pictures stay small


def idle_action(env):
    """An action that keeps the ego on its course: the meta-actions' IDLE, zero controls, or the
    seed tables' straight-ahead entry."""
    space, name = env.action_space, env.vector.adapter.name
    if name == "meta":
        return 1
    if name in ("seed_line", "seed_lane"):
        return 1 if name == "seed_line" else 3
    if name == "grid":
        return space.n // 2
    action = np.zeros(space.shape, dtype=space.dtype)  # continuous: no steering, no acceleration
    if name == "target_speed":
        action[0] = 0.5  # half the action's top speed, no steering
    return action


def picture(scenario: str) -> Path:
    env = drivelab.make(scenario, obs="kinematics", seed=0)
    env.reset(options={"episode_seed": EPISODE_SEED})
    recorder = EpisodeRecorder(env, side_by_side=False)
    frame = recorder.first_frame()
    for _ in range(STEPS):
        (_, _, terminated, truncated, _), frames = recorder.step(idle_action(env))
        frame = frames[-1]
        if terminated or truncated:
            break
    env.close()
    path = OUT / f"{scenario}.png"
    image = cv2.cvtColor(frame, cv2.COLOR_RGB2BGR)
    for scale in (1.0, 0.8, 0.6, 0.5):  # the largest size under MAX_BYTES
        small = cv2.resize(image, None, fx=scale, fy=scale, interpolation=cv2.INTER_AREA)
        ok, data = cv2.imencode(".png", small, [cv2.IMWRITE_PNG_COMPRESSION, 9])
        if ok and len(data) <= MAX_BYTES:
            break
    path.write_bytes(data.tobytes())
    return path


def main(names: list[str]) -> None:
    from hooks import SCENARIOS  # the docs' one import of the scenario registry (docs/ is on the path)

    OUT.mkdir(exist_ok=True)
    for name in names or list(SCENARIOS):
        path = picture(name)
        print(f"{path.relative_to(Path.cwd()) if path.is_relative_to(Path.cwd()) else path}: "
              f"{path.stat().st_size / 1000:.0f} kB")


if __name__ == "__main__":
    main(sys.argv[1:])
