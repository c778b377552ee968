"""drivelab tune: a study end to end on tiny budgets, its continuation, the pruner's wiring."""

import json
import os
import signal

import pandas as pd
import pytest
import yaml
from typer.testing import CliRunner

from drivelab.cli import app
from drivelab.errors import UsageError
from drivelab.training import tune
from drivelab.training.tune import TrialReporter, open_optuna_study, read_study, run_study

runner = CliRunner()

# highway, compiled core, no traffic, 8-second episodes: a 64-step trial trains in about a second
TINY = {
    "name": "tiny", "algo": "ppo", "env": "highway", "obs": "kinematics", "traffic": "empty",
    "backend": "fast", "env_options": {"duration_s": 8}, "steps": 64, "eval_every": 32,
    "eval_episodes": 1, "final_eval_episodes": 2, "n_trials": 3,
    "hyperparams": {"n_steps": 16, "batch_size": 16, "n_epochs": 1},
    "sampler": {"seed": 0},
    "space": {
        "learning_rate": {"type": "log", "low": 1.0e-4, "high": 1.0e-2},
        "gamma": {"type": "float", "low": 0.8, "high": 0.99},
        "n_epochs": {"type": "int", "low": 1, "high": 3},
        "policy_kwargs": {"type": "categorical", "choices": [{"net_arch": [32]}, {"net_arch": [64, 64]}]},
    },
}  # fmt: skip


def study_file(tmp_path, **changes):
    path = tmp_path / "study.yaml"
    path.write_text(yaml.safe_dump({**TINY, **changes}))
    return path


def test_three_trial_study_end_to_end_then_continued(tmp_path):
    path, folder = study_file(tmp_path), tmp_path / "study"
    command = ["tune", str(path), "--study-dir", str(folder), "--workers", "1"]
    result = runner.invoke(app, command)
    assert result.exit_code == 0, result.output
    summary = json.loads((folder / "summary.json").read_text())
    assert summary["states"] == {"complete": 3} and summary["metric"] == "mean_return"
    trials = pd.read_csv(folder / "trials.csv")
    assert list(trials["number"]) == [0, 1, 2] and set(trials["state"]) == {"complete"}
    assert list(trials["last_step"]) == [64, 64, 64]  # the periodic evaluations reached the study
    best = summary["best"]
    # the objective is the final evaluation (eval.json) of the best trial's run directory
    report = json.loads((folder / best["run_dir"] / "eval.json").read_text())
    assert best["value"] == report["mean_return"] == trials["value"].max()
    assert report["episodes"] == 2
    for number, row in trials.iterrows():
        config = yaml.safe_load((folder / f"trial-{number:04d}" / "config.yaml").read_text())
        assert config["hyperparams"]["learning_rate"] == row["learning_rate"]
        assert config["hyperparams"]["n_steps"] == 16 and config["steps"] == 64
        assert 1e-4 <= row["learning_rate"] <= 1e-2 and 0.8 <= row["gamma"] <= 0.99
        assert json.loads(row["policy_kwargs"]) in TINY["space"]["policy_kwargs"]["choices"]
    # the best values as an RL Zoo entry, read as RL Zoo reads it (YAML 1.1)
    entry = yaml.safe_load((folder / "best-hyperparams.yml").read_text())["drivelab/Highway-v0"]
    assert entry["n_timesteps"] == 64 and entry["policy"] == "MlpPolicy"
    assert entry["env_kwargs"]["traffic"] == "empty" and entry["env_kwargs"]["backend"] == "fast"
    assert {key: entry[key] for key in best["params"]} == best["params"]
    assert "best: trial-000" in result.output and "summary.md" in result.output
    assert "| number | state | value |" in (folder / "summary.md").read_text()

    # the same command again: the study is complete, nothing runs; one more trial: only it runs
    models = {p: p.stat().st_mtime_ns for p in folder.glob("trial-*/model.zip")}
    result = runner.invoke(app, command)
    assert result.exit_code == 0, result.output
    assert "trial-0" not in result.output.split("study tiny")[-1].split("best:")[0]  # no trial ran
    result = runner.invoke(app, [*command, "--n-trials", "4"])
    assert result.exit_code == 0, result.output
    assert {p: p.stat().st_mtime_ns for p in models} == models
    trials = pd.read_csv(folder / "trials.csv")
    assert list(trials["number"]) == [0, 1, 2, 3] and set(trials["state"]) == {"complete"}
    # the continued sampler does not draw the first trial's values again
    assert trials.loc[3, "learning_rate"] != trials.loc[0, "learning_rate"]


