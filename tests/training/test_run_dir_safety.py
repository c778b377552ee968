"""A run never deletes a user's files, and bad input or a failed run leaves no partial output.

Guards ``training/run.py`` (resume of a run without a checkpoint, a damaged resume state, failures
after the run directory exists), ``config.check_run_name``, ``evaluate.make_out_dir`` and the
learning-rate bound of every agent. Runs are tiny (PPO, at most 192 steps on an empty road).
"""

import json
import shutil
from pathlib import Path

import pytest
import torch
from typer.testing import CliRunner

from drivelab.agents.a2c import A2CConfig
from drivelab.agents.base import parse_hyperparams
from drivelab.agents.bc import BCConfig
from drivelab.agents.dueling_ddqn import DuelingDDQNConfig
from drivelab.agents.ppo import PPOConfig
from drivelab.agents.rlad.sac import RLADConfig
from drivelab.agents.sb3_params import check_sb3_hyperparams
from drivelab.cli import app
from drivelab.config import check_run_name, save_yaml
from drivelab.errors import UsageError
from drivelab.training import run as run_module
from drivelab.training.evaluate import make_out_dir
from tests.training.tiny_runs import TINY, tiny_config, tree


@pytest.fixture(scope="module")
def finished_run(tmp_path_factory) -> Path:
    """A finished tiny PPO run with checkpoints (and a resume state) at step 128."""
    return run_module.train(tiny_config(), tmp_path_factory.mktemp("runs"))


# --- 1. resume of a folder without a checkpoint ------------------------------------------------
def test_resume_refuses_a_folder_holding_user_files_and_changes_nothing(tmp_path):
    folder = tmp_path / "project"
    (folder / "data").mkdir(parents=True)
    (folder / "config.yaml").write_text("algo: ppo\nsteps: 64\ntraffic: empty\n")
    (folder / "thesis.tex").write_text("mine")
    (folder / "data" / "x.csv").write_text("1")
    before = tree(tmp_path)
    result = CliRunner().invoke(app, ["train", "--resume", str(folder)])
    lines = result.output.strip().splitlines()
    assert result.exit_code == 2, result.output
    assert lines[-1].startswith("error: ") and "data/, thesis.tex" in lines[-1], result.output
    assert "Traceback" not in result.output
    assert tree(tmp_path) == before


def test_resume_refuses_a_folder_whose_only_file_is_atiny_config(tmp_path):
    (tmp_path / "config.yaml").write_text("algo: ppo\nsteps: 64\ntraffic: empty\n")
    before = tree(tmp_path)
    with pytest.raises(UsageError, match="no monitor.csv"):
        run_module.resume(tmp_path)
    assert tree(tmp_path) == before


def test_resume_of_a_run_stopped_before_its_first_checkpoint_trains_it_again(finished_run, tmp_path):
    run_dir = tmp_path / "r"
    shutil.copytree(finished_run, run_dir)
    # as if killed while writing its first checkpoint: the run's logs, a resume state, no manifest
    for name in ("model.zip", "learning_curve.png", "checkpoints/latest.json", "checkpoints/latest.zip"):
        (run_dir / name).unlink()
    (run_dir / "checkpoints" / "latest.tmp.zip").write_bytes(b"partial")
    assert run_module.resume(run_dir) == run_dir
    assert (run_dir / "model.zip").is_file()
    assert json.loads((run_dir / "checkpoints/latest.json").read_text())["steps"] == 128
    assert not (run_dir / "checkpoints" / "latest.tmp.zip").exists()


# --- 2. a damaged resume state ---------------------------------------------------------------------
DAMAGE = {
    "python generator": lambda state: state["rng"].__setitem__("python", [3, [1, 2], None]),
    "world start": lambda state: state["worlds"][0].__setitem__("start", "garbage"),
    "monitor time": lambda state: state["monitor"].__setitem__("elapsed_s", "x"),
    "rows": lambda state: state.__setitem__("rows", {}),
    "negative rows": lambda state: state.__setitem__("rows", {"monitor": -5, "evaluations": 0}),
    "not a mapping": lambda state: state.clear() or state.update(format=1, steps=128),
}


@pytest.mark.parametrize("damage", list(DAMAGE))
def test_a_damaged_resume_state_is_one_error_and_changes_nothing(finished_run, tmp_path, damage):
    run_dir = tmp_path / "r"
    shutil.copytree(finished_run, run_dir)
    path = run_dir / "checkpoints" / "resume-128.json"
    state = json.loads(path.read_text())
    DAMAGE[damage](state)
    path.write_text(json.dumps(state))
    before = tree(run_dir)
    with pytest.raises(UsageError, match=f"resume state '{path}'"):
        run_module.resume(run_dir, 192)
    assert tree(run_dir) == before


# --- 3. failures after the run directory exists ----------------------------------------------------
@pytest.mark.parametrize("algo", ["ppo", "a2c", "dqn", "sac"])
def test_sb3_learning_rates_above_one_are_refused(algo):
    assert check_sb3_hyperparams(algo, {"learning_rate": 1})["learning_rate"] == 1.0
    with pytest.raises(UsageError, match=r"'learning_rate' of .* must be a number in \(0, 1.0\]"):
        check_sb3_hyperparams(algo, {"learning_rate": 1e30})


