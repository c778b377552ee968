"""Shipped hyper-parameter files: lookup by scenario, overrides, and what a new run records."""

import copy
from importlib import resources

import pytest
import yaml
from typer.testing import CliRunner

from drivelab.agents.registry import ALGORITHMS
from drivelab.cli import app
from drivelab.hyperparams import resolve_hyperparams, shipped_hyperparams, with_shipped_hyperparams


def test_scenario_entry_default_and_overrides():
    assert shipped_hyperparams("a2c", "racetrack")["gamma"] == 0.9  # highway-env's racetrack example
    assert shipped_hyperparams("ppo", "default")["gamma"] == 0.8
    assert shipped_hyperparams("sac", "merge") == shipped_hyperparams("sac", "default")  # no entry of its own
    assert shipped_hyperparams("dqn", "no_such_scenario") == shipped_hyperparams("dqn", "default")
    assert shipped_hyperparams("no_such_algo", "highway") == {}
    merged = resolve_hyperparams("dqn", "merge", {"gamma": 0.95, "tau": 0.5})
    assert merged["gamma"] == 0.95 and merged["tau"] == 0.5 and merged["buffer_size"] == 15_000


def test_highway_files_hold_the_documented_defaults():
    # highway-env's scripts/sb3_highway_dqn.py and sb3_highway_ppo.py; every SB3 algorithm has a file
    dqn, ppo = shipped_hyperparams("dqn", "default"), shipped_hyperparams("ppo", "default")
    assert (dqn["learning_rate"], dqn["buffer_size"], dqn["gamma"], dqn["target_update_interval"]) == (
        5e-4, 15_000, 0.8, 50)  # fmt: skip
    assert (ppo["n_steps"], ppo["batch_size"], ppo["n_epochs"], ppo["gamma"]) == (256, 64, 10, 0.8)
    for algo, spec in ALGORITHMS.items():
        if spec.family == "sb3":
            assert shipped_hyperparams(algo, "default") != {}, algo


# entries that differ from ``default`` without being tuned, each with its documented source
CHOSEN_ENTRIES = {
    ("a2c", "drivelab/Racetrack-v0"),  # highway-env's racetrack example's gamma 0.9
    ("ppo", "drivelab/Racetrack-v0"),  # the same (the ppo-racetrack study's best did worse: not kept)
    ("ppo", "drivelab/Town-v0"),  # drivelab's choice: a longer horizon for the town
}


def _without_budget(entry: dict) -> dict:
    return {key: value for key, value in entry.items() if key != "n_timesteps"}


@pytest.mark.parametrize("algo", ["a2c", "dqn", "ppo", "sac"])
def test_every_entry_is_the_default_or_a_committed_studys_best(algo):
    """A scenario entry that differs from ``default`` (and is not a documented choice) holds the
    best trial of the drivelab tune study committed under benchmarks/results/tune/ALGO-SCENARIO/."""
    from pathlib import Path

    results = Path(__file__).parents[1] / "benchmarks" / "results" / "tune"
    table = _zoo_file(algo)
    tuned = 0
    for env_id, entry in table.items():
        if _without_budget(entry) == _without_budget(table["default"]) or (algo, env_id) in CHOSEN_ENTRIES:
            continue
        scenario = env_id.removeprefix("drivelab/").removesuffix("-v0").lower()
        best = results / f"{algo}-{scenario}" / "best-hyperparams.yml"
        assert best.is_file(), f"{env_id} of {algo}.yaml differs from default without a committed study"
        assert yaml.safe_load(best.read_text())[env_id] == entry, env_id
        summary = yaml.safe_load((best.parent / "summary.json").read_text())
        assert summary["best"]["params"].items() <= entry.items() and summary["n_trials"] >= 10
        tuned += 1
    assert tuned >= {"ppo": 2, "a2c": 1, "dqn": 1, "sac": 0}[algo]


def test_every_file_names_a_registered_algorithm():
    files = [f.name for f in resources.files("drivelab.hyperparams").iterdir() if f.name.endswith(".yaml")]
    assert files and all(name.removesuffix(".yaml") in ALGORITHMS for name in files), files


def test_sb3_models_start_from_the_files_default_entry():
    import gymnasium

    from drivelab.agents.sb3 import build_sb3

    model = build_sb3("dqn", gymnasium.make("CartPole-v1"), 0, {"learning_starts": 7}, None)
    assert (model.gamma, model.buffer_size, model.learning_starts) == (0.8, 15_000, 7)


