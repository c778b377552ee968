"""Seed 004's circuits: the follow-line and follow-lane presets (their roads and vehicle are
highway-env classes in ``drivelab.envs.backends.circuits``)."""

from __future__ import annotations

from drivelab.world.scenario import Scenario

SEED_TABLES = ("seed_line", "seed_lane")  # seed 004's two 5-action (throttle, steering) tables

FOLLOW_LINE = Scenario(
    "follow-line",
    "drivelab.envs.backends.circuits.FollowLineEnv",
    "seed 004: 467 m circuit, one 7 m lane with a yellow centre line, curves both ways, no traffic",
    config={"duration": 60},
    traffic={"empty": {}, "regular": {}, "dense": {}},  # no traffic on this task
    action_kinds=SEED_TABLES + ("grid", "continuous"),
    default_reward="line_follow",
    circuit=True,
    guide_line=True,
    fast_backend=False,  # the guide line and the drag of seed 004's ego are highway-backend only
)

FOLLOW_LANE = Scenario(
    "follow-lane",
    "drivelab.envs.backends.circuits.FollowLaneEnv",
    "seed 004: 1.9 km three-lane circuit, curves both ways, no traffic; leaving the lane ends it",
    config={"duration": 60},
    traffic={"empty": {}, "regular": {}, "dense": {}},
    action_kinds=SEED_TABLES[::-1] + ("grid", "continuous"),
    default_reward="lane_follow",
    circuit=True,
    keep_lane=True,
    fast_backend=False,
)
