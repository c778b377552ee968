"""Issue 47: every scenario declares its options; a misspelled key, a bad value or a contradiction
is one UsageError naming the key, from every Python entry point (``scenarios/options.py``)."""

from __future__ import annotations

import gymnasium
import numpy as np
import pytest

import drivelab
from drivelab.config import build_config
from drivelab.envs.vector import VectorDriveEnv
from drivelab.errors import UsageError
from drivelab.scenarios import SCENARIOS, TRAFFIC_LEVELS, options_table
from drivelab.scenarios.options import Option, check_backend_options, declared_config
from drivelab.sim.core.simulator import described_config

INF, NAN = float("inf"), float("nan")


def _must(scenario: str, key: str, expected: str) -> str:
    return f"option {key!r} of scenario {scenario!r} must be {expected}"


# (scenario, DriveEnv keywords, the error's text): the issue's cases, then part 3's
ISSUE_CASES = [
    (
        "highway",
        {"config": {"lanse_count": 2}},
        "scenario 'highway' has no option 'lanse_count' (did you mean 'lanes_count'?)",
    ),
    (
        "blocks",
        {"backend_options": {"random_lane_width": True, "accident_prob": 0, "horizon": 1000}},
        "scenario 'blocks' has no options 'random_lane_width' (MetaDrive's; lane_width: null draws each "
        "map's width), 'accident_prob' (drivelab's maps place no accident obstacles), 'horizon' "
        "(MetaDrive's episode limit: the env keyword duration_s sets it)",
    ),
    (
        "blocks",
        {"backend_options": {"mapp": "OSX", "num_scenario": 10, "traffic_densty": 0.3}},
        "scenario 'blocks' has no options 'mapp' (did you mean 'map'?), 'num_scenario' (did you mean "
        "'num_scenarios'?), 'traffic_densty' (did you mean 'traffic_density'?)",
    ),
    (
        "blocks",
        {"traffic": "empty", "backend_options": {"traffic_density": 0.3}},
        "option 'traffic_density' (0.3) contradicts traffic 'empty', which sets it to 0.0",
    ),
    (
        "town",
        {"backend_options": {"simulation_frequency": 0}},
        _must("town", "simulation_frequency", "an integer >= 1, got 0"),
    ),
    (
        "highway",
        {"backend_options": {"vehicles_count": -5}},
        _must("highway", "vehicles_count", "an integer >= 0, got -5"),
    ),
    (
        "highway",
        {"backend_options": {"ego_spacing": INF}},
        _must("highway", "ego_spacing", "a number > 0, got inf"),
    ),
    (
        "town",
        {"backend_options": {"layout": "bogus"}},
        _must("town", "layout", "one of 'train', 'test', got 'bogus'"),
    ),
    (
        "highway",
        {"backend_options": {"policy_frequency": 0}},
        _must("highway", "policy_frequency", "an integer >= 1, got 0"),
    ),
    (
        "highway",
        {"backend_options": {"lanes_count": 0}},
        _must("highway", "lanes_count", "an integer >= 1, got 0"),
    ),
    (
        "highway",
        {"config": {"lanes_count": "abc"}},
        _must("highway", "lanes_count", "an integer >= 1, got 'abc'"),
    ),
    ("highway", {"config": {"duration": -1}}, "duration_s must be a number of seconds > 0, got -1"),
    (
        "highway",
        {"backend_options": {"duration": -1}},
        "'duration' (the episode time limit is the env keyword duration_s)",
    ),
]


@pytest.mark.parametrize("scenario, kwargs, message", ISSUE_CASES, ids=[str(c[1]) for c in ISSUE_CASES])
def test_the_issues_cases_are_refused_with_one_line(scenario, kwargs, message):
    with pytest.raises(UsageError) as refused:
        drivelab.make(scenario, **kwargs)
    assert message in str(refused.value)
    assert "\n" not in str(refused.value)