def test_an_interrupted_study_resumes_its_running_trial(tmp_path, monkeypatch):
    """SIGINT in the middle of trial 0: its run is checkpointed, the trial stays running in the
    journal; the same command resumes that run from its checkpoint instead of a new trial."""
    study = read_study({**TINY, "n_trials": 2, "checkpoint_every": 32}, tmp_path / "study")
    report = TrialReporter.__call__

    def interrupt_at_first_evaluation(self, step, summary):
        os.kill(os.getpid(), signal.SIGINT)  # what Ctrl-C does; StopRequest stops at the next step
        return report(self, step, summary)

    monkeypatch.setattr(TrialReporter, "__call__", interrupt_at_first_evaluation)
    with pytest.raises(KeyboardInterrupt):
        run_study(study, workers=1)
    monkeypatch.setattr(TrialReporter, "__call__", report)
    manifest = json.loads((study.study_dir / "trial-0000" / "checkpoints" / "latest.json").read_text())
    assert 0 < manifest["steps"] < 64
    states = [t.state.name for t in open_optuna_study(study).get_trials()]
    assert states == ["RUNNING"]

    summary = run_study(study, workers=1)
    done = [(o["name"], o["action"]) for o in summary["outcomes"]]
    assert done == [("trial-0000", "resume"), ("trial-0001", "train")]
    assert summary["states"] == {"complete": 2}
    assert (study.study_dir / "trial-0000" / "eval.json").is_file()

    # the study that was never stopped: the same trials, values and results
    whole = read_study({**TINY, "n_trials": 2, "checkpoint_every": 32}, tmp_path / "whole")
    run_study(whole, workers=1)
    resumed = pd.read_csv(study.study_dir / "trials.csv").drop(columns=["seconds", "run_dir"])
    reference = pd.read_csv(whole.study_dir / "trials.csv").drop(columns=["seconds", "run_dir"])
    pd.testing.assert_frame_equal(resumed, reference)


def test_median_pruner_stops_a_trial_behind_the_others(tmp_path):
    """Deterministic intermediate values: a trial reporting below the median of the finished
    trials at the same step is pruned; one above it goes on."""
    study = read_study({**TINY, "pruner": {"n_startup_trials": 2}}, tmp_path / "study")
    study.study_dir.mkdir()
    optuna_study = open_optuna_study(study)
    for value in (10.0, 12.0):
        trial = optuna_study.ask()
        trial.report(value, 32)
        optuna_study.tell(trial, value)

    def reporter(trial):
        return TrialReporter(str(study.study_dir), study.name, trial._trial_id, "mean_return", study.pruner)

    behind, ahead = optuna_study.ask(), optuna_study.ask()
    assert reporter(behind)(32, {"mean_return": 1.0}) is False
    assert reporter(ahead)(32, {"mean_return": 20.0}) is True
    assert optuna_study.trials[2].intermediate_values == {32: 1.0}
    # a resumed run reports the same step again: the first value stays
    assert reporter(behind)(32, {"mean_return": 50.0}) is False


def test_a_pruned_trial_stops_its_run_and_is_recorded_pruned(tmp_path, monkeypatch):
    """The pruner's answer reaches the run: training stops after the evaluation, the run is
    checkpointed there (resumable, no final evaluation) and the trial is told PRUNED."""
    study = read_study({**TINY, "n_trials": 1}, tmp_path / "study")
    monkeypatch.setattr(TrialReporter, "__call__", lambda self, step, summary: False)
    summary = run_study(study, workers=1)
    (outcome,) = summary["outcomes"]
    # stopped at the first evaluation (step 32), checkpointed at the rollout start before it (16)
    assert outcome["ok"] and outcome["stopped"] == 16
    assert summary["states"] == {"pruned": 1} and summary["best"] is None
    run_dir = study.study_dir / "trial-0000"
    assert json.loads((run_dir / "checkpoints" / "latest.json").read_text())["steps"] == 16
    assert not (run_dir / "eval.json").exists() and not (run_dir / "model.zip").exists()
    assert not (study.study_dir / "best-hyperparams.yml").exists()


