"""A run whose weights become NaN or infinite stops within ``CHECK_EVERY_STEPS`` steps with one
``error:`` line (exit 2) and keeps its last finite checkpoint, which evaluates and resumes.

Guards ``training/divergence.py`` and its use in ``training/run.py``. Training diverges for real:
a global optimizer hook raises every learning rate to infinity once the run has written its
checkpoint of step 200, so the first updates after it overflow the weights (``-H learning_rate``
stops at 1). Runs are tiny (at most 400 steps on an empty road).
"""

import json
import re
from pathlib import Path

import pytest
import torch
import yaml
from torch.optim.optimizer import register_optimizer_step_pre_hook
from typer.testing import CliRunner

from drivelab.cli import app
from drivelab.config import build_config
from drivelab.training import checkpoints
from drivelab.training import run as run_module
from drivelab.training.divergence import CHECK_EVERY_STEPS, non_finite_weights, remedy

CHECKPOINT, STEPS = 200, 400  # the checkpoint before the divergence; the next would be at STEPS
pytestmark = pytest.mark.usefixtures("one_torch_thread")
NET = {"policy_kwargs": {"net_arch": [16]}}
TOWN = {"env": "town", "action": "target_speed", "reward": "roach", "env_options": {"duration_s": 3}}
SETUPS = {  # each updates its weights between steps 200 and 220: the first update after the checkpoint
    "dqn": {"algo": "dqn",
            "hyperparams": {"learning_starts": 210, "buffer_size": 500, "batch_size": 16, **NET}},
    "dueling_ddqn": {"algo": "dueling_ddqn",
                     "hyperparams": {"learning_starts": 210, "buffer_size": 500, "batch_size": 16}},
    "ppo": {"algo": "ppo", "hyperparams": {"n_steps": 20, "batch_size": 20, "n_epochs": 1, **NET}},
    "a2c": {"algo": "a2c", "action": "continuous", "hyperparams": {"n_steps": 20, **NET}},
    "sac": {"algo": "sac", "action": "continuous",
            "hyperparams": {"learning_starts": 210, "buffer_size": 500, "batch_size": 16, **NET}},
    "ppo_own": {"algo": "ppo_own", "action": "continuous", "hyperparams": {"n_steps": 20, "batch_size": 20}},
    "a2c_own": {"algo": "a2c_own", "action": "continuous", "hyperparams": {"n_steps": 20}},
    "bc": {"algo": "bc", "obs": "waypoints,measurements", **TOWN,
           "hyperparams": {"round_steps": 20, "epochs": 1, "batch_size": 16}},
    "rlad": {"algo": "rlad", **TOWN,
             "obs": ["camera:width=24:height=24", "waypoints", "measurements:stack=3"],
             "hyperparams": {"learning_starts": 210, "batch_size": 4, "buffer_size": 300, "hidden_size": 16}},
}  # fmt: skip
SILENT = ("dqn", "dueling_ddqn")  # act on NaN Q-values without an error: only the check finds them
ERROR = re.compile(r"error: training of '(\w+)' diverged at step (\d+): (.*)")


class AbsurdLearningRate:
    """A global optimizer hook: once a run in ``runs`` has a checkpoint, every optimizer steps with a
    learning rate of infinity (until ``runs`` is None)."""

    def __init__(self) -> None:
        self.runs: Path | None = None

    def __call__(self, optimizer, args, kwargs) -> None:
        if self.runs is not None and any(self.runs.glob("*/checkpoints/latest.json")):
            for group in optimizer.param_groups:
                group["lr"] = float("inf")


@pytest.fixture
def absurd_learning_rate():
    hook = AbsurdLearningRate()
    handle = register_optimizer_step_pre_hook(hook)
    yield hook
    handle.remove()


def _train_command(tmp_path: Path, setup: str) -> list[str]:
    values = {
        "env": "highway", "obs": "kinematics", "action": "meta", "traffic": "empty", "steps": STEPS,
        "seed": 2, "name": setup, "eval_every": STEPS, "eval_episodes": 1, "checkpoint_every": CHECKPOINT,
        "env_options": {"duration_s": 10}, **SETUPS[setup],
    }  # fmt: skip
    path = tmp_path / f"{setup}.yaml"
    path.write_text(yaml.safe_dump(values))
    return ["train", "--config", str(path), "--runs-dir", str(tmp_path / "runs")]


def _error(result) -> re.Match:
    """The one ``error:`` line of a failed command (the progress bar shares stderr)."""
    lines = [line for line in re.split(r"[\r\n]", result.stderr) if line.startswith("error:")]
    assert len(lines) == 1, result.stderr[-2000:]
    match = ERROR.fullmatch(lines[0])
    assert match, lines[0]
    return match


@pytest.mark.parametrize("setup", list(SETUPS))
def test_a_diverging_run_stops_at_the_next_check_and_keeps_its_last_finite_checkpoint(
    tmp_path, setup, absurd_learning_rate
):
    absurd_learning_rate.runs = tmp_path / "runs"
    result = CliRunner().invoke(app, _train_command(tmp_path, setup))
    assert result.exit_code == 2, result.output
    algo, steps, detail = _error(result).groups()
    run_dir = tmp_path / "runs" / setup
    assert algo == SETUPS[setup]["algo"]
    # found by the first check after the divergence, not at the next checkpoint (STEPS)
    assert CHECKPOINT < int(steps) <= CHECKPOINT + CHECK_EVERY_STEPS
    if setup in SILENT:
        assert int(steps) == CHECKPOINT + CHECK_EVERY_STEPS
        assert re.match(r"\S+ \(and \d+ more weight tensors\) became (nan|inf); lower learning_rate", detail)
    assert detail.endswith(
        f"{str(run_dir)!r} keeps its last finite checkpoint, of step {CHECKPOINT}, for "
        f"`drivelab evaluate {run_dir}` (a resume would repeat the same steps)"
    )
    manifest = json.loads((run_dir / "checkpoints" / "latest.json").read_text())
    assert manifest["steps"] == CHECKPOINT and not (run_dir / "model.zip").exists()
    assert sorted(p.name for p in (run_dir / "checkpoints").glob("resume-*.json")) == [
        f"resume-{CHECKPOINT}.json"
    ]
    config = build_config(yaml.safe_load((run_dir / "config.yaml").read_text()))
    assert non_finite_weights(checkpoints.load_agent(run_dir, config)) == []


