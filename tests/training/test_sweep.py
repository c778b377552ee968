"""Sweeps: grid expansion, per-cell overrides, skip/resume/restart on re-run, pool and Ray."""

import json
import shutil
import zipfile

import pytest
import yaml

from drivelab.errors import UsageError
from drivelab.hyperparams import shipped_hyperparams
from drivelab.training.sweep import expand_sweep, load_sweep, plan, run_sweep

TINY_PPO = {"n_steps": 16, "batch_size": 16, "n_epochs": 1}


def tiny_spec(steps=32, seeds=2, **grid):
    return {
        "base": {
            "algo": "ppo", "env": "highway", "obs": "kinematics", "traffic": "empty", "steps": steps,
            "eval_every": 32, "eval_episodes": 1, "env_options": {"duration_s": 8}, "hyperparams": TINY_PPO,
        },
        "grid": {**grid, "seed": seeds},
        "eval_episodes": 1,
    }  # fmt: skip


def test_grid_expands_with_overrides_and_shipped_hyperparams(tmp_path):
    # 256 steps: one rollout of the shipped PPO's n_steps, the fewest a PPO cell may have
    spec = tiny_spec(steps=256, algo=["ppo", "a2c"], reward=["highway", "highway,right_lane=0"])
    spec["name"] = "abl"
    spec["overrides"] = [
        {"match": {"algo": "a2c"}, "set": {"hyperparams": {"n_steps": 8}}},
        {"match": {"algo": "a2c", "reward": "highway"}, "set": {"steps": 64}},
    ]
    spec["base"]["hyperparams"] = {"learning_rate": 1e-3}
    sweep = expand_sweep(spec, tmp_path)
    configs = {c.config.name: c.config for c in sweep.cells}
    assert list(configs) == [
        "abl-ppo-highway-highway-s0", "abl-ppo-highway-highway-s1",
        "abl-ppo-highway-highway_right_lane_0-s0", "abl-ppo-highway-highway_right_lane_0-s1",
        "abl-a2c-highway-highway-s0", "abl-a2c-highway-highway-s1",
        "abl-a2c-highway-highway_right_lane_0-s0", "abl-a2c-highway-highway_right_lane_0-s1",
    ]  # fmt: skip
    ppo, a2c = configs["abl-ppo-highway-highway-s1"], configs["abl-a2c-highway-highway-s0"]
    assert ppo.seed == 1 and ppo.reward == "highway" and ppo.steps == 256
    # shipped ppo.yaml (gamma 0.8, n_steps 256) under the base's learning_rate
    assert ppo.hyperparams["gamma"] == 0.8 and ppo.hyperparams["n_steps"] == 256
    assert ppo.hyperparams["learning_rate"] == 1e-3
    # shipped a2c.yaml's highway entry (tuned) under the base's learning_rate and the override
    shipped = shipped_hyperparams("a2c", "highway")
    assert a2c.hyperparams == {**shipped, "n_steps": 8, "learning_rate": 1e-3} and a2c.steps == 64
    assert configs["abl-a2c-highway-highway_right_lane_0-s0"].steps == 256
    assert configs["abl-a2c-highway-highway_right_lane_0-s0"].env_options == {"duration_s": 8}


@pytest.mark.parametrize(
    "text, message",
    [
        ("grid: [ppo\n", "malformed YAML"),
        ("- 1\n- 2\n", "must hold a mapping"),
        ("base: {algo: ppo}\n", "non-empty 'grid'"),
        ("grid: {algo: ppo}\n", "axis 'algo' must be a non-empty list"),
        ("grid: {algo: [ppo], colour: [red]}\n", "unknown run field 'colour'"),
        ("grid: {algo: [ppo]}\nrepeat: 2\n", "unknown sweep key 'repeat'"),
        ("grid: {algo: [dqn]}\nbase: {action: continuous}\n", "cannot take 'continuous'"),
        ("grid: {algo: [ppo]}\noverrides: [{match: {env: merge}, set: {steps: 5}}]\n", "not a grid axis"),
        ("grid: {algo: [ppo], reward: [nice]}\n", "unknown reward preset 'nice'"),
        ("grid: {env: [highway]}\n", "need an 'algo'"),
    ],
)
def test_malformed_sweep_files(tmp_path, text, message):
    path = tmp_path / "sweep.yaml"
    path.write_text(text)
    with pytest.raises(UsageError, match=message):
        load_sweep(path, tmp_path / "runs")
    assert not (tmp_path / "runs").exists()


