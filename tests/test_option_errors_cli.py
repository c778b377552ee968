"""Issue 47: a scenario option misspelled, of the wrong type or range, or contradicting the traffic
level, in a run's YAML or beside ``--traffic``, is one ``error:`` line, exit code 2, and nothing
written (``scenarios/options.py``, checked by ``build_config``)."""

from __future__ import annotations

import pytest

from tests.test_bad_input import assert_refused, train_args

# name → (CLI options after `train`, the run YAML's text, expected part of the error line)
CASES = {
    "blocks misspelled keys": (
        ["--env", "blocks"],
        "env_options: {backend_options: {mapp: OSX, num_scenario: 10, traffic_densty: 0.3}}",
        "scenario 'blocks' has no options 'mapp' (did you mean 'map'?), 'num_scenario' (did you mean "
        "'num_scenarios'?), 'traffic_densty' (did you mean 'traffic_density'?)",
    ),
    "blocks MetaDrive keys": (
        ["--env", "blocks"],
        "env_options: {backend_options: {random_lane_width: true, accident_prob: 0, horizon: 1000}}",
        "scenario 'blocks' has no options 'random_lane_width' (MetaDrive's; lane_width: null",
    ),
    "--traffic empty with a traffic density": (
        ["--env", "blocks", "--traffic", "empty"],
        "env_options: {backend_options: {traffic_density: 0.3}}",
        "option 'traffic_density' (0.3) contradicts traffic 'empty', which sets it to 0.0",
    ),
    "traffic: dense with a vehicle count": (
        [],
        "env: highway\ntraffic: dense\nenv_options: {backend_options: {vehicles_count: 5}}",
        "option 'vehicles_count' (5) contradicts traffic 'dense', which sets it to 35",
    ),
    "highway-env config misspelled": (
        ["--env", "highway"],
        "env_options: {config: {lanse_count: 2}}",
        "scenario 'highway' has no option 'lanse_count' (did you mean 'lanes_count'?)",
    ),
    "highway-env config lanes_count abc": (
        ["--env", "highway"],
        "env_options: {config: {lanes_count: abc}}",
        "option 'lanes_count' of scenario 'highway' must be an integer >= 1, got 'abc'",
    ),
    "highway-env config duration -1": (
        ["--env", "highway"],
        "env_options: {config: {duration: -1}}",
        "duration_s must be a number of seconds > 0, got -1",
    ),
    "town simulation_frequency 0": (
        ["--env", "town"],
        "env_options: {backend_options: {simulation_frequency: 0}}",
        "option 'simulation_frequency' of scenario 'town' must be an integer >= 1, got 0",
    ),
    "town vehicles_count -5": (
        ["--env", "town"],
        "env_options: {backend_options: {vehicles_count: -5}}",
        "option 'vehicles_count' of scenario 'town' must be an integer >= 0, got -5",
    ),
    "highway ego_spacing inf": (
        ["--env", "highway"],
        "env_options: {backend_options: {ego_spacing: .inf}}",
        "option 'ego_spacing' of scenario 'highway' must be a number > 0, got inf",
    ),
    "town layout bogus": (
        ["--env", "town"],
        "env_options: {backend_options: {layout: bogus}}",
        "option 'layout' of scenario 'town' must be one of 'train', 'test', got 'bogus'",
    ),
    "highway policy_frequency 0": (
        ["--env", "highway"],
        "env_options: {backend_options: {policy_frequency: 0}}",
        "option 'policy_frequency' of scenario 'highway' must be an integer >= 1, got 0",
    ),
    "highway lanes_count 0": (
        ["--env", "highway"],
        "env_options: {backend_options: {lanes_count: 0}}",
        "option 'lanes_count' of scenario 'highway' must be an integer >= 1, got 0",
    ),
    "highway duration as a backend option": (
        ["--env", "highway"],
        "env_options: {backend_options: {duration: -1}}",
        "has no option 'duration' (the episode time limit is the env keyword duration_s)",
    ),
    # one per scenario option set
    "merge extra_vehicles -1": (
        ["--env", "merge"],
        "env_options: {backend_options: {extra_vehicles: -1}}",
        "option 'extra_vehicles' of scenario 'merge' must be an integer >= 0, got -1",
    ),
    "roundabout incoming_vehicle_destination 3": (
        ["--env", "roundabout"],
        "env_options: {backend_options: {incoming_vehicle_destination: 3}}",
        "option 'incoming_vehicle_destination' of scenario 'roundabout' must be an integer in [0, 2] or null",
    ),
    "intersection destination": (
        ["--env", "intersection"],
        "env_options: {backend_options: {destination: o2}}",
        "scenario 'intersection' has no option 'destination' (a highway-env setting that drivelab does not "
        "take)",
    ),
    "intersection simulation_frequency 1": (
        ["--env", "intersection"],
        "env_options: {backend_options: {simulation_frequency: 1, policy_frequency: 1}}",
        "option 'simulation_frequency' of scenario 'intersection' must be an integer >= 2, got 1",
    ),
    "racetrack other_vehicle": (
        ["--env", "racetrack"],
        "env_options: {backend_options: {other_vehicle: 2}}",
        "scenario 'racetrack' has no option 'other_vehicle' (did you mean 'other_vehicles'?)",
    ),
    "town light_timings green": (
        ["--env", "town"],
        "env_options: {backend_options: {light_timings: {green: 5}}}",
        "option 'light_timings' has no phase 'green' (did you mean 'green_s'?)",
    ),
    "follow-line lane_width nan": (
        ["--env", "follow-line"],
        "env_options: {backend_options: {lane_width: .nan}}",
        "option 'lane_width' of scenario 'follow-line' must be a number >= 2, got nan",
    ),
    "follow-lane policy_frequency 3": (
        ["--env", "follow-lane"],
        "env_options: {backend_options: {policy_frequency: 3}}",
        "policy_frequency (3) must divide simulation_frequency (10) of scenario 'follow-lane'",
    ),
    "blocks lane_count 9": (
        ["--env", "blocks"],
        "env_options: {backend_options: {lane_count: 9}}",
        "option 'lane_count' of scenario 'blocks' must be an integer in [1, 5] or null, got 9",
    ),
}


@pytest.mark.parametrize("case", list(CASES))
def test_train_refuses_a_bad_scenario_option(work, case):
    args, text, message = CASES[case]
    (work / "run.yaml").write_text(f"algo: ppo\n{text}\n")
    assert_refused(work, train_args(work, "--config", "run.yaml", *args), message)
    assert not (work / "runs").exists()


def test_sweep_checks_every_cells_scenario_options_before_writing(work):
    """The regular cell takes the vehicle count; the dense cell contradicts it: refused first."""
    (work / "sweep.yaml").write_text(
        "base: {algo: ppo, env: highway, steps: 32, env_options: {backend_options: {vehicles_count: 5}}}\n"
        "grid: {traffic: [regular, dense]}\n"
    )
    message = "option 'vehicles_count' (5) contradicts traffic 'dense'"
    assert_refused(work, ["sweep", "sweep.yaml", "--workers", "1", "--runs-dir", "runs"], message)
    assert_refused(work, ["sweep", "sweep.yaml", "--dry-run"], message)
