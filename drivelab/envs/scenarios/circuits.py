"""Seed 004's circuits: the follow-line and follow-lane presets (their roads are described as
blocks, ``roads.blocks.circuit``; their highway-env environments and vehicle are in
``drivelab.envs.backends.circuits``)."""

from __future__ import annotations

from drivelab.envs.backends.roads.blocks import circuit
from drivelab.envs.backends.roads.description import RoadDescription
from drivelab.envs.backends.roads.tracks import FOLLOW_LANE_ROAD, FOLLOW_LINE_ROAD
from drivelab.world.scenario import Scenario

SEED_TABLES = ("seed_line", "seed_lane")  # seed 004's two 5-action (throttle, steering) tables


def _circuit_road(config: dict, defaults: dict, guide_line: bool) -> RoadDescription:
    road = {key: config.get(key, value) for key, value in defaults.items()}
    return circuit(road["track"], road["lanes_count"], road["lane_width"], road["speed_limit"], guide_line)


def follow_line_road(config: dict) -> RoadDescription:
    """The follow-line circuit for a config (``FollowLineEnv``'s defaults), with its guide line."""
    return _circuit_road(config, FOLLOW_LINE_ROAD, guide_line=True)


def follow_lane_road(config: dict) -> RoadDescription:
    """The follow-lane circuit for a config (``FollowLaneEnv``'s defaults)."""
    return _circuit_road(config, FOLLOW_LANE_ROAD, guide_line=False)


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
    road=follow_line_road,
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
    road=follow_lane_road,
)