@pytest.mark.parametrize(
    ("config_class", "algo", "key"),
    [
        (PPOConfig, "ppo_own", "learning_rate"),
        (A2CConfig, "a2c_own", "learning_rate"),
        (BCConfig, "bc", "learning_rate"),
        (DuelingDDQNConfig, "dueling_ddqn", "learning_rate"),
        (DuelingDDQNConfig, "dueling_ddqn", "final_learning_rate"),
        (RLADConfig, "rlad", "learning_rate"),
        (RLADConfig, "rlad", "alix_learning_rate"),
    ],
)
def test_own_agents_learning_rates_above_one_are_refused(config_class, algo, key):
    assert getattr(parse_hyperparams(config_class, algo, {key: 1.0}), key) == 1.0
    with pytest.raises(UsageError, match=key):
        parse_hyperparams(config_class, algo, {key: 1e30})


def test_a_huge_learning_rate_is_refused_before_any_folder_exists(tmp_path):
    with pytest.raises(UsageError, match="learning_rate"):
        run_module.train(tiny_config(hyperparams={**TINY, "learning_rate": 1e30}), tmp_path / "runs")
    assert tree(tmp_path) == {}


def _poison_weights_at(monkeypatch, step: int) -> None:
    """Training diverges at ``step``: every weight of the model becomes NaN."""
    on_step = run_module.RunCallback._on_step

    def poisoned(callback):
        if callback.num_timesteps == step:
            with torch.no_grad():
                for parameter in callback.model.policy.parameters():
                    parameter.fill_(float("nan"))
        return on_step(callback)

    monkeypatch.setattr(run_module.RunCallback, "_on_step", poisoned)


def test_divergence_before_the_first_checkpoint_leaves_no_folder(tmp_path, monkeypatch):
    _poison_weights_at(monkeypatch, 10)
    with pytest.raises(UsageError, match="diverged at step .*no checkpoint was written"):
        run_module.train(tiny_config(), tmp_path / "runs")
    assert tree(tmp_path) == {}


def test_divergence_keeps_the_checkpoints_written_before_it(tmp_path, monkeypatch):
    _poison_weights_at(monkeypatch, 100)
    with pytest.raises(UsageError, match="diverged at step .*keeps its last finite checkpoint, of step 64"):
        run_module.train(tiny_config(), tmp_path)
    manifest = json.loads((tmp_path / "r" / "checkpoints" / "latest.json").read_text())
    assert manifest["steps"] == 64 and not (tmp_path / "r" / "model.zip").exists()


def test_running_out_of_memory_is_one_error_and_leaves_no_folder(tmp_path, monkeypatch):
    def no_memory(*args, **kwargs):
        raise MemoryError

    monkeypatch.setattr(run_module, "_make_envs", no_memory)
    with pytest.raises(UsageError, match=r"not enough memory .*n_envs=1"):
        run_module.train(tiny_config(), tmp_path / "runs" / "x")
    assert tree(tmp_path) == {}


def test_a_model_too_large_to_build_is_one_error():
    class Spec:
        def build(self, *args):
            raise MemoryError

    with pytest.raises(UsageError, match="not enough memory"):
        run_module._check_model(Spec(), tiny_config(), probe=None)


# --- 4. run names and folders the file system cannot hold ------------------------------------------
def test_run_names_too_long_or_with_control_characters_are_refused():
    assert check_run_name("a" * 255) == "a" * 255
    for name in ("a" * 256, "é" * 128, "a\nb", "tab\there"):
        with pytest.raises(UsageError, match="run name"):
            check_run_name(name)


def test_a_run_name_too_long_is_one_error_line_and_creates_nothing(tmp_path):
    result = CliRunner().invoke(
        app,
        ["train", "--algo", "ppo", "--steps", "64", "--runs-dir", str(tmp_path / "y"), "--name", "a" * 300],
    )
    assert result.exit_code == 2, result.output
    assert result.output.startswith("error: run name") and "300 bytes" in result.output
    assert tree(tmp_path) == {}


def test_a_runs_dir_too_long_for_the_file_system_creates_nothing(tmp_path):
    with pytest.raises(UsageError, match="File name too long"):
        run_module.train(tiny_config(), tmp_path / "y" / ("b" * 300))
    with pytest.raises(UsageError, match="File name too long"):
        make_out_dir(tmp_path / "z" / ("b" * 300) / "c", "report folder")
    assert tree(tmp_path) == {}


def test_ctrl_c_while_a_run_is_set_up_leaves_no_folder(tmp_path, monkeypatch):
    """A run interrupted before training starts (its config written, its worlds being built) would
    leave a folder that neither --resume nor a new run of that name could use."""

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(run_module, "_make_envs", interrupted)
    with pytest.raises(KeyboardInterrupt):
        run_module.train(tiny_config(name="r"), tmp_path / "runs")
    assert list(tmp_path.iterdir()) == []


def test_a_run_made_before_the_eval_every_check_trains_again_from_step_0(tmp_path, monkeypatch):
    """A run with eval_every > steps (made before ``train`` refused that), stopped before its first
    checkpoint: ``train --resume`` trains it again from step 0 with its own config, as it did
    before, instead of refusing the schedule it cannot change (``--resume`` takes no --eval-every)."""
    run_dir = tmp_path / "r"
    run_dir.mkdir()
    config = tiny_config(steps=64, eval_every=100)
    save_yaml(config, run_dir / "config.yaml")
    (run_dir / "monitor.csv").write_text('#{"t_start": 1.0, "env_id": "highway"}\nr,l,t\n')
    trained = []
    monkeypatch.setattr(run_module, "train", lambda config, root, *args: trained.append(config) or root)
    run_module.resume(run_dir)
    assert [(c.steps, c.eval_every) for c in trained] == [(64, 100)]
