"""Exact resume: a run stopped by SIGINT/SIGTERM (or killed after a checkpoint) and resumed ends
with the same parameters, evaluations and monitor rows as the same run uninterrupted.

Budgets are tiny (a few hundred steps) and the interrupts fall inside an episode, and for the
on-policy agents inside a rollout, so that the env's mid-episode state, the counters and every
random generator must all come back for the runs to agree. Equality is exact (``torch.equal``,
identical CSV values): the same code on the same machine, nothing may drift.
"""

import json
import os
import signal

import pandas as pd
import pytest
import torch

from drivelab.config import build_config
from drivelab.errors import UsageError
from drivelab.training import checkpoints
from drivelab.training import run as run_module
from drivelab.training.evaluate import evaluate_run
from tests.training.tiny_runs import train_then_kill_back_to

pytestmark = pytest.mark.usefixtures("one_torch_thread")
SMALL_NET = {"policy_kwargs": {"net_arch": [32, 32]}}
SETUPS = {
    "dqn": {"algo": "dqn", "action": "meta", "steps": 300,
            "hyperparams": {"learning_starts": 50, "buffer_size": 1000, "target_update_interval": 20,
                            **SMALL_NET}},
    "ppo": {"algo": "ppo", "action": "meta", "steps": 256,
            "hyperparams": {"n_steps": 32, "batch_size": 16, "n_epochs": 2, **SMALL_NET}},
    "ppo-2-worlds": {"algo": "ppo", "action": "meta", "steps": 192, "n_envs": 2,
                     "hyperparams": {"n_steps": 16, "batch_size": 16, "n_epochs": 2, **SMALL_NET}},
    "dueling_ddqn": {"algo": "dueling_ddqn", "action": "meta", "steps": 150,
                     "hyperparams": {"learning_starts": 30, "buffer_size": 500, "batch_size": 16}},
    "ppo_own": {"algo": "ppo_own", "action": "continuous", "steps": 192,
                "hyperparams": {"n_steps": 32, "batch_size": 16, "n_epochs": 2}},
    "a2c_own": {"algo": "a2c_own", "action": "continuous", "steps": 160, "hyperparams": {"n_steps": 32}},
    "dueling_ddqn-3-worlds": {"algo": "dueling_ddqn", "action": "meta", "steps": 150, "n_envs": 3,
                              "hyperparams": {"learning_starts": 30, "buffer_size": 500, "batch_size": 16}},
    "ppo_own-4-worlds": {"algo": "ppo_own", "action": "continuous", "steps": 256, "n_envs": 4,
                         "hyperparams": {"n_steps": 8, "batch_size": 16, "n_epochs": 2}},
    # the array path (monitored VecEnv stepped by step_arrays) with every running statistic
    "ppo_own-4-worlds-normalised": {"algo": "ppo_own", "action": "meta", "steps": 256, "n_envs": 4,
                                    "hyperparams": {"n_steps": 8, "batch_size": 16, "n_epochs": 2,
                                                    "normalize_observations": True,
                                                    "normalize_rewards": True}},
    # self-imitation: its replay (40 transitions, wrapped by the third rollout) is in the checkpoint
    "ppo_own-4-worlds-self-imitation": {"algo": "ppo_own", "action": "meta", "steps": 256, "n_envs": 4,
                                        "hyperparams": {"n_steps": 8, "batch_size": 16, "n_epochs": 2,
                                                        "normalize_rewards": True, "sil_updates": 2,
                                                        "sil_batch_size": 8, "sil_capacity": 40}},
    "a2c_own-3-worlds-beta": {"algo": "a2c_own", "action": "continuous", "steps": 240, "n_envs": 3,
                              "hyperparams": {"n_steps": 16, "distribution": "beta",
                                              "normalize_observations": True}},
    # pixel SAC: the replay (frames, stacks, the open episode) is part of the checkpoint
    **{name: {"algo": algo, "env": "town", "obs": ["camera:width=24:height=24:stack=3", "waypoints",
                                                     "measurements:stack=3"],
              "action": "target_speed", "reward": "roach", "traffic": "empty", "steps": 90,
              "env_options": {"duration_s": 3},
              "hyperparams": {"learning_starts": 20, "batch_size": 4, "buffer_size": 64, "hidden_size": 32,
                              "log_interval": 10, **extra}}
       for name, algo, extra in (("rlad", "rlad", {}), ("drq", "drq", {}),
                                 ("rlad-fast", "rlad", {"fast_update": True}))},
    "bc": {"algo": "bc", "env": "town", "obs": "waypoints,measurements", "action": "target_speed",
           "steps": 200, "hyperparams": {"round_steps": 40, "epochs": 2, "batch_size": 16}},
    "dagger-2-worlds": {"algo": "dagger", "env": "town", "obs": "waypoints,measurements", "n_envs": 2,
                        "action": "target_speed", "steps": 200,
                        "hyperparams": {"round_steps": 40, "epochs": 2, "batch_size": 16}},
}  # fmt: skip


