"""Scenarios: one module per scenario holds its preset (which road, how much traffic, its rules)
and, for the compiled core, its hooks (``Scenario.spawn`` / ``spawn_many``: the episode
set-up; ``Scenario.arrivals``: vehicles arriving between steps). The simulators read a Scenario
handed to them; nothing below this package looks a scenario up by name."""

from __future__ import annotations

from drivelab.errors import UsageError
from drivelab.scenarios import blocks, circuits, highway, intersection, merge, racetrack, roundabout, town
from drivelab.scenarios.circuits import SEED_TABLES
from drivelab.scenarios.options import TRAFFIC_LEVELS, check_traffic, option_rows
from drivelab.world.scenario import Scenario

SCENARIOS: dict[str, Scenario] = {
    s.name: s
    for s in (
        highway.SCENARIO,
        merge.SCENARIO,
        roundabout.SCENARIO,
        intersection.SCENARIO,
        racetrack.SCENARIO,
        town.SCENARIO,
        circuits.FOLLOW_LINE,
        circuits.FOLLOW_LANE,
        blocks.SCENARIO,
    )
}

__all__ = [
    "SCENARIOS", "FAST_SCENARIOS", "REFERENCE_SCENARIOS", "SEED_TABLES", "TRAFFIC_LEVELS", "check_traffic",
    "get_scenario", "gym_id", "options_table", "scenario_name",
]  # fmt: skip


FAST_SCENARIOS = tuple(name for name, s in SCENARIOS.items() if s.fast_backend)  # the compiled core's
REFERENCE_SCENARIOS = tuple(name for name, s in SCENARIOS.items() if s.reference_backend)  # highway-env's


def gym_id(scenario: str) -> str:
    """``"highway"`` → ``"drivelab/Highway-v0"``, ``"follow-line"`` → ``"drivelab/FollowLine-v0"``."""
    return f"drivelab/{''.join(part.capitalize() for part in scenario.split('-'))}-v0"


SCENARIO_OF_ID = {gym_id(name): name for name in SCENARIOS}


def scenario_name(name: str) -> str:
    """A scenario's name from its name or its gymnasium id (``drivelab/Highway-v0``); other
    strings are returned as they are (``get_scenario`` reports them)."""
    return SCENARIO_OF_ID.get(name, name)


def get_scenario(name: str) -> Scenario:
    """The scenario called ``name`` (or registered as the gymnasium id ``name``), or a UsageError
    listing the known ones."""
    name = scenario_name(name)
    if name not in SCENARIOS:
        raise UsageError(f"unknown scenario {name!r} (choose from {', '.join(SCENARIOS)})")
    return SCENARIOS[name]


def options_table(name: str) -> list[dict]:
    """The options of scenario ``name`` (or its gymnasium id) as rows for a table: name, type,
    range, default, the traffic levels' values and what it does (``options.option_rows``)."""
    return option_rows(get_scenario(name))