def _manifest_steps(run_dir):
    return json.loads((run_dir / "checkpoints" / "latest.json").read_text())["steps"]


def _learned_from(run_dir) -> int:
    """The step the last training of the run's model started from (SB3's counter)."""
    with zipfile.ZipFile(run_dir / "model.zip") as archive:
        return json.loads(archive.read("sb3.json"))["counters"]["_num_timesteps_at_start"]


def test_rerun_skips_finished_resumes_interrupted_restarts_unstarted(tmp_path):
    runs = tmp_path / "runs"
    sweep = expand_sweep(tiny_spec(steps=32), runs)
    outcomes = run_sweep(sweep, workers=1)  # in this process: the pool is tested below
    assert [(o["name"], o["action"], o["ok"]) for o in outcomes] == [
        ("ppo-highway-s0", "train", True),
        ("ppo-highway-s1", "train", True),
    ]
    s0, s1 = runs / "ppo-highway-s0", runs / "ppo-highway-s1"
    assert _manifest_steps(s0) == 32 and (s0 / "eval.json").is_file() and (s1 / "model.zip").is_file()
    stamp = (s0 / "model.zip").stat().st_mtime_ns

    assert [o["action"] for o in run_sweep(sweep)] == ["skip", "skip"]  # nothing to do: no pool
    assert (s0 / "model.zip").stat().st_mtime_ns == stamp

    longer = expand_sweep(tiny_spec(steps=48), runs)  # a larger budget: same config identity
    # as if s1 stopped before its first checkpoint (no manifest only, beside the model and the
    # checkpoint, is a damaged run: refused, test_sweep_safety.py)
    shutil.rmtree(s1 / "checkpoints")
    (s1 / "model.zip").unlink()
    (s1 / "eval.json").unlink()
    assert [action for _, action in plan(longer)] == ["resume", "restart"]
    before = json.loads((s0 / "eval.json").read_text())["run"]
    (s0 / "eval.json").write_text(json.dumps({"run": before, "stale": True}))
    outcomes = run_sweep(longer, workers=1)
    assert all(o["ok"] for o in outcomes), outcomes
    assert "stale" not in json.loads((s0 / "eval.json").read_text())  # re-evaluated after the resume
    assert _manifest_steps(s0) == 48 and _learned_from(s0) == 32  # continued from 32
    assert _manifest_steps(s1) == 48 and _learned_from(s1) == 0  # trained afresh
    assert [action for _, action in plan(longer)] == ["skip", "skip"]

    (s0 / "eval.json").unlink()
    assert [action for _, action in plan(longer)] == ["evaluate", "skip"]

    other = tiny_spec(steps=48)
    other["base"]["traffic"] = "dense"
    with pytest.raises(UsageError, match="different config"):
        plan(expand_sweep(other, runs))


def test_ctrl_c_stops_an_in_process_sweep_and_a_rerun_resumes_it(tmp_path, monkeypatch):
    """Ctrl-C in the first cell (one worker: in this process) stops the sweep there, checkpointed,
    instead of counting the cell as failed and going on; the re-run resumes it."""
    import os
    import signal

    from drivelab.training import run as run_module

    original = run_module.RunCallback._on_step

    def interrupt_at_20(self):
        if self.num_timesteps == 20:
            os.kill(os.getpid(), signal.SIGINT)
        return original(self)

    runs = tmp_path / "runs"
    sweep = expand_sweep(tiny_spec(steps=32), runs)
    monkeypatch.setattr(run_module.RunCallback, "_on_step", interrupt_at_20)
    with pytest.raises(KeyboardInterrupt):
        run_sweep(sweep, workers=1)
    monkeypatch.undo()
    assert _manifest_steps(runs / "ppo-highway-s0") == 16  # PPO's rollouts: 16 steps
    assert not (runs / "ppo-highway-s1").exists()
    assert [action for _, action in plan(sweep)] == ["resume", "train"]
    assert all(o["ok"] for o in run_sweep(sweep, workers=1))
    assert [action for _, action in plan(sweep)] == ["skip", "skip"]


