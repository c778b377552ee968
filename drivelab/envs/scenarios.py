"""Scenario presets: which highway-env road to build, and how much traffic to put on it."""

from __future__ import annotations

from drivelab.errors import UsageError
from drivelab.world.scenario import Scenario

TRAFFIC_LEVELS = ("empty", "regular", "dense")


SEED_TABLES = ("seed_line", "seed_lane")  # seed 004's two 5-action (throttle, steering) tables
_RING = ("se", "ex", "ee", "nx", "ne", "wx", "we", "sx")

SCENARIOS: dict[str, Scenario] = {
    s.name: s
    for s in [
        Scenario(
            "highway",
            "highway_env.envs.highway_env.HighwayEnvFast",
            "3-lane straight highway, 30 s (highway-env's highway-fast settings)",
            config={"lanes_count": 3, "duration": 30},
            traffic={
                "empty": {"vehicles_count": 0},
                "regular": {"vehicles_count": 20},
                "dense": {"vehicles_count": 35, "vehicles_density": 1.5},
            },
        ),
        Scenario(
            "merge",
            "highway_env.envs.merge_env.MergeEnv",
            "highway with an on-ramp merging in; ends after the merge (x > 370 m)",
            config={"duration": 40},
            traffic={
                "empty": {"keep_npcs": False},
                "regular": {},
                "dense": {"extra_vehicles": 6},
            },
            arrival="merge_end",
            arrival_x_m=370.0,
        ),
        Scenario(
            "roundabout",
            "highway_env.envs.roundabout_env.RoundaboutEnv",
            "two-lane roundabout, enter from the south and leave to the north",
            config={"duration": 11},
            traffic={
                "empty": {"keep_npcs": False},
                "regular": {},
                "dense": {"extra_vehicles": 5},
            },
            destination="nxs",
            intersection_nodes=_RING,
            meta_target_speeds=(0, 8, 16),
        ),
        Scenario(
            "intersection",
            "highway_env.envs.intersection_env.IntersectionEnv",
            "unsignalised 4-way crossing, turn left to exit o1",
            config={"duration": 13, "destination": "o1"},
            traffic={
                "empty": {"keep_npcs": False, "initial_vehicle_count": 0, "spawn_probability": 0.0},
                "regular": {"initial_vehicle_count": 10, "spawn_probability": 0.6},
                "dense": {"initial_vehicle_count": 15, "spawn_probability": 0.9},
            },
            destination="o1",
            arrival="exit",
            traffic_flow=True,
            intersection_nodes=("ir0", "ir1", "ir2", "ir3"),
            meta_target_speeds=(0, 4.5, 9),
        ),
        Scenario(
            "racetrack",
            "highway_env.envs.racetrack_env.RacetrackEnv",
            "two-lane closed circuit with tight curves",
            # highway-env's own observation off: off-road is judged by drivelab, not highway-env
            config={"duration": 60, "observation": {"type": "Kinematics"}},
            traffic={
                "empty": {"other_vehicles": 0},
                "regular": {"other_vehicles": 1},
                "dense": {"other_vehicles": 5},
            },
            action_kinds=("grid", "continuous", "target_speed"),  # highway-env's racetrack: no meta-actions
        ),
        Scenario(
            "town",
            "drivelab.envs.town_env.TownEnv",
            "signalised town (train layout; layout=test for the test town): lights, pedestrians, routes",
            config={"duration": 60, "retarget": True},  # training: a new target on arrival (NoCrash: off)
            traffic={
                "empty": {"vehicles_count": 0, "pedestrians_count": 0},
                "regular": {"vehicles_count": 15, "pedestrians_count": 10},
                "dense": {"vehicles_count": 30, "pedestrians_count": 20},
            },
            arrival="route_end",
            default_reward="roach",
            intersection_nodes=tuple(f"J{j}:ir{k}" for j in range(9) for k in range(4)),
            meta_target_speeds=(0, 4.5, 9),
            fast_backend=False,  # its vehicles stop for lights: not in the compiled kernels yet
            route_deviation_m=3.5,  # NoCrash / Roach episode rules
            blocked_after_s=90.0,
        ),
        Scenario(
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
        ),
        Scenario(
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
        ),
    ]
}


FAST_SCENARIOS = tuple(
    name for name, scenario in SCENARIOS.items() if scenario.fast_backend
)  # the compiled core's


def get_scenario(name: str) -> Scenario:
    """The scenario called ``name``, or a UsageError listing the known ones."""
    if name not in SCENARIOS:
        raise UsageError(f"unknown scenario {name!r} (choose from {', '.join(SCENARIOS)})")
    return SCENARIOS[name]


def check_traffic(level: str) -> str:
    if level not in TRAFFIC_LEVELS:
        raise UsageError(f"unknown traffic level {level!r} (choose from {', '.join(TRAFFIC_LEVELS)})")
    return level
