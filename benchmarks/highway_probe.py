"""What limits the highway: a hand-written driver that changes lanes, on its 100 fixed evaluation
episodes.

    nice -n 10 env OMP_NUM_THREADS=1 NUMBA_NUM_THREADS=1 \\
        .venv/bin/python benchmarks/highway_probe.py [--episodes 100] [--backends fast]

The target asks for crashes in at most 5 % of the episodes at a mean speed of at least 25 m/s, in
regular traffic whose vehicles drive 21-24 m/s (0.7-0.8 of the 30 m/s limit) on three lanes, all of
them ahead of the ego at the start. The learners trade one for the other (PPO: 10 % at 22.7 m/s,
DQN: 68 % at 28.5 m/s). The driver here learns nothing and reads the world itself (privileged: every
vehicle's position and speed): it follows the vehicle ahead in its lane at a time gap (speed = the
leader's + gain × (gap − standstill − time gap × the leader's speed), capped at 30 m/s, and in some
rows at the speed from which braking at a set deceleration reaches the leader's at the standstill
gap; the ego brakes at 5 m/s² at most), and moves to an adjacent lane when that lane lets it drive
faster and the gaps there are safe (the vehicle behind at least 8 m + 1.5 s of its closing speed
away, the one ahead 12 m + 2 s of the ego's). It steers by pure pursuit of the target lane's centre
25 m ahead, in the velocity's frame (the expert's ``slip_aware`` law), through the ``target_speed``
action (up to 35 m/s). Rows differ in how closely it follows and whether it changes lanes.
highway-env's highway is straight along x with lanes 4 m apart, which the driver's lane arithmetic
assumes.
Writes ``benchmarks/results/highway_probe.{json,md}``.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import drivelab  # noqa: E402
from drivelab.agents.expert import slip_aware_pursuit  # noqa: E402
from drivelab.training.seeds import evaluation_seeds  # noqa: E402
from drivelab.training.stats import bootstrap_ci  # noqa: E402

sys.path.insert(0, str(ROOT / "benchmarks"))
from intersection_probe import header, run_probe, wilson_text  # noqa: E402

ACTION_MAX_MPS = 35.0  # the target_speed action's range
CRUISE_MPS = 30.0  # the lanes' speed limit, where highway-env's speed reward saturates
LANE_M, LANES = 4.0, 3  # highway-env's highway: lanes 4 m apart along y, from y = 0
LENGTH_M = 5.0  # highway-env's vehicles (bumper to bumper = centres − a length)
LOOKAHEAD_M = 25.0
BEHIND_M, BEHIND_S = 8.0, 1.5  # a lane change needs the follower there this far, plus its closing speed
AHEAD_M, AHEAD_S = 12.0, 2.0  # and its leader this far, plus the ego's closing speed
INCENTIVE_MPS = 0.5  # the speed a lane change must gain

# plan: (time gap s, standstill m, gain 1/s, braking cap m/s² (0: none), changes lanes)
PLANS = {
    "keeps its lane, 1.5 s gap": (1.5, 5.0, 0.5, 0.0, False),
    "changes lanes, 0.5 s gap": (0.5, 4.0, 1.0, 0.0, True),
    "changes lanes, 0.4 s gap": (0.4, 3.0, 1.2, 0.0, True),
    "changes lanes, 0.4 s gap, braking cap 3 m/s²": (0.4, 3.0, 1.2, 3.0, True),
    "changes lanes, 0.4 s gap, braking cap 4.5 m/s²": (0.4, 3.0, 1.2, 4.5, True),
}


def _lane(y: float) -> int:
    return int(np.clip(np.round(y / LANE_M), 0, LANES - 1))


def gaps(world, lane: int) -> tuple[tuple[float, float], tuple[float, float]]:
    """((gap, speed) of the nearest vehicle ahead, (gap, speed) of the nearest behind) in ``lane``,
    bumper to bumper; a free side reads (1000 m, the cruise speed) ahead, (1000 m, 0) behind."""
    x = world.ego.position[0]
    vehicles = np.asarray(world.vehicles).reshape(-1, 6)
    in_lane = np.abs(vehicles[:, 1] - LANE_M * lane) < 0.75 * LANE_M  # changing lanes: in both
    dx = vehicles[:, 0] - x
    found = []
    for side, free in ((in_lane & (dx > 0), CRUISE_MPS), (in_lane & (dx <= 0), 0.0)):
        if side.any():
            nearest = np.argmin(np.abs(dx[side]))
            found.append((float(abs(dx[side][nearest]) - LENGTH_M), float(vehicles[side][nearest, 3])))
        else:
            found.append((1000.0, free))
    return found[0], found[1]


def drive(world, plan: tuple) -> np.ndarray:
    """The driver's ``[target speed fraction, steering]`` in ``world`` (module docstring)."""
    time_gap_s, standstill_m, gain, brake_mps2, changes = plan
    y, heading, speed = world.ego.position[1], float(world.ego.heading), float(world.ego.speed_mps)

    def allowed(ahead: tuple[float, float]) -> float:
        gap, leader = ahead
        wanted = leader + gain * (gap - standstill_m - time_gap_s * leader)
        if brake_mps2 > 0:  # no faster than braking at brake_mps2 reaches its speed at standstill_m
            wanted = min(wanted, np.sqrt(leader**2 + 2 * brake_mps2 * max(gap - standstill_m, 0.0)))
        return float(np.clip(wanted, 0.0, CRUISE_MPS))

    def safe(lane: int) -> bool:
        (ahead, leader), (behind, follower) = gaps(world, lane)
        return behind > BEHIND_M + max(0.0, follower - speed) * BEHIND_S and (
            ahead > AHEAD_M + max(0.0, speed - leader) * AHEAD_S
        )

    lane = _lane(y)
    current = allowed(gaps(world, lane)[0])
    target = lane
    if changes and abs(heading) > 0.015:  # mid-change: carry on, back if the new lane turned unsafe
        target = _lane(y + np.sign(heading) * LANE_M * 0.6)
        if target != lane and not safe(target):
            target = lane
    elif changes:
        best = current
        for other in (lane - 1, lane + 1):
            if 0 <= other < LANES and safe(other) and allowed(gaps(world, other)[0]) > best + INCENTIVE_MPS:
                best, target = allowed(gaps(world, other)[0]), other
    speed_wanted = current if target == lane else min(current, allowed(gaps(world, target)[0]))
    # pure pursuit of the target lane's centre LOOKAHEAD_M ahead, in the velocity's frame
    dy = LANE_M * target - y
    ahead_x = LOOKAHEAD_M * np.cos(heading) + dy * np.sin(heading)
    ahead_y = -LOOKAHEAD_M * np.sin(heading) + dy * np.cos(heading)
    steering, _ = slip_aware_pursuit(ahead_x, ahead_y, LENGTH_M)
    return np.array([speed_wanted / ACTION_MAX_MPS, steering], dtype=np.float32)


