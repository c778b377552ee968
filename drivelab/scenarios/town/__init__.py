"""The signalised town (the RLAD paper), one folder: its preset (here), its road described as blocks
(``road.py``), its episode set-up (``spawn.py``) and simulator (``simulator.py``) on the compiled
core, and its highway-env reference (``reference_env.py``: road, lights, pedestrians and traffic as
highway-env objects, ``backend="highway"``)."""

from __future__ import annotations

import difflib

from drivelab.errors import UsageError
from drivelab.scenarios.options import Option, timing_options
from drivelab.scenarios.town.spawn import spawn_town
from drivelab.sim.junctions.rules import LightTimings
from drivelab.sim.roads.description import RoadDescription
from drivelab.world.scenario import Scenario

LAYOUT_NAMES = ("train", "test")  # drivelab.scenarios.town.road.LAYOUTS (imported with the town's road)
PHASES = ("green_s", "yellow_s", "all_red_s")  # LightTimings' fields: a cycle's phases per axis


def town_road(config: dict) -> RoadDescription:
    """The town's road for a config: its ``layout`` ("train" by default, as ``TownEnv``'s)."""
    from drivelab.scenarios.town.road import LAYOUTS, road_description

    return road_description(LAYOUTS[config.get("layout", "train")])


def check_light_timings(timings: dict) -> None:
    """``light_timings``: seconds of some of LightTimings' phases (the others keep their
    defaults), green above 0, yellow and all-red at least 0, all finite."""
    for key, value in timings.items():
        if key not in PHASES:
            close = difflib.get_close_matches(str(key), PHASES, n=1)
            hint = f"did you mean {close[0]!r}?" if close else f"its phases: {', '.join(PHASES)}"
            raise UsageError(f"option 'light_timings' has no phase {key!r} ({hint})")
        number = isinstance(value, (int, float)) and not isinstance(value, bool)
        if not number or not 0 <= value < float("inf") or (key == "green_s" and value == 0):
            least = "> 0" if key == "green_s" else ">= 0"
            raise UsageError(f"option 'light_timings' phase {key!r} must be seconds {least}, got {value!r}")


OPTIONS = (
    Option("layout", str, "train", "the town: train (3 x 3 junctions) or test (3 x 2)", choices=LAYOUT_NAMES),
    Option("vehicles_count", int, 15, "town vehicles on random routes", minimum=0, traffic=True),
    Option(
        "pedestrians_count", int, 10, "pedestrians on the pavements and crossings", minimum=0, traffic=True
    ),
    Option(
        "light_timings", dict, dict(vars(LightTimings())),
        "seconds of each light phase per axis (green_s, yellow_s, all_red_s; a phase left out keeps "
        "its default)",
        expected="a mapping of phases to seconds", check=check_light_timings,
    ),
    Option("ego_start_speed", float, 0.0, "the ego's speed at the start, m/s", minimum=0),
    Option(
        "retarget", bool, True,
        "a new random target each time one is reached; false (evaluation): the episode ends on arrival "
        "and its time limit is NoCrash's, the route at 10 km/h plus 10 s",
    ),
    Option("fixed_routes", bool, False, "the 25 NoCrash evaluation routes (one route an episode)"),
    *timing_options(10, 5, 5),
)  # fmt: skip


SCENARIO = Scenario(
    "town",
    "drivelab.scenarios.town.reference_env.TownEnv",
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
    simulator="drivelab.scenarios.town.simulator.TownSimulator",
    camera="map",
    route_deviation_m=3.5,  # NoCrash / Roach episode rules
    blocked_after_s=90.0,
    spawn=spawn_town,
    road=town_road,
    options=OPTIONS,
)