def _config(setup: str, name: str, **overrides):
    values = {
        "env": "highway", "obs": "kinematics", "traffic": "regular", "seed": 3, "name": name,
        "eval_every": 50, "eval_episodes": 1, "checkpoint_every": 100, "env_options": {"duration_s": 10},
        **SETUPS[setup], **overrides,
    }  # fmt: skip
    return build_config(values)


def _signal_at(monkeypatch, step: int, signum: int) -> None:
    """The training process sends itself ``signum`` once, in the callback of step ``step``."""
    original = run_module.RunCallback._on_step

    def on_step(self):
        if self.num_timesteps >= step and not getattr(self, "signalled", False):
            self.signalled = True
            os.kill(os.getpid(), signum)
        return original(self)

    monkeypatch.setattr(run_module.RunCallback, "_on_step", on_step)


def _tensors(state, prefix=""):
    """(name, tensor) pairs of a nested state dict (networks and optimizers)."""
    items = state.items() if isinstance(state, dict) else enumerate(state)
    for key, value in items:
        if torch.is_tensor(value):
            yield f"{prefix}{key}", value
        elif isinstance(value, (dict, list, tuple)):
            yield from _tensors(value, f"{prefix}{key}.")


def _parameters(run_dir, config) -> dict:
    agent = checkpoints.load_agent(run_dir, config)
    state = agent._state() if hasattr(agent, "_state") else agent.get_parameters()
    return dict(_tensors(state))


def _monitor(run_dir) -> pd.DataFrame:
    return pd.read_csv(run_dir / "monitor.csv", skiprows=1)


def _progress(run_dir) -> pd.DataFrame:
    """progress.csv's step column, and SB3's rollout count where it logs one (an empty table for a
    run too short to log: dueling_ddqn's rows are 250 steps apart)."""
    if (run_dir / "progress.csv").stat().st_size == 0:
        return pd.DataFrame()
    table = pd.read_csv(run_dir / "progress.csv")
    return table[[column for column in ("time/total_timesteps", "time/iterations") if column in table]]


def _assert_same_run(reference, resumed, config) -> None:
    """Same final parameters (and optimizer state), evaluations and episodes (returns, lengths),
    and one progress.csv with the same rows (steps) as the run never stopped."""
    expected, got = _parameters(reference, config), _parameters(resumed, config)
    assert expected.keys() == got.keys()
    different = [name for name in expected if not torch.equal(expected[name], got[name])]
    assert not different, different
    pd.testing.assert_frame_equal(
        pd.read_csv(reference / "evaluations.csv"), pd.read_csv(resumed / "evaluations.csv")
    )
    pd.testing.assert_frame_equal(_monitor(reference)[["r", "l"]], _monitor(resumed)[["r", "l"]])
    assert _monitor(resumed)["l"].sum() <= config.steps  # no episode counted twice
    pd.testing.assert_frame_equal(_progress(reference), _progress(resumed))
    assert sorted(path.name for path in resumed.glob("progress*.csv")) == ["progress.csv"]


@pytest.mark.parametrize(
    ("setup", "step", "signum", "checkpoint_step"),
    [
        ("dqn", 137, signal.SIGINT, 136),  # DQN's safe points: before every step
        ("ppo", 75, signal.SIGTERM, 64),  # inside the third rollout of 32: back to its start
        ("ppo-2-worlds", 75, signal.SIGINT, 64),
        ("dueling_ddqn", 77, signal.SIGTERM, 76),
        ("ppo_own", 75, signal.SIGINT, 64),
        ("a2c_own", 75, signal.SIGTERM, 64),
        ("ppo_own-4-worlds", 100, signal.SIGINT, 96),  # rollouts of 8 steps x 4 worlds
        ("ppo_own-4-worlds-normalised", 100, signal.SIGTERM, 96),
        ("ppo_own-4-worlds-self-imitation", 100, signal.SIGINT, 96),
        ("a2c_own-3-worlds-beta", 100, signal.SIGINT, 96),  # rollouts of 16 steps x 3 worlds
        ("dueling_ddqn-3-worlds", 77, signal.SIGTERM, 75),  # safe points every 3 steps
        ("rlad", 47, signal.SIGTERM, 46),  # mid-episode, the replay half full
        ("drq", 47, signal.SIGINT, 46),
        ("rlad-fast", 47, signal.SIGTERM, 46),
        ("bc", 95, signal.SIGINT, 80),  # rounds of 40 steps: back to the third round's start
        ("dagger-2-worlds", 95, signal.SIGTERM, 80),
    ],
)
def test_interrupted_and_resumed_run_equals_the_uninterrupted_one(
    tmp_path, monkeypatch, setup, step, signum, checkpoint_step
):
    reference = run_module.train(_config(setup, "reference"), tmp_path)

    handler = signal.getsignal(signum)
    _signal_at(monkeypatch, step, signum)
    with pytest.raises(run_module.TrainingInterrupted, match=f"interrupted at step {checkpoint_step}"):
        run_module.train(_config(setup, "resumed"), tmp_path)
    resumed = tmp_path / "resumed"
    assert json.loads((resumed / "checkpoints/latest.json").read_text())["steps"] == checkpoint_step
    assert signal.getsignal(signum) is handler  # training's handler is gone
    monkeypatch.undo()

    run_module.resume(resumed)
    _assert_same_run(reference, resumed, _config(setup, "reference"))
    assert sorted(p.name for p in (resumed / "checkpoints").glob("resume-*")) == [
        f"resume-{SETUPS[setup]['steps']}.json", f"resume-{SETUPS[setup]['steps']}.npz",
    ]  # fmt: skip