def test_every_entry_point_refuses_a_misspelled_option():
    options = {"backend_options": {"vehicle_count": 3}}
    message = "did you mean 'vehicles_count'"
    with pytest.raises(UsageError, match=message):
        gymnasium.make("drivelab/Highway-v0", **options)
    with pytest.raises(UsageError, match=message):
        VectorDriveEnv(2, "highway", **options)
    with pytest.raises(UsageError, match=message):
        drivelab.make("highway", backend="highway", **options)
    with pytest.raises(UsageError, match=message):  # a run's YAML, before anything is written
        build_config({"algo": "ppo", "env": "highway", "env_options": options})
    with pytest.raises(UsageError, match="did you mean 'lanes_count'"):  # a run's highway-env config
        build_config({"algo": "ppo", "env": "highway", "env_options": {"config": {"lane_count": 2}}})


# per scenario: options that are all valid (every declared option, none at its default) and one
# invalid setting with the error's text
VALID = {
    "highway": {"lanes_count": 4, "vehicles_count": 5, "vehicles_density": 2, "ego_spacing": 2.0,
                "initial_lane_id": 1, "simulation_frequency": 10, "policy_frequency": 2},
    "merge": {"keep_npcs": False, "extra_vehicles": 2, "simulation_frequency": 10, "policy_frequency": 2},
    "roundabout": {"incoming_vehicle_destination": 2, "keep_npcs": False, "extra_vehicles": 1,
                   "simulation_frequency": 10, "policy_frequency": 2},
    "intersection": {"initial_vehicle_count": 4, "spawn_probability": 0.3, "keep_npcs": False,
                     "extra_vehicles": 1, "simulation_frequency": 10, "policy_frequency": 2},
    "racetrack": {"other_vehicles": 3, "simulation_frequency": 10, "policy_frequency": 10},
    "town": {"layout": "test", "vehicles_count": 3, "pedestrians_count": 2,
             "light_timings": {"green_s": 8, "all_red_s": 0.0}, "ego_start_speed": 2.0,
             "retarget": False, "fixed_routes": True, "simulation_frequency": 20, "policy_frequency": 10},
    "follow-line": {"lanes_count": 2, "lane_width": 5.0, "speed_limit": 15, "initial_speed": 0,
                    "simulation_frequency": 20, "policy_frequency": 10},
    "follow-lane": {"lanes_count": 2, "lane_width": 4.0, "speed_limit": 25.0, "initial_speed": 3.0,
                    "simulation_frequency": 20, "policy_frequency": 4},
    "blocks": {"map": "SC", "start_seed": 5, "num_scenarios": 2, "lane_count": None, "lane_width": None,
               "signalised": True, "traffic_density": 0.3, "simulation_frequency": 10, "policy_frequency": 5},
}  # fmt: skip
INVALID = {
    "highway": (
        {"initial_lane_id": 2, "lanes_count": 2},
        "'initial_lane_id' (2) of scenario 'highway' must be below lanes_count (2)",
    ),
    "merge": (
        {"extra_vehicles": 1.5},
        "'extra_vehicles' of scenario 'merge' must be an integer >= 0, got 1.5",
    ),
    "roundabout": ({"incoming_vehicle_destination": 3}, "must be an integer in [0, 2] or null, got 3"),
    "intersection": (
        {"spawn_probability": 1.5},
        "'spawn_probability' of scenario 'intersection' must be a number in [0, 1]",
    ),
    "racetrack": ({"speed_limit": 20.0}, "'speed_limit' (a highway-env setting that drivelab does not take)"),
    "town": (
        {"light_timings": {"green": 5}},
        "option 'light_timings' has no phase 'green' (did you mean 'green_s'?)",
    ),
    "follow-line": ({"track": [("straight", 10.0)]}, "scenario 'follow-line' has no option 'track'"),
    "follow-lane": (
        {"lane_width": NAN},
        "'lane_width' of scenario 'follow-lane' must be a number >= 2, got nan",
    ),
    "blocks": ({"map": "OSQ"}, "map 'OSQ': unknown block letter(s) ['Q']"),
}


def _control(name: str) -> str:
    return "meta" if SCENARIOS[name].action_kinds[0] == "meta" else "continuous"