def test_a_diverged_model_is_not_evaluated(tmp_path, absurd_learning_rate):
    absurd_learning_rate.runs = tmp_path / "runs"
    command = [*_train_command(tmp_path, "dqn"), "--eval-every", "250"]
    result = CliRunner().invoke(app, command)
    assert result.exit_code == 2
    assert _error(result).group(2) == "250"  # the evaluation's own check, before the periodic one
    assert not (tmp_path / "runs" / "dqn" / "evaluations.csv").exists()


def test_a_diverged_run_evaluates_and_resumes_from_its_last_finite_checkpoint(tmp_path, absurd_learning_rate):
    absurd_learning_rate.runs = tmp_path / "runs"
    runner, command = CliRunner(), _train_command(tmp_path, "dqn")
    assert runner.invoke(app, command).exit_code == 2
    run_dir = tmp_path / "runs" / "dqn"
    checkpoint = (run_dir / "checkpoints" / "latest.zip").read_bytes()
    evaluated = runner.invoke(app, ["evaluate", str(run_dir), "--episodes", "1"])
    assert evaluated.exit_code == 0, evaluated.output
    assert json.loads((run_dir / "eval.json").read_text())["episodes"] == 1
    # the same steps again diverge again, where they did, and leave the checkpoint as it was
    resumed = runner.invoke(app, ["train", "--resume", str(run_dir)])
    assert resumed.exit_code == 2
    assert _error(resumed).group(2) == str(CHECKPOINT + CHECK_EVERY_STEPS)
    assert (run_dir / "checkpoints" / "latest.zip").read_bytes() == checkpoint


def test_a_resume_with_sane_updates_finishes_the_run(tmp_path, absurd_learning_rate):
    absurd_learning_rate.runs = tmp_path / "runs"
    assert CliRunner().invoke(app, _train_command(tmp_path, "dqn")).exit_code == 2
    run_dir = tmp_path / "runs" / "dqn"
    absurd_learning_rate.runs = None
    resumed = CliRunner().invoke(app, ["train", "--resume", str(run_dir)])
    assert resumed.exit_code == 0, resumed.output
    assert json.loads((run_dir / "checkpoints" / "latest.json").read_text())["steps"] == STEPS
    assert (run_dir / "model.zip").is_file()


# --- non_finite_weights ------------------------------------------------------------------------
class Agent:
    """Weights as agents hold them: modules (one of them twice, as SB3's aliases) and a tensor."""

    def __init__(self) -> None:
        self.policy = torch.nn.Sequential(torch.nn.Linear(3, 4), torch.nn.BatchNorm1d(4))
        self.q_net = self.policy  # an alias: its weights are named once
        self.log_alpha = torch.zeros(1, requires_grad=True)
        self.steps = torch.tensor(3)  # integers are no weights


def test_non_finite_weights_names_each_tensor_once_with_nan_or_inf():
    agent = Agent()
    assert non_finite_weights(agent) == []
    with torch.no_grad():
        agent.policy[0].weight[1, 2] = float("nan")
        agent.policy[1].running_var[0] = float("inf")
        agent.log_alpha.fill_(-float("inf"))
    assert non_finite_weights(agent) == [
        ("policy.0.weight", "nan"), ("policy.1.running_var", "inf"), ("log_alpha", "inf"),
    ]  # fmt: skip


def test_finite_weights_whose_sums_overflow_are_finite():
    agent = Agent()
    with torch.no_grad():
        agent.policy[0].weight.fill_(3e38)  # the sum of 12 of them is inf in float32
    assert non_finite_weights(agent) == []


def test_remedy_names_max_grad_norm_only_where_the_algorithm_has_it():
    class Config:
        max_grad_norm = 0.5

    class Own:
        config = Config()

    class SAC:
        pass

    assert remedy(Own()) == "lower learning_rate, or limit max_grad_norm"
    assert remedy(SAC()) == "lower learning_rate"


def test_weights_are_checked_at_most_once_per_check_interval(tmp_path, monkeypatch):
    steps_checked = []
    check = run_module.RunCallback.check_weights

    def counted(callback, steps):
        steps_checked.append(callback.num_timesteps)
        return check(callback, steps)

    monkeypatch.setattr(run_module.RunCallback, "check_weights", counted)
    values = {**SETUPS["dqn"], "env": "highway", "obs": "kinematics", "action": "meta", "traffic": "empty",
              "steps": 450, "seed": 2, "name": "r", "eval_every": 450, "checkpoint_every": 450,
              "env_options": {"duration_s": 10}}  # fmt: skip
    run_module.train(build_config(values), tmp_path)
    # DQN (train_freq 1) has a safe point at every step: checks at 100, 200, ..., and at 450 those of
    # the one evaluation (eval_every = steps) and of the final checkpoint
    assert steps_checked == [100, 200, 300, 400, 450, 450]
