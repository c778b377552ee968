"""What limits the racetrack: a hand-written lane keeper on its 100 fixed evaluation episodes.

    nice -n 10 env OMP_NUM_THREADS=1 NUMBA_NUM_THREADS=1 \\
        .venv/bin/python benchmarks/racetrack_probe.py [--episodes 100] [--backends fast,highway]

The learners on the racetrack (SB3 PPO, tuned PPO, SAC) end about half their episodes in the one
other car, a slower vehicle (6-9 m/s) put on the first curve ahead of the ego. The controller here
learns nothing: it steers with highway-env's own lane-following law (the one its IDM vehicles use:
a lateral-offset loop feeding a heading loop, plus the lane's curvature ahead) on the 10-number ego
state the learners read, holds a cruise speed, and brakes to keep a time gap behind a vehicle ahead;
it never changes lanes. Rows differ in what it keeps the gap to: nothing, the ego state's front
vehicle (the nearest one within half a lane width of the ego's straight line of travel), or the
nearest one along the lane's arc (privileged: read from the world's vehicle rows). Success is the
leaderboard's (the whole 60 s episode without a collision or leaving the road); "≥ 1 lap clean"
adds at least 382 m driven, the outer lane's lap (the inner lane's is 348 m). Writes
``benchmarks/results/racetrack_probe.{json,md}``.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import drivelab  # noqa: E402
from drivelab.perception.ego_state import CURVATURE_SCALE_M, MAX_ACCELERATION_MPS2  # noqa: E402
from drivelab.training.seeds import evaluation_seeds  # noqa: E402
from drivelab.world.geometry import FULL_LOCK_RAD  # noqa: E402

sys.path.insert(0, str(ROOT / "benchmarks"))
from intersection_probe import header, run_probe, wilson_text  # noqa: E402

LAP_M = 382.0  # the outer lane's lap (highway-env's racetrack; the inner lane's: 348 m)
LANE_WIDTH_M = 5.0  # the racetrack's lanes
VEHICLE_LENGTH_M = 5.0  # highway-env's Vehicle.LENGTH
TAU_LATERAL_S, TAU_HEADING_S = 0.6, 0.2  # highway-env's ControlledVehicle gains
TAU_PURSUIT_S = 0.5 * TAU_HEADING_S
TIME_GAP_S, STANDSTILL_M = 1.5, 10.0  # gap keeping: wanted gap = standstill + speed x time gap
# plan: (cruise speed m/s, what it keeps a gap to: nothing, the ego state's front vehicle, or the
# nearest vehicle along the lane's arc)
PLANS = {
    "cruise 10 m/s, no gap keeping": (10.0, "nothing"),
    "cruise 10 m/s, gap to the ego state's front vehicle": (10.0, "ego state"),
    **{f"cruise {v} m/s, gap along the lane's arc": (float(v), "lane arc") for v in (6, 8, 10, 12, 15)},
}


def ego_state_gap(obs: np.ndarray, max_speed_mps: float) -> tuple[float, float]:
    """The gap (m) and speed (m/s) of the vehicle ahead as the ego state reports them: along the
    ego's straight line of travel, within half a lane width of it; (inf, 0) when none."""
    if obs[2] >= 1.0:
        return np.inf, 0.0
    speed = obs[0] * max_speed_mps
    return float(obs[2] * 50.0), float(speed + obs[3] * max_speed_mps)


def path_gap(world) -> tuple[float, float]:
    """The same along the lane's arc instead of a straight line (privileged: from the world's
    vehicle rows): the nearest vehicle within half a lane width of the circle the lane curves on."""
    ego, best = world.ego, (np.inf, 0.0)
    kappa = float(ego.lane_curvature)
    cos, sin = np.cos(ego.heading), np.sin(ego.heading)
    for x, y, heading, speed, *_ in np.asarray(world.vehicles):
        dx, dy = x - ego.position[0], y - ego.position[1]
        ahead, left = dx * cos + dy * sin, -dx * sin + dy * cos
        if abs(kappa) < 1e-3:
            off, along = abs(left), ahead
        else:
            radius = 1.0 / kappa  # signed: the circle's centre at (0, radius) in the ego frame
            off = abs(abs(radius) - np.hypot(ahead, left - radius))
            along = abs(radius) * np.arctan2(ahead, np.sign(radius) * (radius - left))
        if 0 < along < best[0] and off < ego.lane_width_m / 2:
            best = (float(along), float(speed * np.cos(heading - ego.heading)))
    return best