def test_a2c_takes_policy_kwargs_and_leaves_them_as_given():
    """SB3's A2C adds its optimizer class to ``policy_kwargs`` in place: the run's values stay
    as given (and JSON, as the model saves them)."""
    import gymnasium

    from drivelab.agents.sb3 import build_sb3

    given = {"policy_kwargs": {"net_arch": [8]}, "n_steps": 4}
    model = build_sb3("a2c", gymnasium.make("CartPole-v1"), 0, given, None)
    assert given == {"policy_kwargs": {"net_arch": [8]}, "n_steps": 4}
    assert model.drivelab_hyperparams == given and model.policy_kwargs["net_arch"] == [8]


def test_lookups_are_independent_copies():
    first = shipped_hyperparams("ppo", "highway")
    first["policy_kwargs"]["net_arch"]["pi"].append(1)
    assert shipped_hyperparams("ppo", "highway")["policy_kwargs"]["net_arch"]["pi"] == [256, 256]


def test_with_shipped_hyperparams_uses_the_scenario():
    values = with_shipped_hyperparams({"algo": "a2c", "env": "racetrack", "hyperparams": {"n_steps": 5}})
    assert values["hyperparams"] == {"n_steps": 5, "learning_rate": 7e-4, "gamma": 0.9}
    assert with_shipped_hyperparams({"env": "highway"}) == {"env": "highway"}


def test_cli_train_records_resolved_hyperparams(tmp_path):
    config = tmp_path / "run.yaml"
    config.write_text(yaml.safe_dump({"env_options": {"duration_s": 8}, "traffic": "empty"}))
    result = CliRunner().invoke(
        app,
        ["train", "--algo", "ppo", "--steps", "32", "--eval-every", "32", "--eval-episodes", "1",
         "-H", "n_steps=16", "-H", "batch_size=16", "-H", "n_epochs=1", "-H", "gamma=0.5",
         "--config", str(config), "--name", "hp", "--runs-dir", str(tmp_path / "runs")],
    )  # fmt: skip
    assert result.exit_code == 0, result.output
    saved = yaml.safe_load((tmp_path / "runs" / "hp" / "config.yaml").read_text())["hyperparams"]
    assert saved["gamma"] == 0.5 and saved["n_steps"] == 16  # command line wins
    assert saved["learning_rate"] == shipped_hyperparams("ppo", "highway")["learning_rate"]  # the file's
    assert saved["policy_kwargs"] == shipped_hyperparams("ppo", "highway")["policy_kwargs"]


# --- RL Zoo's format ---------------------------------------------------------------------------
# rl_zoo3 is not installed beside drivelab: its dependency typepy[datetime] pins python-dateutil
# < 3, which would downgrade the installed 4.0.0. These tests read our files as rl_zoo3 2.9's code
# does (rl_zoo3/exp_manager.py, ExperimentManager): read_hyperparameters (yaml.safe_load; the env
# id's entry, else "default"), _preprocess_hyperparams (n_timesteps → int, env_kwargs for the env,
# train_freq list → tuple, the rest passed on) and setup_experiment (ALGOS[algo](env=env,
# tensorboard_log=..., seed=..., verbose=..., device=..., **hyperparams), SB3's own classes).
SB3_FILES = [algo for algo, spec in ALGORITHMS.items() if spec.family == "sb3"]


def _zoo_file(algo: str) -> dict:
    return yaml.safe_load((resources.files("drivelab.hyperparams") / f"{algo}.yaml").read_text())


def _zoo_model(algo: str, env_id: str, entry: dict):
    """What rl_zoo3 train --algo ALGO --env ENV_ID -conf drivelab/hyperparams/ALGO.yaml builds."""
    import gymnasium
    import stable_baselines3

    hyperparams = copy.deepcopy(entry)  # SB3's A2C writes its optimizer into policy_kwargs
    del hyperparams["n_timesteps"]  # RL Zoo's budget: learn(int(n_timesteps))
    env = gymnasium.make(env_id, **hyperparams.pop("env_kwargs", {}))
    if isinstance(hyperparams.get("train_freq"), list):
        hyperparams["train_freq"] = tuple(hyperparams["train_freq"])
    model_class = getattr(stable_baselines3, algo.upper())
    model = model_class(env=env, tensorboard_log=None, seed=0, verbose=0, device="cpu", **hyperparams)
    return model, env