def test_a_run_stopped_between_its_final_checkpoint_and_its_model_is_finished(tmp_path):
    import shutil

    import torch

    from drivelab.training.checkpoints import load_agent
    from drivelab.training.evaluate import load_run_config

    runs = tmp_path / "runs"
    sweep = expand_sweep(tiny_spec(steps=32, seeds=1), runs)
    run_sweep(sweep, workers=1)
    run_dir = runs / "ppo-highway-s0"
    shutil.copy(run_dir / "model.zip", tmp_path / "first.zip")
    for name in ("model.zip", "eval.json", "learning_curve.png"):
        (run_dir / name).unlink()  # as if killed after the final checkpoint
    assert [action for _, action in plan(sweep)] == ["resume"]
    assert all(o["ok"] for o in run_sweep(sweep, workers=1))
    assert (run_dir / "eval.json").is_file() and (run_dir / "learning_curve.png").is_file()
    assert _manifest_steps(run_dir) == 32
    config = load_run_config(run_dir)
    again = load_agent(run_dir, config).policy.state_dict()
    first = load_agent(run_dir, config, path=tmp_path / "first.zip").policy.state_dict()
    assert again.keys() == first.keys() and all(torch.equal(again[k], first[k]) for k in first)


def test_a_run_killed_between_its_model_and_its_learning_curve_is_finished(tmp_path):
    """Killed after model.zip was saved, before learning_curve.png was drawn (found by SIGKILL of a
    sweep's process group): the re-run draws the curve and evaluates the run, without training it
    again, instead of skipping it as finished without the curve that the run never stopped has."""
    runs = tmp_path / "runs"
    sweep = expand_sweep(tiny_spec(steps=32, seeds=1), runs)
    run_sweep(sweep, workers=1)
    run_dir = runs / "ppo-highway-s0"
    evaluation = json.loads((run_dir / "eval.json").read_text())["per_episode"]
    model = (run_dir / "model.zip").stat().st_mtime_ns
    (run_dir / "learning_curve.png").unlink()
    (run_dir / "eval.json").unlink()  # the sweep evaluates after the curve: none yet either
    assert [action for _, action in plan(sweep)] == ["finish"]
    assert [(o["action"], o["ok"]) for o in run_sweep(sweep, workers=1)] == [("finish", True)]
    assert (run_dir / "learning_curve.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert not (run_dir / "learning_curve.tmp.png").exists()  # drawn beside it, then renamed
    assert json.loads((run_dir / "eval.json").read_text())["per_episode"] == evaluation
    assert (run_dir / "model.zip").stat().st_mtime_ns == model
    assert [action for _, action in plan(sweep)] == ["skip"]


def test_two_cells_of_one_config_are_refused(tmp_path):
    spec = tiny_spec(seeds=1, env=["highway", "drivelab/Highway-v0"])  # one scenario, two names
    with pytest.raises(UsageError, match="are the same run"):
        expand_sweep(spec, tmp_path / "runs")


def test_hyperparameters_an_agent_refuses_stop_the_sweep_before_any_run(tmp_path):
    spec = tiny_spec(seeds=1, algo=["ppo", "a2c"])  # A2C has no batch_size
    with pytest.raises(UsageError, match="unknown hyperparameter 'batch_size' for 'a2c'"):
        expand_sweep(spec, tmp_path / "runs")
    spec = tiny_spec(seeds=1)
    spec["base"]["hyperparams"] = {**TINY_PPO, "learning_rate": -1}
    with pytest.raises(UsageError, match="learning_rate"):
        expand_sweep(spec, tmp_path / "runs")
    assert list(tmp_path.iterdir()) == []


def test_failed_cell_is_reported_and_others_finish(tmp_path, monkeypatch):
    """A cell that fails while it runs (a full disk, a diverging agent: here A2C's unknown
    batch_size, let through the up-front check) is reported; the others finish."""
    import drivelab.training.run

    spec = tiny_spec(seeds=1, algo=["ppo", "a2c"])
    monkeypatch.setattr(drivelab.training.run, "check_config", lambda config: None)
    sweep = expand_sweep(spec, tmp_path)
    monkeypatch.undo()
    outcomes = run_sweep(sweep, workers=2)
    by_name = {o["name"]: o for o in outcomes}
    assert by_name["ppo-highway-s0"]["ok"] and (tmp_path / "ppo-highway-s0" / "model.zip").is_file()
    failed = by_name["a2c-highway-s0"]
    assert not failed["ok"] and "unknown hyperparameter 'batch_size' for 'a2c'" in failed["error"]
    assert "batch_size" in (tmp_path / ".sweep-logs" / "a2c-highway-s0.log").read_text()
    assert not (tmp_path / "a2c-highway-s0").exists()


def test_two_run_grid_through_ray_matches_local_runs(tmp_path):
    pytest.importorskip("ray")
    spec = tiny_spec(steps=32)
    ray_runs, pool_runs = tmp_path / "ray", tmp_path / "pool"
    outcomes = run_sweep(expand_sweep(spec, ray_runs), executor="ray", workers=2)
    assert [(o["name"], o["ok"]) for o in outcomes] == [("ppo-highway-s0", True), ("ppo-highway-s1", True)]
    run_sweep(expand_sweep(spec, pool_runs), executor="pool", workers=1)  # in-process reference
    for name in ("ppo-highway-s0", "ppo-highway-s1"):
        ray_dir, pool_dir = ray_runs / name, pool_runs / name
        assert sorted(p.name for p in ray_dir.iterdir() if "tfevents" not in p.name) == sorted(
            p.name for p in pool_dir.iterdir() if "tfevents" not in p.name
        )
        assert yaml.safe_load((ray_dir / "config.yaml").read_text()) == yaml.safe_load(
            (pool_dir / "config.yaml").read_text()
        )
        # same seed, one thread: the same training and evaluation either way
        assert (ray_dir / "evaluations.csv").read_text() == (pool_dir / "evaluations.csv").read_text()
        ray_eval = json.loads((ray_dir / "eval.json").read_text())
        pool_eval = json.loads((pool_dir / "eval.json").read_text())
        assert ray_eval["per_episode"] == pool_eval["per_episode"]
    assert [o["action"] for o in run_sweep(expand_sweep(spec, ray_runs), executor="ray")] == ["skip", "skip"]


@pytest.mark.parametrize("command", ["sweep", "tune"])
@pytest.mark.parametrize("address", ["127.0.0.1:{port}", "ray://127.0.0.1:{port}", "bogus"])
def test_a_ray_cluster_that_cannot_be_joined_is_one_line_and_writes_nothing(tmp_path, command, address):
    """Ray retried an address where nothing answers for minutes (host:port) or 30 s (ray://), and
    any failure to join came after the runs folder was made and the progress bar drawn, with Ray's
    messages: now one error line, at once, and nothing written."""
    import socket

    from typer.testing import CliRunner

    from drivelab.cli import app

    pytest.importorskip("ray")
    with socket.socket() as probe:  # a port nothing listens on once it is closed
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    address = address.format(port=port)
    if command == "sweep":
        (tmp_path / "sweep.yaml").write_text(yaml.safe_dump(tiny_spec()))
        args = ["sweep", str(tmp_path / "sweep.yaml"), "--runs-dir", str(tmp_path / "out")]
    else:
        study = {**tiny_spec()["base"], "space": {"gamma": {"type": "float", "low": 0.8, "high": 0.9}}}
        (tmp_path / "study.yaml").write_text(yaml.safe_dump({**study, "n_trials": 1}))
        args = ["tune", str(tmp_path / "study.yaml"), "--study-dir", str(tmp_path / "out")]
    result = CliRunner().invoke(app, [*args, "--executor", "ray", "--workers", "1", "--address", address])
    assert result.exit_code == 2, result.output
    (line,) = result.output.splitlines()
    assert line.startswith(f"error: cannot join the Ray cluster at {address!r}: "), line
    if address != "bogus":
        assert "nothing answers at 127.0.0.1" in line
    assert not (tmp_path / "out").exists()


def test_cli_sweep_bad_file_and_dry_run(tmp_path):
    from typer.testing import CliRunner

    from drivelab.cli import app

    runner = CliRunner()
    bad = tmp_path / "bad.yaml"
    bad.write_text("grid: {algo: [ppo], colour: [red]}\n")
    result = runner.invoke(app, ["sweep", str(bad), "--runs-dir", str(tmp_path / "runs")])
    assert (
        result.exit_code == 2 and result.output.strip() == "error: sweep grid has unknown run field 'colour'"
    )
    good = tmp_path / "good.yaml"
    good.write_text(yaml.safe_dump(tiny_spec()))
    result = runner.invoke(app, ["sweep", str(good), "--runs-dir", str(tmp_path / "runs"), "--dry-run"])
    assert result.exit_code == 0
    assert result.output.split() == ["train", str(tmp_path / "runs" / "ppo-highway-s0"),
                                     "train", str(tmp_path / "runs" / "ppo-highway-s1")]  # fmt: skip
    result = runner.invoke(app, ["sweep", str(good), "--executor", "dask"])
    assert result.exit_code == 2 and "unknown executor 'dask'" in result.output
    assert not (tmp_path / "runs").exists()