def test_the_tables_cover_every_scenario_and_option():
    assert set(VALID) == set(INVALID) == set(SCENARIOS)
    for name, scenario in SCENARIOS.items():
        assert set(VALID[name]) == {option.name for option in scenario.options}
        defaults = declared_config(scenario, "regular", _control(name))
        assert all(VALID[name][key] != defaults[key] for key in VALID[name]), name


@pytest.mark.parametrize("name", list(SCENARIOS))
def test_each_scenarios_options_are_checked(name):
    check_backend_options(SCENARIOS[name], VALID[name], "regular", _control(name))
    options, message = INVALID[name]
    with pytest.raises(UsageError) as refused:
        check_backend_options(SCENARIOS[name], options, "regular", _control(name))
    assert message in str(refused.value)


@pytest.mark.parametrize("name", ["highway", "merge", "roundabout", "intersection", "racetrack", "town"])
def test_valid_options_reach_the_config_both_backends_build(name):
    """The compiled core and highway-env both take every declared option of the scenario."""
    options = VALID[name]
    for backend in ("fast", "highway"):
        env = drivelab.make(name, obs="kinematics", backend=backend, backend_options=options)
        env.reset(seed=0)
        config = env.simulator._road.config if backend == "fast" else env.backend.env.config
        for key in ("simulation_frequency", "policy_frequency"):
            assert config[key] == options[key]
        assert env.vector.simulator.policy_frequency_hz == options["policy_frequency"]
        env.step(env.action_space.sample())


@pytest.mark.parametrize("name", ["follow-line", "follow-lane", "blocks"])
def test_valid_options_build_the_described_roads(name):
    env = drivelab.make(name, obs="kinematics", action="continuous", backend_options=VALID[name])
    env.reset(seed=0)
    assert env.vector.simulator.policy_frequency_hz == VALID[name]["policy_frequency"]
    env.step(env.action_space.sample())


@pytest.mark.parametrize("name", list(SCENARIOS))
def test_declared_defaults_are_what_the_simulators_assemble(name):
    """For every traffic level and control, each declared option's value equals the config the
    simulators assemble from the scenario's preset and highway-env's defaults."""
    scenario = SCENARIOS[name]
    for level in TRAFFIC_LEVELS:
        for control in ("meta", "continuous"):
            config, keep_npcs, extra_vehicles = described_config(scenario, level, control, None)
            config = {**config, "keep_npcs": keep_npcs, "extra_vehicles": extra_vehicles}
            for key, value in declared_config(scenario, level, control).items():
                assert config[key] == value, (level, control, key)


def test_the_highways_declared_defaults_are_its_simulators():
    env = drivelab.make("highway", obs="kinematics", traffic="dense")
    env.reset(seed=0)
    config = env.simulator._road.config
    declared = declared_config(SCENARIOS["highway"], "dense", "meta")
    assert {key: config[key] for key in declared} == declared
    assert env.simulator.count[0] == 1 + declared["vehicles_count"]


def test_every_declared_default_passes_its_own_check():
    for scenario in SCENARIOS.values():
        names = [option.name for option in scenario.options]
        assert len(names) == len(set(names)), scenario.name
        assert {"simulation_frequency", "policy_frequency"} <= set(names)
        for level in TRAFFIC_LEVELS:
            for control in ("meta", "continuous"):
                check_backend_options(scenario, declared_config(scenario, level, control), level, control)


def test_the_town_declares_its_layouts():
    from drivelab.scenarios.town import LAYOUT_NAMES
    from drivelab.scenarios.town.road import LAYOUTS

    assert LAYOUT_NAMES == tuple(LAYOUTS)


@pytest.mark.parametrize(
    "value, accepted",
    [(3, True), (np.int64(3), True), (0, False), (True, False), (3.0, False), ("3", False), (None, False)],
)
def test_an_integer_option_takes_integers_in_range_only(value, accepted):
    option = Option("count", int, 1, "a count", minimum=1)
    if accepted:
        option.validate(value, "test")
    else:
        with pytest.raises(UsageError, match=r"option 'count' of scenario 'test' must be an integer >= 1"):
            option.validate(value, "test")