@pytest.mark.parametrize("algo", SB3_FILES)
def test_rl_zoo_reads_the_files(algo):
    from drivelab.agents.sb3 import policy_for
    from drivelab.envs import gym_id
    from drivelab.scenarios import SCENARIOS
    from drivelab.yaml_io import YamlLoader

    text = (resources.files("drivelab.hyperparams") / f"{algo}.yaml").read_text()
    table = _zoo_file(algo)
    assert table == yaml.load(text, Loader=YamlLoader)  # YAML 1.1 and drivelab's reading agree
    ids = {gym_id(name) for name in SCENARIOS}
    assert "default" in table and set(table) - {"default"} <= ids, set(table) - ids
    for env_id, entry in table.items():
        assert isinstance(entry["n_timesteps"], int) and entry["n_timesteps"] > 0, env_id
        model, env = _zoo_model(algo, "drivelab/Highway-v0" if env_id == "default" else env_id, entry)
        # the network class is the one drivelab gives the environment's observation
        assert entry["policy"] == policy_for(env.observation_space), env_id
        assert model.policy_class is type(model).policy_aliases[entry["policy"]]
        numbers = {k: v for k, v in entry.items() if isinstance(v, (int, float)) and k != "train_freq"}
        values = {k: getattr(model, k) for k in numbers if k != "n_timesteps"}
        values = {k: v(1.0) if callable(v) else v for k, v in values.items()}  # clip_range: a schedule
        assert values == {k: v for k, v in numbers.items() if k != "n_timesteps"}, env_id
        # drivelab reads the same entry, without RL Zoo's run settings
        scenario = next((n for n in SCENARIOS if gym_id(n) == env_id), env_id)
        shipped = shipped_hyperparams(algo, scenario)
        assert shipped == {k: v for k, v in entry.items() if k not in ("n_timesteps", "policy", "env_kwargs")}
        env.close()


def test_drivelab_reads_entries_by_scenario_or_env_id():
    from drivelab.hyperparams import zoo_entry

    assert shipped_hyperparams("ppo", "racetrack") == shipped_hyperparams("ppo", "drivelab/Racetrack-v0")
    entry = zoo_entry("ppo", "racetrack")
    assert (entry["n_timesteps"], entry["policy"], entry["gamma"]) == (100_000, "MlpPolicy", 0.9)
    tuned = zoo_entry("ppo", "merge")  # a tuned entry names the study's environment
    assert (tuned["policy"], tuned["env_kwargs"]["obs"]) == ("MlpPolicy", ["kinematics"])
    assert not {"n_timesteps", "policy", "env_kwargs"} & set(shipped_hyperparams("sac", "highway"))
    assert zoo_entry("sac", "highway")["env_kwargs"] == {"action": "continuous"}
    # follow-line has no entry: RL Zoo and drivelab both take `default`
    assert zoo_entry("dqn", "follow-line") == zoo_entry("dqn", "default")


def test_rl_zoo_settings_drivelab_cannot_honour_are_refused():
    from drivelab.errors import UsageError
    from drivelab.hyperparams import parse_zoo_file

    with pytest.raises(UsageError, match="'drivelab/Highway-v0' sets RL Zoo's 'normalize'"):
        parse_zoo_file("drivelab/Highway-v0: {n_timesteps: 10, normalize: true}\n", "x.yaml")
    with pytest.raises(UsageError, match="must map env ids to mappings"):
        parse_zoo_file("- 1\n", "x.yaml")


def test_written_files_read_back_as_numbers_in_yaml_1_1():
    from drivelab.hyperparams import parse_zoo_file, zoo_yaml

    entry = {"n_timesteps": 20000, "learning_rate": 1e-05, "gamma": 0.95, "ent_coef": 3e20, "net": [64, 64]}
    text = zoo_yaml({"drivelab/Merge-v0": entry, "default": entry}, "tuned\nsecond line")
    assert text.startswith("# tuned\n# second line\n") and "&" not in text  # no anchors
    assert parse_zoo_file(text, "x.yaml") == {"drivelab/Merge-v0": entry, "default": entry}