def test_write_best_updates_one_entry_of_a_zoo_file(tmp_path):
    study = read_study({**TINY, "n_trials": 1}, tmp_path / "study")
    summary = run_study(study, workers=1)
    target = tmp_path / "ppo.yml"
    target.write_text("# my PPO values\n# second line\ndefault: &d\n  n_timesteps: 100\n  policy: MlpPolicy\n"
                      "drivelab/Merge-v0: *d\n")  # fmt: skip
    tune.write_best(study, summary, target)
    text = target.read_text()
    assert text.startswith("# my PPO values\n# second line\n# drivelab/Highway-v0: tuned by drivelab tune")
    entries = yaml.safe_load(text)
    assert entries["drivelab/Merge-v0"] == {"n_timesteps": 100, "policy": "MlpPolicy"}
    assert entries["drivelab/Highway-v0"]["learning_rate"] == summary["best"]["params"]["learning_rate"]


@pytest.mark.parametrize(
    "changes, message",
    [
        ({"space": {"gamma": {"type": "float", "low": 0.8}}}, "needs 'low' and 'high'"),
        ({"space": {"n_steps": {"type": "int", "low": 1.5, "high": 8}}}, "needs integer bounds"),
        ({"space": {"gamma": {"type": "log", "low": 0.1, "high": 0.9, "step": 0.1}}}, "both 'step'"),
        ({"space": {"gamma": {"type": "float", "low": 0.5, "high": 0.9, "step": 0.3}}}, "must divide high"),
        ({"space": {"n_epochs": {"type": "int", "low": 1, "high": 10, "step": 2}}}, "must divide high"),
        ({"sampler": {"seed": -1}}, "tune sampler 'seed' must be an integer >= 0"),
        ({"pruner": {"patience": 3}}, "unknown key 'patience'"),
        ({"direction": "up"}, "must be maximize or minimize"),
    ],
)
def test_more_malformed_study_files(changes, message):
    with pytest.raises(UsageError, match=message):
        read_study({**TINY, **changes})


def test_crash_rate_is_minimised_and_log_type_is_a_log_float():
    study = read_study({**TINY, "metric": "crash_rate"})
    assert study.direction == "minimize"
    learning_rate = next(p for p in study.space if p.name == "learning_rate")
    assert (learning_rate.kind, learning_rate.log, learning_rate.low) == ("float", True, 1e-4)


@pytest.mark.parametrize(
    "name", ["ppo-highway", "ppo-merge", "ppo-roundabout", "ppo-intersection", "ppo-racetrack", "a2c-highway",
             "dqn-highway"],
)  # fmt: skip
def test_the_committed_study_files_are_valid(name):
    """The studies whose tuned values drivelab/hyperparams/ ships read as studies of their
    algorithm and scenario, searching the learning rate and the discount at least."""
    from pathlib import Path

    study = tune.load_study(Path(__file__).parents[2] / "benchmarks" / "sweeps" / f"tune-{name}.yaml")
    algo, env = name.split("-")
    assert (study.name, study.run["algo"], study.run["env"]) == (name, algo, env)
    assert study.n_trials >= 10 and study.run["steps"] >= 40_000 and study.final_eval_episodes in (20, 100)
    assert {p.name for p in study.space} >= {"learning_rate", "gamma"}


def test_a_study_begun_before_the_eval_every_check_goes_on(tmp_path):
    """A study with eval_every > steps made before tune refused that: continued (its study.yaml is
    this study's), not refused for a schedule that cannot change (it is the study's identity); a
    new study with it is refused."""
    path, folder = study_file(tmp_path, eval_every=128), tmp_path / "study"
    with pytest.raises(UsageError, match=r"'eval_every' \(128\) is larger than 'steps' \(64\)"):
        tune.load_study(path, folder)
    folder.mkdir()
    identity = read_study(yaml.safe_load(path.read_text()), folder).identity()
    (folder / tune.SPEC_FILE).write_text(yaml.safe_dump(json.loads(json.dumps(identity)), sort_keys=False))
    assert tune.load_study(path, folder).run["eval_every"] == 128