def test_resume_after_a_kill_cuts_the_logs_back_to_the_checkpoint(tmp_path, monkeypatch):
    """A SIGKILL leaves logs and results beyond the last periodic checkpoint: the run is
    simulated by keeping the checkpoint at step 200 of a finished 300-step run (with its
    eval.json). Resuming cuts evaluations.csv, monitor.csv and progress back to step 200, removes
    the stale eval.json and ends exactly as the finished run did."""
    config = _config("dqn", "run")
    run_dir, reference = train_then_kill_back_to(
        monkeypatch, tmp_path, config, 200, then=lambda run_dir: evaluate_run(run_dir, episodes=1)
    )

    calls = []
    learn = run_module._learn

    def inspect_then_learn(model, run_dir, *args):
        calls.append(model.num_timesteps)
        assert not (run_dir / "eval.json").exists()
        assert list(pd.read_csv(run_dir / "evaluations.csv")["step"]) == [50, 100, 150, 200]
        assert _monitor(run_dir)["l"].sum() <= 200
        progress = pd.read_csv(run_dir / "progress.csv")  # continued by the resumed run
        assert progress["time/total_timesteps"].max() <= 200
        return learn(model, run_dir, *args)

    monkeypatch.setattr(run_module, "_learn", inspect_then_learn)
    run_module.resume(run_dir)
    assert calls == [200]
    _assert_same_run(reference, run_dir, config)
    assert list(pd.read_csv(run_dir / "evaluations.csv")["step"]) == [50, 100, 150, 200, 250, 300]


def _files(run_dir) -> dict:
    return {p: p.read_bytes() for p in sorted(run_dir.rglob("*")) if p.is_file()}


def test_resume_checks_everything_before_writing(tmp_path, monkeypatch):
    """A truncated replay or a damaged resume state: one UsageError, the run directory as it was."""
    _signal_at(monkeypatch, 70, signal.SIGINT)
    with pytest.raises(run_module.TrainingInterrupted):
        run_module.train(_config("dqn", "run", steps=120), tmp_path)
    monkeypatch.undo()
    run_dir = tmp_path / "run"
    (run_dir / "eval.json").write_text("{}")  # a stale result resume would remove
    replay = run_dir / "checkpoints/replay.npz"
    data = replay.read_bytes()
    replay.write_bytes(data[: len(data) // 2])
    before = _files(run_dir)
    with pytest.raises(UsageError, match="checkpoint replay .* is missing, truncated or corrupted"):
        run_module.resume(run_dir, steps=200)
    assert _files(run_dir) == before
    replay.write_bytes(data)

    state = run_dir / "checkpoints/resume-69.npz"
    state.write_bytes(state.read_bytes()[:100])
    before = _files(run_dir)
    with pytest.raises(UsageError, match="resume state .* is damaged"):
        run_module.resume(run_dir, steps=200)
    assert _files(run_dir) == before


def test_a_second_signal_stops_at_once_without_a_new_checkpoint(tmp_path, monkeypatch):
    """The first SIGINT asks for a stop at the next step; a second one before it (here: both in
    one callback) stops at once, and the run resumes from its last periodic checkpoint."""
    original = run_module.RunCallback._on_step

    def on_step(self):
        if self.num_timesteps == 130:
            os.kill(os.getpid(), signal.SIGINT)
            os.kill(os.getpid(), signal.SIGINT)
        return original(self)

    monkeypatch.setattr(run_module.RunCallback, "_on_step", on_step)
    with pytest.raises(run_module.TrainingInterrupted, match="interrupted at step 100"):
        run_module.train(_config("dqn", "run", steps=200), tmp_path)
    assert json.loads((tmp_path / "run/checkpoints/latest.json").read_text())["steps"] == 100
