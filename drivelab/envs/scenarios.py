"""Scenario presets: which highway-env road to build, and how much traffic to put on it."""

from __future__ import annotations

from dataclasses import dataclass, field

from drivelab.errors import UsageError

TRAFFIC_LEVELS = ("empty", "regular", "dense")


@dataclass(frozen=True)
class Scenario:
    """A named driving task.

    :param env_class: dotted path of the highway-env environment class that builds the road.
    :param config: highway-env config shared by every traffic level.
    :param traffic: per traffic level, highway-env config overrides plus the drivelab-only key
        ``extra_vehicles`` (NPCs added on random lanes after highway-env populated the road) and
        ``keep_npcs`` (False removes every NPC highway-env created).
    :param destination: road-network node the ego is routed to (None: follow the road).
    :param arrival: how the backend decides the goal is reached: "none", "merge_end", "exit".
    :param intersection_nodes: road-network nodes whose lanes count as junction area.
    :param meta_target_speeds: the speeds FASTER / SLOWER step through (None: highway-env's
        default 20, 25, 30 m/s), as in highway-env's own config of the scenario.
    :param fast_backend: drivelab's fast backend runs it (the "auto" backend then picks it).
    :param route_deviation_m: the episode fails when the ego is farther than this from its route.
    :param blocked_after_s: the episode fails when the ego stays below 0.1 m/s this long.
    :param default_reward: the reward preset a run gets when it names none.
    :param circuit: the road is a closed loop: the route is one whole lap (however long).
    :param guide_line: a yellow line is painted along the route (follow-line).
    :param keep_lane: leaving the ego's starting lane counts as leaving the road (follow-lane).
    """

    name: str
    env_class: str
    description: str
    config: dict = field(default_factory=dict)
    traffic: dict = field(default_factory=dict)
    destination: str | None = None
    arrival: str = "none"
    intersection_nodes: tuple[str, ...] = ()
    continuous_policy_frequency_hz: int = 5
    meta_target_speeds: tuple[float, ...] | None = None
    fast_backend: bool = True
    route_deviation_m: float | None = None
    blocked_after_s: float | None = None
    action_kinds: tuple[str, ...] = ("meta", "grid", "continuous", "target_speed")
    default_reward: str = "highway"
    circuit: bool = False
    guide_line: bool = False
    keep_lane: bool = False

    def in_junction(self, lane_index: tuple) -> bool:
        """Whether highway-env lane (from, to, id) is junction area: it leaves a junction node
        (on the roundabout, it must also end at one: the exits leave the ring too)."""
        if lane_index[0] not in self.intersection_nodes:
            return False
        return self.name != "roundabout" or lane_index[1] in self.intersection_nodes


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
            intersection_nodes=("ir0", "ir1", "ir2", "ir3"),
            meta_target_speeds=(0, 4.5, 9),
        ),
        Scenario(
            "racetrack",
            "highway_env.envs.racetrack_env.RacetrackEnv",
            "two-lane closed circuit with tight curves",
            config={"duration": 60},
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


def get_scenario(name: str) -> Scenario:
    """The scenario called ``name``, or a UsageError listing the known ones."""
    if name not in SCENARIOS:
        raise UsageError(f"unknown scenario {name!r} (choose from {', '.join(SCENARIOS)})")
    return SCENARIOS[name]


def check_traffic(level: str) -> str:
    if level not in TRAFFIC_LEVELS:
        raise UsageError(f"unknown traffic level {level!r} (choose from {', '.join(TRAFFIC_LEVELS)})")
    return level