@pytest.mark.parametrize(
    "value, accepted",
    [(0.5, True), (1, True), (0.0, False), (-1, False), (INF, False), (NAN, False), (False, False)],
)
def test_a_number_option_takes_finite_numbers_in_range_only(value, accepted):
    option = Option("gap", float, 1.0, "a gap", minimum=0, exclusive_minimum=True)
    if accepted:
        option.validate(value, "test")
    else:
        with pytest.raises(UsageError, match=r"must be a number > 0"):
            option.validate(value, "test")


def test_a_traffic_option_adjusts_the_default_level_only():
    highway = SCENARIOS["highway"]
    check_backend_options(highway, {"vehicles_count": 50}, "regular")
    check_backend_options(highway, {"vehicles_count": 0}, "empty")  # what the level sets anyway
    check_backend_options(highway, {"lanes_count": 5}, "dense")  # not a traffic option
    with pytest.raises(UsageError, match="option 'vehicles_count' \\(50\\) contradicts traffic 'dense'"):
        check_backend_options(highway, {"vehicles_count": 50}, "dense")
    with pytest.raises(UsageError, match="option 'vehicles_density' \\(2\\) contradicts traffic 'empty'"):
        check_backend_options(highway, {"vehicles_density": 2}, "empty")


def test_the_policy_frequency_must_divide_the_simulation_frequency():
    merge = SCENARIOS["merge"]
    check_backend_options(merge, {"policy_frequency": 3}, "regular", "meta")  # 15 / 3
    with pytest.raises(UsageError, match=r"policy_frequency \(5\) must divide simulation_frequency \(12\)"):
        check_backend_options(merge, {"simulation_frequency": 12}, "regular", "continuous")  # 5 Hz
    check_backend_options(merge, {"simulation_frequency": 12}, "regular", "meta")  # 1 Hz
    with pytest.raises(UsageError, match="must be an integer >= 2, got 1"):  # a regulated road
        check_backend_options(SCENARIOS["intersection"], {"simulation_frequency": 1, "policy_frequency": 1})


@pytest.mark.parametrize(
    "key, message",
    [
        ("show_trajectories", "'show_trajectories' (a highway-env setting that drivelab does not take)"),
        ("other_vehicles_type", "(each scenario's traffic model is fixed (IDM/MOBIL))"),
        ("controlled_vehicles", "(drivelab drives one ego vehicle)"),
        ("high_speed_reward", "(drivelab's reward is the env keyword reward)"),
        ("observation", "(observations are the env keyword obs)"),
        ("bogus", "has no option 'bogus'; its options: incoming_vehicle_destination, keep_npcs, "),
    ],
)
def test_what_drivelab_does_not_take_is_refused_and_said(key, message):
    with pytest.raises(UsageError) as refused:
        check_backend_options(SCENARIOS["roundabout"], {key: 1})
    assert message in str(refused.value)


@pytest.mark.parametrize("backend", ["fast", "highway"])
def test_keep_npcs_and_extra_vehicles_given_as_options_take_effect(backend):
    def vehicles(**options) -> int:
        env = drivelab.make("merge", obs="kinematics", backend=backend, backend_options=options)
        env.reset(seed=3)
        return len(env.world.vehicles)

    assert vehicles(keep_npcs=False) == 0
    assert vehicles(keep_npcs=False, extra_vehicles=2) == 2
    assert vehicles(extra_vehicles=2) == vehicles() + 2


def test_options_table_lists_types_ranges_defaults_and_levels():
    rows = {row["name"]: row for row in options_table("drivelab/Blocks-v0")}
    assert rows["traffic_density"] == {
        "name": "traffic_density", "type": "float", "range": "[0, 1]", "default": 0.1,
        "traffic_levels": {"empty": 0.0, "regular": 0.1, "dense": 0.2},
        "doc": "MetaDrive's traffic density: vehicles per 10 m of a block's lanes",
    }  # fmt: skip
    assert rows["lane_count"]["type"] == "int | null" and rows["lane_count"]["range"] == "[1, 5]"
    assert rows["map"]["type"] == "str | int" and rows["map"]["traffic_levels"] == {}
    assert [row["name"] for row in options_table("racetrack")] == [
        "other_vehicles", "simulation_frequency", "policy_frequency",
    ]  # fmt: skip
