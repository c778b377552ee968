"""A scenario's options, declared as MetaDrive declares its config: each key a user may set
(``backend_options=``, a highway-env ``config=`` dict's road and traffic keys, a run's
``env_options: {backend_options: …}``) with its type, range, default and meaning.

``check_backend_options`` (called by ``VectorDriveEnv`` and ``build_config``) refuses, as one-line
UsageErrors: a key the scenario does not declare (naming the nearest declared one); a value of the
wrong type or out of range; settings that contradict each other (a traffic option with an explicit
``empty`` or ``dense`` level that sets it otherwise, a policy frequency that does not divide the
simulation frequency, the scenario's own ``Scenario.check_options``). ``option_rows`` lists the
declarations for the documentation's tables.
"""

from __future__ import annotations

import difflib
from typing import TYPE_CHECKING, Any

from drivelab.errors import UsageError
from drivelab.world.options import Option

if TYPE_CHECKING:
    from drivelab.world.scenario import Scenario

DEFAULT_TRAFFIC = "regular"  # the level the traffic options adjust
TRAFFIC_LEVELS = ("empty", "regular", "dense")
# keys a user may know from highway-env or MetaDrive that drivelab takes elsewhere or not at all:
# key → (the option the hint needs the scenario to declare, or None; the hint)
HINTS = {
    "duration": (None, "the episode time limit is the env keyword duration_s"),
    "horizon": (None, "MetaDrive's episode limit: the env keyword duration_s sets it"),
    "offroad_terminal": (None, "it is the env keyword offroad_terminal"),
    "observation": (None, "observations are the env keyword obs"),
    "action": (None, "the action kind is the env keyword action"),
    "traffic": (None, "the traffic level is the env keyword traffic"),
    "controlled_vehicles": (None, "drivelab drives one ego vehicle"),
    "other_vehicles_type": (None, "each scenario's traffic model is fixed (IDM/MOBIL)"),
    "random_lane_width": ("lane_width", "MetaDrive's; lane_width: null draws each map's width"),
    "random_lane_num": ("lane_count", "MetaDrive's; lane_count: null draws each map's lane count"),
    "lane_num": ("lane_count", "MetaDrive's lane_num is lane_count here"),
    "accident_prob": (None, "drivelab's maps place no accident obstacles"),
}


def timing_options(
    simulation_hz: int, policy_hz: int, continuous_policy_hz: int, minimum_simulation_hz: int = 1
) -> tuple[Option, Option]:
    """``simulation_frequency`` and ``policy_frequency``, highway-env's timing keys, which every
    scenario reads. ``policy_hz`` is the config's (meta-actions'); continuous controls decide at
    ``continuous_policy_hz`` (``Scenario.continuous_policy_frequency_hz``) unless the key is
    given. ``minimum_simulation_hz``: 2 where a regulated road enforces its right of way twice a
    second (highway-env's ``RegulatedRoad``: every ``simulation_frequency // 2`` frames)."""
    policy_doc = "decisions per second (policy steps); it must divide simulation_frequency"
    if continuous_policy_hz != policy_hz:
        policy_doc += f"; {continuous_policy_hz} with continuous controls unless given"
    return (
        Option(
            "simulation_frequency", int, simulation_hz,
            "simulation frames per second (each policy step runs simulation / policy frequency frames)",
            minimum=minimum_simulation_hz,
        ),
        Option("policy_frequency", int, policy_hz, policy_doc, minimum=1),
    )  # fmt: skip


def arranged_traffic_options() -> tuple[Option, Option]:
    """``keep_npcs`` and ``extra_vehicles``, drivelab's keys for the traffic levels of scenarios
    whose traffic highway-env places (``HighwayBackend.arrange_traffic``, ``spawn.arrange_traffic``)."""
    return (
        Option(
            "keep_npcs", bool, True,
            "keep the vehicles the scenario places (false: none of them, extra_vehicles still come)",
            traffic=True,
        ),
        Option(
            "extra_vehicles", int, 0,
            "vehicles added on random lanes after the scenario's own, at least 15 m from any other",
            minimum=0, traffic=True,
        ),
    )  # fmt: skip


def check_traffic(level: str) -> str:
    """``level`` if it is a traffic level, else a UsageError listing them."""
    if level not in TRAFFIC_LEVELS:
        raise UsageError(f"unknown traffic level {level!r} (choose from {', '.join(TRAFFIC_LEVELS)})")
    return level