def lane_keeper(
    obs: np.ndarray, speed_mps: float, cruise_mps: float, front: tuple[float, float] | None
) -> np.ndarray:
    """``[steering, acceleration]`` in [-1, 1]: highway-env's lane-following law on one 10-number
    ego state (``drivelab.perception.ego_state``: offset + right over half the lane width, heading
    error's sine, curvature x 50 m), a cruise speed, and a time gap kept behind ``front`` (gap m,
    speed m/s; None: no gap keeping)."""
    offset_m = obs[1] * LANE_WIDTH_M / 2
    heading_error = float(np.arcsin(np.clip(obs[5], -1.0, 1.0)))
    curvature = obs[8] / CURVATURE_SCALE_M
    speed = max(speed_mps, 1.0)
    # highway-env's ControlledVehicle.steering_control on the lane's offset and heading error
    lateral_command = -offset_m / TAU_LATERAL_S
    heading_command = float(np.arcsin(np.clip(lateral_command / speed, -1.0, 1.0)))
    heading_ref = curvature * speed * TAU_PURSUIT_S + np.clip(heading_command, -np.pi / 4, np.pi / 4)
    rate = (heading_ref - heading_error) / TAU_HEADING_S
    slip = np.arcsin(np.clip(VEHICLE_LENGTH_M / 2 / speed * rate, -1.0, 1.0))
    steering = float(np.arctan(2 * np.tan(slip))) / FULL_LOCK_RAD
    acceleration = cruise_mps - speed_mps  # 1 m/s² per m/s of error
    if front is not None and np.isfinite(front[0]):
        gap_m, closing = front[0], speed_mps - front[1]  # closing > 0: catching up
        wanted = STANDSTILL_M + speed_mps * TIME_GAP_S
        acceleration = min(acceleration, 0.5 * (gap_m - wanted) - closing)
    return np.array([steering, acceleration / MAX_ACCELERATION_MPS2], dtype=np.float32).clip(-1, 1)


def play(backend: str, plan: tuple[float, str], episodes: int) -> dict:
    """Counts of one plan (cruise speed, what it keeps a gap to) over the first ``episodes``
    evaluation episodes."""
    cruise_mps, sees = plan
    env = drivelab.make(
        "racetrack", obs="ego_state:features=10", action="continuous", traffic="regular", backend=backend
    )
    counts = {"episodes": episodes, "success": 0, "crash": 0, "off_road": 0, "lap": 0}
    distances = []
    for seed in evaluation_seeds(episodes):
        obs, info = env.reset(seed=int(seed))
        world = env.unwrapped.world
        speed, done = float(world.ego.speed_mps), False
        while not done:
            front = {
                "nothing": None,
                "ego state": ego_state_gap(obs, world.max_speed_mps),
                "lane arc": path_gap(world),
            }[sees]
            obs, _, terminated, truncated, info = env.step(lane_keeper(obs, speed, cruise_mps, front))
            world = env.unwrapped.world
            speed, done = float(world.ego.speed_mps), terminated or truncated
        metrics = info["episode_metrics"]
        distance_m = 1000.0 * metrics["distance_km"]
        counts["success"] += int(metrics["success"] > 0)
        counts["crash"] += int(metrics["collisions"] > 0)
        counts["off_road"] += int(metrics["off_road_events"] > 0)
        counts["lap"] += int(metrics["success"] > 0 and distance_m >= LAP_M)
        distances.append(distance_m)
    return {**counts, "mean_distance_m": float(np.mean(distances))}


def markdown(result: dict) -> str:
    lines = [
        *header("Racetrack: a hand-written lane keeper on the 100 evaluation episodes", result),
        "Observation: the 10-number ego state the learners read; continuous [steering, acceleration];",
        "regular traffic (one other vehicle); 60 s episodes. Rates in %, with their 90 % Wilson interval.",
        f'"≥ 1 lap clean": success and at least {LAP_M:.0f} m driven.',
        "",
        "| plan | backend | success % | ≥ 1 lap clean % | crash % | off road % | mean distance m |",
        "|---|---|---|---|---|---|---|",
    ]
    for row in result["rows"]:
        n = row["episodes"]
        rates = " | ".join(wilson_text(row[key], n) for key in ("success", "lap", "crash", "off_road"))
        lines.append(f"| {row['plan']} | {row['backend']} | {rates} | {row['mean_distance_m']:.0f} |")
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    run_probe("racetrack_probe", __doc__.split("\n\n")[0], PLANS, play, markdown, "fast")
