"""The CARLA study's circuits: the follow-line and follow-lane presets (their roads are described as
blocks, ``roads.blocks.circuit``; their reference environments and vehicle are highway-env
classes in ``drivelab.scenarios.circuits.reference_env``) and their compiled-core set-up."""

from __future__ import annotations

import numpy as np
from gymnasium.utils import seeding

from drivelab.scenarios.circuits.tracks import FOLLOW_LANE_ROAD, FOLLOW_LINE_ROAD
from drivelab.scenarios.options import Option, timing_options
from drivelab.sim.core import traffic as T
from drivelab.sim.core.spawn import finish, make_on_lane, random_lane_index
from drivelab.sim.roads.blocks import circuit
from drivelab.sim.roads.description import RoadDescription
from drivelab.world.scenario import Scenario

SEED_TABLES = ("seed_line", "seed_lane")  # the CARLA study's two 5-action (throttle, steering) tables


def spawn_circuit(seed: int, road, control: str) -> tuple[np.ndarray, int, np.ndarray, None]:
    """CircuitEnv._reset as a row: the pedal ego on a random lane (``random_lane_index``'s
    draws), a uniform distance along it, at the configured initial speed; no traffic."""
    if control != "continuous":
        raise NotImplementedError("the circuits' pedal ego takes continuous controls")
    rng, _ = seeding.np_random(int(seed))
    lane = random_lane_index(road, rng)
    longitudinal = float(rng.uniform(0, road.geometry.length(lane)))
    ego = make_on_lane(road, lane, longitudinal, float(road.config["initial_speed"]), T.PEDAL_KIND)
    return finish(road, [ego]), 0, np.zeros(2), None


def _circuit_road(config: dict, defaults: dict, guide_line: bool) -> RoadDescription:
    road = {key: config.get(key, value) for key, value in defaults.items()}
    return circuit(road["track"], road["lanes_count"], road["lane_width"], road["speed_limit"], guide_line)


def follow_line_road(config: dict) -> RoadDescription:
    """The follow-line circuit for a config (``FollowLineEnv``'s defaults), with its guide line."""
    return _circuit_road(config, FOLLOW_LINE_ROAD, guide_line=True)


def follow_lane_road(config: dict) -> RoadDescription:
    """The follow-lane circuit for a config (``FollowLaneEnv``'s defaults)."""
    return _circuit_road(config, FOLLOW_LANE_ROAD, guide_line=False)


def circuit_options(road: dict) -> tuple[Option, ...]:
    """A circuit's options, defaults from its environment's road config (``tracks``); its track
    is the CARLA study's (a track must close exactly: it is not an option)."""
    return (
        Option("lanes_count", int, road["lanes_count"], "parallel lanes around the circuit", minimum=1),
        Option("lane_width", float, road["lane_width"], "lane width, m", minimum=2),
        Option(
            "speed_limit", float, road["speed_limit"], "the lanes' speed limit, m/s",
            minimum=0, exclusive_minimum=True,
        ),
        Option("initial_speed", float, 5.0, "the ego's speed at the start, m/s", minimum=0),
        *timing_options(10, 5, 5),
    )  # fmt: skip


FOLLOW_LINE = Scenario(
    "follow-line",
    "drivelab.scenarios.circuits.reference_env.FollowLineEnv",
    "the CARLA study: 467 m circuit, one 7 m lane with a yellow centre line, curves both ways, no traffic",
    config={"duration": 60},
    traffic={"empty": {}, "regular": {}, "dense": {}},  # no traffic on this task
    action_kinds=SEED_TABLES + ("grid", "continuous"),
    default_reward="line_follow",
    circuit=True,
    guide_line=True,
    spawn=spawn_circuit,
    road=follow_line_road,
    options=circuit_options(FOLLOW_LINE_ROAD),
)

FOLLOW_LANE = Scenario(
    "follow-lane",
    "drivelab.scenarios.circuits.reference_env.FollowLaneEnv",
    "the CARLA study: 1.9 km three-lane circuit, curves both ways, no traffic; leaving the lane ends it",
    config={"duration": 60},
    traffic={"empty": {}, "regular": {}, "dense": {}},
    action_kinds=SEED_TABLES[::-1] + ("grid", "continuous"),
    default_reward="lane_follow",
    circuit=True,
    keep_lane=True,
    spawn=spawn_circuit,
    road=follow_lane_road,
    options=circuit_options(FOLLOW_LANE_ROAD),
)
