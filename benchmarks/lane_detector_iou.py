"""Lane-line detectors scored on held-out generated frames: IoU of the left/right line masks and
agreement of the resulting lane state with the state from the ground-truth masks.

    .venv/bin/python benchmarks/lane_detector_iou.py [--frames 300] [--seed 12345]

Frames come from ``generate_lane_frames`` with a seed the shipped CNN was not trained on (it was
trained with seed 0): the follow-lane circuit at random places, lanes, offsets (±1.2 m) and
heading errors (σ 4°), drawn by drivelab's camera at 160 x 120. IoU is pooled over all frames'
pixels per line; "state agreement" is the share of frames whose 6-valued lane state equals the
one computed from the true masks.
"""

from __future__ import annotations

import json
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np

os.environ.setdefault("PYGAME_HIDE_SUPPORT_PROMPT", "1")

import torch  # noqa: E402

from drivelab.perception.lane import LaneState, classical_lane_masks, lane_centres, state_of  # noqa: E402
from drivelab.perception.lane_cnn import iou, load_lane_cnn  # noqa: E402
from drivelab.training.lane_dataset import generate_lane_frames  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from provenance import Parser, cpu_isa, whole  # noqa: E402

RESULTS = Path(__file__).parent / "results"


def lane_state(masks: np.ndarray, sensor: LaneState) -> int:
    centres = lane_centres(masks, sensor.rows, sensor.half_lane_px)
    return state_of(float(np.nanmean(centres)) if np.isfinite(centres).any() else np.nan, sensor.model.width)


def main() -> None:
    parser = Parser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=whole(), default=300)
    parser.add_argument("--seed", type=whole(0), default=12345)
    args = parser.parse_args()
    torch.set_num_threads(1)
    images, truth = generate_lane_frames(args.frames, args.seed)
    truth = truth.astype(bool)
    network = load_lane_cnn()
    sensor = LaneState(detector="classical")
    predictions = {
        "cnn": np.stack([network.segment(image) for image in images]),
        "classical": np.stack([classical_lane_masks(image) for image in images]),
    }
    true_states = np.array([lane_state(m, sensor) for m in truth])
    rows = []
    for name, predicted in predictions.items():
        states = np.array([lane_state(m, sensor) for m in predicted])
        per_frame = [iou(p, t) for p, t in zip(predicted, truth, strict=True)]
        rows.append({
            "detector": name,
            "iou_left": iou(predicted[:, 0], truth[:, 0]),
            "iou_right": iou(predicted[:, 1], truth[:, 1]),
            "iou_both": iou(predicted, truth),
            "median_frame_iou": float(np.median(per_frame)),
            "state_agreement": float(np.mean(states == true_states)),
            "state_within_one": float(np.mean(np.abs(states - true_states) <= 1)),
        })  # fmt: skip
        print(rows[-1], flush=True)
    result = {
        "command": "python " + " ".join(sys.argv),
        "machine": f"{cpu_isa()}, {os.cpu_count()} cores, Python {platform.python_version()}",
        "date": time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime()),
        "frames": args.frames,
        "seed": args.seed,
        "rows": rows,
    }
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / "lane_detector_iou.json").write_text(json.dumps(result, indent=2))
    lines = [
        "# Lane-line detectors on held-out generated frames",
        "",
        f"Command: `{result['command']}`  ",
        f"Machine: {result['machine']}; {result['date']}. {args.frames} frames (seed {args.seed}; the CNN "
        "was trained on seed 0 frames), 160 x 120.",
        "",
        "| detector | IoU left line | IoU right line | IoU both | median frame IoU | lane state = truth's "
        "| within one strip |",
        "|---|---|---|---|---|---|---|",
        *[
            f"| {r['detector']} | {r['iou_left']:.3f} | {r['iou_right']:.3f} | {r['iou_both']:.3f} | "
            f"{r['median_frame_iou']:.3f} | {r['state_agreement']:.1%} | {r['state_within_one']:.1%} |"
            for r in rows
        ],
        "",
    ]
    (RESULTS / "lane_detector_iou.md").write_text("\n".join(lines))
    print("\n".join(lines))


if __name__ == "__main__":
    main()
