import pytest

from drivelab.config import RunConfig, build_config, check_eval_every
from drivelab.errors import UsageError
from drivelab.yaml_io import load_yaml


def test_build_config_coerces_obs_list():
    config = build_config({"algo": "ppo", "obs": "lidar, topdown", "steps": 100})
    assert config.obs == ("lidar", "topdown")
    assert config.resolved_eval_every == 20 and config.resolved_checkpoint_every == 10


def test_eval_every_may_not_exceed_steps():
    """0 (five over the run) and eval_every == steps (one, at the end) pass; one step more would
    never evaluate."""
    for eval_every in (0, 1, 99, 100):
        check_eval_every(build_config({"algo": "ppo", "steps": 100, "eval_every": eval_every}))
    message = r"^config field 'eval_every' \(101\) is larger than 'steps' \(100\)"
    with pytest.raises(UsageError, match=message):
        check_eval_every(build_config({"algo": "ppo", "steps": 100, "eval_every": 101}))
    for steps in (1, 4, 5, 7, 100):  # what 0 resolves to always runs
        assert 1 <= build_config({"algo": "ppo", "steps": steps}).resolved_eval_every <= steps


def test_sensor_dicts_in_yaml_become_specs():
    config = build_config({"algo": "ppo", "obs": [{"name": "lidar", "beams": 120}, "topdown"]})
    assert config.obs == ("lidar:beams=120", "topdown")


@pytest.mark.parametrize(
    "values, message",
    [
        ({"algo": "ppo", "stepz": 3}, "unknown config field 'stepz'"),
        ({"algo": "ppo", "steps": "many"}, "'steps' must be an integer"),
        ({"algo": "ppo", "steps": 0}, "'steps' must be >= 1"),
        ({"algo": "ppo", "seed": True}, "'seed' must be an integer"),
        ({"algo": "ppo", "steps": 1.5}, "'steps' must be an integer, got 1.5"),
        ({"algo": "ppo", "seed": 10**400}, "'seed' must be an integer, got 1000"),  # beyond a float
        ({"algo": "ppo", "hyperparams": [1]}, "'hyperparams' must be a mapping"),
        ({"env": "highway"}, "no 'algo'"),
    ],
)
def test_bad_config_values_name_the_field(values, message):
    with pytest.raises(UsageError, match=message):
        build_config(values)


def test_malformed_yaml_is_one_line(tmp_path):
    path = tmp_path / "bad.yaml"
    path.write_text("algo: ppo\nsteps: [1, 2\n")
    with pytest.raises(UsageError, match=r"malformed YAML .* at line \d+") as info:
        load_yaml(path)
    assert "\n" not in str(info.value)


def test_yaml_must_be_a_mapping(tmp_path):
    path = tmp_path / "list.yaml"
    path.write_text("- ppo\n")
    with pytest.raises(UsageError, match="mapping"):
        load_yaml(path)


def test_identity_ignores_steps_and_name():
    a = RunConfig(algo="ppo", steps=10, name="a")
    assert a.identity() == RunConfig(algo="ppo", steps=99, name="b").identity()
    assert a.identity() != RunConfig(algo="ppo", seed=1).identity()


def test_action_and_reward_default_to_the_scenario_s():
    from drivelab.config import build_config

    assert (build_config({"algo": "ppo"}).action, build_config({"algo": "ppo"}).reward) == ("meta", "highway")
    line = build_config({"algo": "qlearning", "env": "follow-line", "obs": "line"})
    lane = build_config({"algo": "qlearning", "env": "follow-lane", "obs": "lane"})
    assert (line.action, line.reward) == ("seed_line", "line_follow")
    assert (lane.action, lane.reward) == ("seed_lane", "lane_follow")
    assert build_config({"algo": "ppo", "env": "town"}).reward == "roach"
    given = build_config({"algo": "qlearning", "env": "follow-line", "action": "grid", "reward": "highway"})
    assert (given.action, given.reward) == ("grid", "highway")


def test_town_runs_are_evaluated_without_new_targets():
    config = build_config({"algo": "ppo", "env": "town", "obs": "waypoints", "action": "target_speed"})
    assert "retarget" not in (config.env_kwargs().get("backend_options") or {})  # the town's default
    assert config.eval_env_kwargs()["backend_options"]["retarget"] is False
    highway = build_config({"algo": "ppo", "env": "highway"})
    assert highway.eval_env_kwargs() == highway.env_kwargs()


def test_exponent_numbers_are_numbers_in_yaml_and_on_the_command_line(tmp_path):
    from drivelab.cli import _parse_pairs
    from drivelab.yaml_io import parse_yaml

    path = tmp_path / "run.yaml"
    path.write_text("algo: ppo\nhyperparams: {learning_rate: 1e-3, ent_coef: -2.5E-2, tag: e5, n: 7}\n")
    assert load_yaml(path)["hyperparams"] == {"learning_rate": 1e-3, "ent_coef": -0.025, "tag": "e5", "n": 7}
    assert _parse_pairs(["learning_rate=1e-3", "gamma=0.99", "name=1e"], "-H") == {
        "learning_rate": 0.001, "gamma": 0.99, "name": "1e"
    }  # fmt: skip
    assert parse_yaml("3e2") == 300.0 and isinstance(parse_yaml("12"), int)


def test_a_saved_config_reads_back_as_it_was_even_strings_that_look_like_exponents(tmp_path):
    """The run directory's config.yaml is written for drivelab's loader, which reads 1e5 as a
    number (YAML 1.2): a run named "1e5" or a string hyper-parameter "2e-3" stays a string, and
    the numbers stay numbers, for drivelab's loader and YAML 1.1's (RL Zoo's yaml.safe_load)."""
    import yaml

    from drivelab.config import save_yaml
    from drivelab.yaml_io import dump_yaml, parse_yaml

    config = build_config(
        {"algo": "ppo", "name": "1e5", "steps": 100,
         "hyperparams": {"tag": "2e-3", "learning_rate": 3e-4, "note": "+1E+2", "big": 1e300, "n_steps": 64}}
    )  # fmt: skip
    save_yaml(config, tmp_path / "config.yaml")
    text = (tmp_path / "config.yaml").read_text()
    assert "name: '1e5'" in text and "tag: '2e-3'" in text
    assert build_config(load_yaml(tmp_path / "config.yaml")) == config
    data = {"a": ["1e5", 1e5, ".5e1", 0.5, "-3E-2", "e5", "5e", "yes", 7, "7", float("inf")]}
    assert parse_yaml(dump_yaml(data)) == data and yaml.safe_load(dump_yaml(data)) == data


def test_the_step_budget_is_checked_against_the_rollout_the_model_gets():
    """Without hyper-parameters an SB3 PPO run builds its model from the shipped default entry
    (n_steps 256), and its budget is checked against that rollout, not SB3's own 2048."""
    from drivelab.config import check_steps

    check_steps(build_config({"algo": "ppo", "env": "highway", "steps": 256}))
    with pytest.raises(UsageError, match=r"one rollout of n_steps 256 x n_envs 2 = 512 steps"):
        check_steps(build_config({"algo": "ppo", "env": "highway", "steps": 511, "n_envs": 2}))


def test_an_integral_float_is_an_integer_field():
    """YAML reads ``steps: 1e5`` as a float (``yaml_io``): a whole one is the int, as for -H values."""
    config = build_config({"algo": "ppo", "steps": 1e5, "seed": 3.0})
    assert (config.steps, config.seed) == (100_000, 3)
    assert type(config.steps) is int and type(config.seed) is int
