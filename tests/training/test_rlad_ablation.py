"""benchmarks/rlad_ablation.py in slices: runs stopped after some steps or at a time limit continue
when the same command runs again, and end as the uninterrupted runs do (tiny town runs)."""

import importlib.util
import time
from pathlib import Path

import pytest
import torch

from drivelab.training import checkpoints
from drivelab.training.evaluate import load_run_config
from drivelab.training.sweep import expand_sweep

pytestmark = pytest.mark.usefixtures("one_torch_thread")
SCRIPT = Path(__file__).parents[2] / "benchmarks" / "rlad_ablation.py"
STEPS = 40


@pytest.fixture(scope="module")
def ablation():
    spec = importlib.util.spec_from_file_location("rlad_ablation", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


BASE = {
    "algo": "rlad", "env": "town", "action": "target_speed", "reward": "roach", "traffic": "empty",
    "obs": ["camera:width=24:height=24:stack=3", "waypoints", "measurements:stack=3"],
    "steps": STEPS, "eval_every": 20, "eval_episodes": 1, "checkpoint_every": 10,
    "env_options": {"duration_s": 3},
    "hyperparams": {"learning_starts": 8, "batch_size": 4, "buffer_size": 64, "hidden_size": 32,
                    "log_interval": 10},
}  # fmt: skip
DRQ = {"alix": False, "aux": False, "waypoint_encoder": "mlp"}


def _sweep(runs_dir):
    spec = {
        "runs_dir": str(runs_dir),
        "eval_episodes": 1,
        "base": BASE,
        "grid": {"hyperparams": [{}, DRQ], "seed": 1},
    }
    return expand_sweep(spec)


def _parameters(run_dir):
    agent = checkpoints.load_agent(run_dir, load_run_config(run_dir))
    return {key: value for key, value in agent._state().items() if key in ("encoder", "actor", "critic")}


def _assert_same_runs(sweep, reference):
    for cell in sweep.cells:
        got = _parameters(sweep.runs_dir / cell.config.name)
        expected = _parameters(reference / cell.config.name)
        for module in expected:
            for name, tensor in expected[module].items():
                assert torch.equal(got[module][name], tensor), (cell.config.name, module, name)
        assert (sweep.runs_dir / cell.config.name / "eval.json").is_file()


def test_stopped_runs_continue_as_the_straight_runs(tmp_path, ablation):
    """Stopped after some steps, or at a time limit, then the same call again: the runs end with
    the parameters of the same runs made straight through."""
    straight = _sweep(tmp_path / "straight")
    names = sorted(c.config.name for c in straight.cells)
    assert [ablation.variant(c) for c in straight.cells] == ["RLAD", "DrQ"]
    assert sorted(ablation.run_slice(straight, workers=1)["finished"]) == names

    # --stop-after-steps 25: both runs stop at 25 (no final evaluation yet), then finish
    sweep = _sweep(tmp_path / "steps")
    first = ablation.run_slice(sweep, workers=1, stop_after_steps=25)
    assert sorted(first["stopped"]) == names and not first["finished"] and not first["failed"]
    assert {ablation.checkpoint_steps(sweep.runs_dir / n) for n in names} == {25}
    assert not any((sweep.runs_dir / n / "eval.json").exists() for n in names)
    second = ablation.run_slice(sweep, workers=1, stop_after_steps=25)
    assert sorted(second["finished"]) == names and not second["stopped"]
    assert {ablation.checkpoint_steps(sweep.runs_dir / n) for n in names} == {STEPS}
    _assert_same_runs(sweep, straight.runs_dir)
    assert sorted(ablation.run_slice(sweep, workers=1)["finished"]) == names  # a third time: nothing to do

    # --time-limit-s: the first run is stopped at its first safe point after 0.5 s (building it
    # takes longer), with a checkpoint; the second is not started
    sweep = _sweep(tmp_path / "time")
    first = ablation.run_slice(sweep, workers=1, deadline=time.time() + 0.5)
    assert sorted(first["stopped"]) == names and not first["failed"]
    started, waiting = (sweep.runs_dir / c.config.name for c in sweep.cells)
    assert (started / "checkpoints" / "latest.json").is_file()  # written on the way out
    assert ablation.checkpoint_steps(started) < STEPS and not (started / "model.zip").exists()
    assert not waiting.exists()
    second = ablation.run_slice(sweep, workers=1)
    assert sorted(second["finished"]) == names
    _assert_same_runs(sweep, straight.runs_dir)


def test_a_slice_shorter_than_eval_every_trains_and_stops(tmp_path, ablation):
    """``--stop-after-steps`` below the runs' eval_every (5000 in the real sweep): the new runs train
    that slice (a run of fewer steps than its eval_every, resumed later), they are not refused."""
    spec = {"runs_dir": str(tmp_path / "runs"), "eval_episodes": 1, "base": BASE, "grid": {"seed": 1}}
    sweep = expand_sweep(spec)
    (name,) = [c.config.name for c in sweep.cells]
    status = ablation.run_slice(sweep, workers=1, stop_after_steps=15)  # eval_every is 20
    assert status == {"finished": [], "stopped": [name], "failed": []}
    assert ablation.checkpoint_steps(sweep.runs_dir / name) == 15