def declared_config(scenario: Scenario, traffic: str, control: str) -> dict:
    """Every declared option's value for a traffic level and a control kind ("meta" or
    "continuous"), layered as ``HighwayBackend.assemble_config`` layers the config: the
    defaults, the level's values, the continuous controls' policy frequency."""
    values = {option.name: option.default for option in scenario.options}
    values.update({key: value for key, value in scenario.traffic.get(traffic, {}).items() if key in values})
    if control == "continuous" and "policy_frequency" in values:
        values["policy_frequency"] = scenario.continuous_policy_frequency_hz
    return values


def check_backend_options(
    scenario: Scenario, options: dict | None, traffic: str = DEFAULT_TRAFFIC, control: str = "meta"
) -> None:
    """``options`` (a user's config keys for ``scenario``) checked, as one-line UsageErrors:
    unknown keys, values of the wrong type or range, contradictions (see the module docstring).

    :param traffic: the traffic level the options are given with.
    :param control: "meta" or "continuous", the action kind's control (the default policy
        frequency depends on it).
    """
    if not options:
        return
    if not isinstance(options, dict):
        raise UsageError(f"backend_options must be a mapping of options, got {options!r}")
    declared = {option.name: option for option in scenario.options}
    unknown = [key for key in options if key not in declared]
    if unknown:
        raise UsageError(unknown_options_message(scenario, unknown))
    for key, value in options.items():
        declared[key].validate(value, scenario.name)
    level = declared_config(scenario, check_traffic(traffic), control)
    if traffic != DEFAULT_TRAFFIC:
        for key, value in options.items():
            if declared[key].traffic and value != level[key]:
                raise UsageError(
                    f"option {key!r} ({value!r}) contradicts traffic {traffic!r}, which sets it to "
                    f"{level[key]!r}: give the option with the default traffic {DEFAULT_TRAFFIC!r} "
                    f"(the level the traffic options adjust), or traffic {traffic!r} without it"
                )
    merged = {**level, **options}
    simulation, policy = merged.get("simulation_frequency"), merged.get("policy_frequency")
    if simulation is not None and policy is not None and simulation % policy != 0:
        raise UsageError(
            f"policy_frequency ({policy}) must divide simulation_frequency ({simulation}) of scenario "
            f"{scenario.name!r}: each policy step runs a whole number of simulation frames"
        )
    if scenario.check_options is not None:
        scenario.check_options(merged)


def unknown_options_message(scenario: Scenario, unknown: list[str]) -> str:
    """One line: each unknown key with the nearest declared one, or a hint, or the known keys."""
    names = [option.name for option in scenario.options]
    parts, listed = [], False
    for key in unknown:
        text = repr(key)
        needs, hint = HINTS.get(str(key), ("", ""))
        close = difflib.get_close_matches(str(key), names, n=1)
        if hint and (needs is None or needs in names):
            text += f" ({hint})"
        elif "reward" in str(key):
            text += " (drivelab's reward is the env keyword reward)"
        elif str(key) in _highway_env_keys(scenario):
            text += " (a highway-env setting that drivelab does not take)"
        elif close:
            text += f" (did you mean {close[0]!r}?)"
        else:
            listed = True
        parts.append(text)
    noun = "option" if len(unknown) == 1 else "options"
    message = f"scenario {scenario.name!r} has no {noun} {', '.join(parts)}"
    if listed:
        message += f"; its options: {', '.join(names)}"
    return message


def _highway_env_keys(scenario: Scenario) -> set[str]:
    """The keys of the highway-env config of the scenario's environment class (imported now:
    only an error message asks)."""
    from highway_env import utils

    return set(utils.class_from_path(scenario.env_class).default_config())


def option_rows(scenario: Scenario) -> list[dict[str, Any]]:
    """The scenario's options as table rows for the docs: name, type, range, default, the
    traffic levels' values (traffic options; else empty), doc."""
    levels = {level: declared_config(scenario, level, "meta") for level in TRAFFIC_LEVELS}
    return [
        {
            "name": option.name,
            "type": option.type_name,
            "range": option.range_text,
            "default": option.default,
            "traffic_levels": {level: levels[level][option.name] for level in levels if option.traffic},
            "doc": option.doc,
        }
        for option in scenario.options
    ]
