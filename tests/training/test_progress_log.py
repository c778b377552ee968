"""A run's progress logs: rows and TensorBoard scalars for short on-policy runs too (A2C's 100
rollouts between rows left a short run with an empty progress.csv), by the step, so that a resumed
run continues the one progress.csv and TensorBoard shows no step twice."""

import pandas as pd
import pytest
from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

from drivelab.agents.sb3 import DrivelabA2C, DrivelabPPO
from drivelab.training import run as run_module
from tests.training.tiny_runs import tiny_config, train_then_kill_back_to

pytestmark = pytest.mark.usefixtures("one_torch_thread")
A2C = {"algo": "a2c", "hyperparams": {"n_steps": 8, "policy_kwargs": {"net_arch": [16]}}}


def _scalar_steps(run_dir, tag: str) -> list[int]:
    """The steps of ``tag``'s scalars as TensorBoard shows them (events of every file, purges applied)."""
    events = EventAccumulator(str(run_dir))
    events.Reload()
    return [event.step for event in events.Scalars(tag)]


def test_a_short_a2c_run_logs_progress_rows_and_tensorboard_scalars(tmp_path):
    run_dir = run_module.train(tiny_config(**A2C), tmp_path)  # 128 steps: 16 rollouts of 8
    progress = pd.read_csv(run_dir / "progress.csv")
    assert progress["time/total_timesteps"].tolist() == list(range(8, 129, 8))
    assert progress["time/iterations"].tolist() == list(range(1, 17))
    assert progress["train/policy_loss"].notna().sum() >= 15  # each row after the first update
    assert _scalar_steps(run_dir, "train/value_loss") == list(range(16, 129, 8))


@pytest.mark.parametrize(
    ("model_class", "rollout", "steps", "every"),
    [
        (DrivelabA2C, 16, 1_000, 6),  # too short for SB3's 100 rollouts: about ten rows
        (DrivelabA2C, 16, 1_000_000, 100),  # SB3's interval where it gives ten rows or more
        (DrivelabA2C, 16, 100, 1),
        (DrivelabPPO, 2048, 1_000_000, 1),  # PPO.learn's interval: every rollout
    ],
)
def test_on_policy_rows_are_sb3s_interval_or_finer_for_ten_rows(model_class, rollout, steps, every):
    model = model_class.__new__(model_class)  # the interval's arithmetic only: no networks
    model.n_steps, model.n_envs = rollout, 1
    model.log_over(steps)
    assert model.log_rollouts == every


def test_a_resumed_run_continues_progress_csv_and_tensorboard(tmp_path, monkeypatch):
    """A run killed after its checkpoint of step 80 had logged up to step 128 (simulated: the
    finished run with that checkpoint put back). The resume cuts progress.csv back to step 80 and
    continues it, and TensorBoard hides the killed process's events past 80: the logs read as the
    run's that never stopped."""
    config = tiny_config(**A2C, checkpoint_every=40)
    run_dir, reference = train_then_kill_back_to(monkeypatch, tmp_path, config, 80)
    run_module.resume(run_dir)

    assert sorted(path.name for path in run_dir.glob("progress*.csv")) == ["progress.csv"]
    columns = ["time/total_timesteps", "time/iterations"]
    pd.testing.assert_frame_equal(
        pd.read_csv(reference / "progress.csv")[columns], pd.read_csv(run_dir / "progress.csv")[columns]
    )
    assert len(list(run_dir.glob("events.out.tfevents.*"))) == 2  # one per process
    for tag in ("time/fps", "rollout/ep_len_mean", "eval/mean_return"):
        assert _scalar_steps(run_dir, tag) == _scalar_steps(reference, tag), tag
    # the update at step 80 was made (and its losses recorded) by the killed process, whose row of
    # step 88 is hidden: the resumed one logs the losses of its own updates, from step 96
    losses = _scalar_steps(reference, "train/value_loss")
    assert _scalar_steps(run_dir, "train/value_loss") == [step for step in losses if step != 88]


def test_a_short_dueling_ddqn_run_logs_about_ten_rows(tmp_path):
    """dueling_ddqn logs every 250 steps: a 128-step run wrote no row; it now writes about ten, at
    steps that do not depend on where a learn call started."""
    config = tiny_config(algo="dueling_ddqn", hyperparams={"learning_starts": 16, "batch_size": 8})
    run_dir = run_module.train(config, tmp_path)
    progress = pd.read_csv(run_dir / "progress.csv")
    assert progress["time/total_timesteps"].tolist() == list(range(12, 129, 12))
    assert progress["train/epsilon"].is_monotonic_decreasing and progress["train/loss"].notna().sum() >= 8