def play(backend: str, plan: tuple, episodes: int) -> dict:
    """Counts and speeds of one plan over the first ``episodes`` evaluation episodes."""
    env = drivelab.make(
        "highway", obs="kinematics", action="target_speed", traffic="regular", backend=backend,
        action_options={"max_speed_mps": ACTION_MAX_MPS},
    )  # fmt: skip
    crashes, off_road, speeds = 0, 0, []
    for seed in evaluation_seeds(episodes):
        env.reset(seed=int(seed))
        done = False
        while not done:
            _, _, terminated, truncated, info = env.step(drive(env.unwrapped.world, plan))
            done = terminated or truncated
        metrics = info["episode_metrics"]
        crashes += int(metrics["collisions"] > 0)
        off_road += int(metrics["off_road_events"] > 0)
        speeds.append(float(metrics["mean_speed_mps"]))
    low, high = bootstrap_ci(speeds)
    speed = {"mean_speed_mps": float(np.mean(speeds)), "speed_low": float(low), "speed_high": float(high)}
    return {"episodes": episodes, "crash": crashes, "off_road": off_road, **speed}


def markdown(result: dict) -> str:
    lines = [
        *header("Highway: a hand-written driver on the 100 evaluation episodes", result),
        "Privileged (it reads every vehicle's position and speed); target_speed actions up to "
        f"{ACTION_MAX_MPS:.0f} m/s, cruise {CRUISE_MPS:.0f} m/s; regular traffic, 30 s episodes. The "
        "target: crash <= 5 % at a mean speed >= 25 m/s. Crash and off-road in % with their 90 % "
        "Wilson interval; speed: the mean over episodes of each episode's mean speed, with its 90 % "
        "bootstrap interval.",
        "",
        "| plan | backend | crash % | off road % | mean speed m/s |",
        "|---|---|---|---|---|",
    ]
    for row in result["rows"]:
        n = row["episodes"]
        speed = f"{row['mean_speed_mps']:.1f} [{row['speed_low']:.1f}, {row['speed_high']:.1f}]"
        lines.append(
            f"| {row['plan']} | {row['backend']} | {wilson_text(row['crash'], n)} | "
            f"{wilson_text(row['off_road'], n)} | {speed} |"
        )
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    run_probe("highway_probe", __doc__.split("\n\n")[0], PLANS, play, markdown, "fast")
