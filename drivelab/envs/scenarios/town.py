"""The signalised town (seed 000): its preset. Its road is described as blocks
(``drivelab.envs.town.road_description``); the reference (``backend="highway"``) builds the road,
lights, pedestrians and traffic as highway-env objects (``drivelab.envs.town_env``), the compiled
core sets episodes up with ``drivelab.envs.backends.fast.town_spawn`` and runs them with its town
simulator."""

from __future__ import annotations

from drivelab.envs.backends.fast.town_spawn import spawn_town
from drivelab.envs.backends.roads.description import RoadDescription
from drivelab.world.scenario import Scenario


def town_road(config: dict) -> RoadDescription:
    """The town's road for a config: its ``layout`` ("train" by default, as ``TownEnv``'s)."""
    from drivelab.envs.town import LAYOUTS, road_description

    return road_description(LAYOUTS[config.get("layout", "train")])


SCENARIO = Scenario(
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
    town_traffic=True,
    route_deviation_m=3.5,  # NoCrash / Roach episode rules
    blocked_after_s=90.0,
    spawn=spawn_town,
    road=town_road,
)
