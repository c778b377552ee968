"""Run directories: train, evaluate, checkpoints, Ctrl-C and resume (tiny step counts)."""

import json
import os
import signal
import zipfile

import pytest

from drivelab.config import build_config
from drivelab.errors import UsageError
from drivelab.training import checkpoints
from drivelab.training import run as run_module
from drivelab.training.evaluate import evaluate_run

FAST_ENV = {"duration_s": 8}


def _config(**overrides):
    values = {
        "algo": "ppo",
        "env": "highway",
        "obs": "kinematics",
        "traffic": "empty",
        "steps": 64,
        "seed": 1,
        "name": "tiny",
        "eval_every": 32,
        "eval_episodes": 1,
        "hyperparams": {"n_steps": 32, "batch_size": 16, "n_epochs": 1},
        "env_options": FAST_ENV,
    }
    values.update(overrides)
    return build_config(values)


def test_train_writes_a_complete_run_directory(tmp_path, capsys):
    run_dir = run_module.train(_config(), tmp_path)
    for name in (
        "config.yaml",
        "progress.csv",
        "monitor.csv",
        "evaluations.csv",
        "model.zip",
        "learning_curve.png",
        "checkpoints/latest.zip",
        "checkpoints/latest.json",
    ):
        assert (run_dir / name).is_file(), name
    assert any(run_dir.glob("events.out.tfevents.*"))
    manifest = json.loads((run_dir / "checkpoints/latest.json").read_text())
    assert manifest["steps"] == 64
    evaluations = (run_dir / "evaluations.csv").read_text().strip().splitlines()
    assert len(evaluations) == 3  # header + evaluations at 32 and 64 steps
    header = json.loads((run_dir / "monitor.csv").read_text().splitlines()[0][1:])
    assert header["env_id"] == "highway"  # the scenario (SB3's Monitor wrote "None": no env spec)

    capsys.readouterr()
    report = evaluate_run(run_dir, episodes=2, video=True, progress=True)
    bar = capsys.readouterr().err  # the episodes' progress bar
    assert "evaluate ppo: 100%" in bar and "2/2" in bar
    assert report["episodes"] == 2
    assert 0.0 <= report["success_rate"] <= 1.0 and 0.0 <= report["crash_rate"] <= 1.0
    saved = json.loads((run_dir / "eval.json").read_text())
    assert {
        "mean_return",
        "std_return",
        "collisions_per_km",
        "off_road_per_km",
        "mean_speed_mps",
    } <= saved.keys()
    assert len(saved["per_episode"]) == 2
    assert (run_dir / "videos").is_dir() and any((run_dir / "videos").iterdir())


def test_existing_run_name_is_refused(tmp_path):
    (tmp_path / "tiny").mkdir()
    with pytest.raises(UsageError, match="already exists"):
        run_module.train(_config(), tmp_path)


def test_interrupt_saves_checkpoint_and_resume_continues(tmp_path, monkeypatch):
    """SIGINT in step 48 stops before the step changes anything learned: the checkpoint is the
    state before it (47 steps); resume continues to the total, then with a larger --steps."""
    original = run_module.RunCallback._on_step

    def interrupt_at_48(self):
        if self.num_timesteps == 48:
            os.kill(os.getpid(), signal.SIGINT)
        return original(self)

    monkeypatch.setattr(run_module.RunCallback, "_on_step", interrupt_at_48)
    with pytest.raises(run_module.TrainingInterrupted, match="interrupted at step 47"):
        run_module.train(
            _config(
                steps=96, algo="dqn", action="meta", hyperparams={"learning_starts": 8, "buffer_size": 500}
            ),
            tmp_path,
        )
    run_dir = tmp_path / "tiny"
    manifest = json.loads((run_dir / "checkpoints/latest.json").read_text())
    assert manifest["steps"] == 47 and manifest["replay_buffer"] is True
    assert not (run_dir / "model.zip").exists()

    monkeypatch.setattr(run_module.RunCallback, "_on_step", original)
    run_module.resume(run_dir)
    manifest = json.loads((run_dir / "checkpoints/latest.json").read_text())
    assert manifest["steps"] == 96
    assert (run_dir / "model.zip").is_file()

    with pytest.raises(UsageError, match="already has 96 steps"):
        run_module.resume(run_dir)
    evaluate_run(run_dir, episodes=1)
    run_module.resume(run_dir, steps=112)
    assert json.loads((run_dir / "checkpoints/latest.json").read_text())["steps"] == 112
    assert not (run_dir / "eval.json").exists()  # it described the 96-step model
    steps = [int(line.split(",")[0]) for line in (run_dir / "evaluations.csv").read_text().splitlines()[1:]]
    assert steps == [32, 64, 96]  # once each, the next evaluation is due at 128


def test_a_run_killed_before_its_first_checkpoint_trains_again_on_resume(tmp_path, monkeypatch):
    """Killed (SIGKILL, power cut) before its first checkpoint, a run holds its config and logs
    and nothing to continue from: resume trains it again from step 0, to the model of a run that
    was never stopped."""
    import torch

    whole = run_module.train(_config(name="whole"), tmp_path)

    class Killed(BaseException):
        pass

    def killed(*args, **kwargs):
        raise Killed

    monkeypatch.setattr(run_module, "save_checkpoint", killed)
    with pytest.raises(Killed):
        run_module.train(_config(), tmp_path)
    monkeypatch.undo()
    run_dir = tmp_path / "tiny"
    assert (run_dir / "config.yaml").is_file() and (run_dir / "monitor.csv").is_file()
    assert not (run_dir / "checkpoints" / "latest.json").exists() and not (run_dir / "model.zip").exists()

    run_module.resume(run_dir)
    assert json.loads((run_dir / "checkpoints/latest.json").read_text())["steps"] == 64
    config = _config()
    again = checkpoints.load_agent(run_dir, config).policy.state_dict()
    reference = checkpoints.load_agent(whole, config).policy.state_dict()
    assert again.keys() == reference.keys()
    assert all(torch.equal(again[key], reference[key]) for key in reference)
    assert (run_dir / "monitor.csv").read_text().count("\n") == (whole / "monitor.csv").read_text().count(
        "\n"
    )


def test_a_checkpoint_killed_between_its_renames_is_finished_on_resume(tmp_path, monkeypatch):
    """Killed after the new model was renamed over latest.zip but before the replay and the
    manifest were (the old manifest then names another file's checksum): resume finishes the
    renames, and the run, stopped after its last checkpoint, gets the model of a run never stopped."""
    import torch

    config = _config(steps=64, checkpoint_every=32, algo="dqn", action="meta",
                     hyperparams={"learning_starts": 8, "buffer_size": 500})  # fmt: skip
    whole = run_module.train(build_config({**config.to_dict(), "name": "whole"}), tmp_path)

    class Killed(BaseException):
        pass

    real_replace, committed = os.replace, []

    def replace(source, target):
        if os.path.basename(source) == "replay.tmp.npz" and committed:
            raise Killed  # the second checkpoint: latest.zip is new, replay and manifest are not
        real_replace(source, target)
        if os.path.basename(source) == "latest.tmp.json":
            committed.append(target)

    monkeypatch.setattr(os, "replace", replace)
    with pytest.raises(Killed):
        run_module.train(config, tmp_path)
    monkeypatch.undo()
    folder = tmp_path / "tiny" / "checkpoints"
    assert json.loads((folder / "latest.json").read_text())["steps"] == 32
    assert (folder / "latest.tmp.json").is_file() and (folder / "replay.tmp.npz").is_file()

    run_module.resume(tmp_path / "tiny")
    manifest = json.loads((folder / "latest.json").read_text())
    assert manifest["steps"] == 64 and manifest["replay_buffer"]
    assert not (folder / "latest.tmp.json").exists() and not (folder / "replay.tmp.npz").exists()
    again = checkpoints.load_agent(tmp_path / "tiny", config).policy.state_dict()
    reference = checkpoints.load_agent(whole, config).policy.state_dict()
    assert all(torch.equal(again[key], reference[key]) for key in reference)


def test_corrupted_or_foreign_checkpoint_is_refused(tmp_path):
    run_dir = run_module.train(_config(steps=32), tmp_path)
    checkpoint = run_dir / "checkpoints/latest.zip"
    data = checkpoint.read_bytes()
    checkpoint.write_bytes(data[: len(data) // 2])
    with pytest.raises(UsageError, match="truncated or corrupted"):
        run_module.resume(run_dir, steps=64)
    checkpoint.write_bytes(data)

    (run_dir / "checkpoints/latest.json").write_text("{not json")
    with pytest.raises(UsageError, match="manifest .* is corrupted"):
        run_module.resume(run_dir, steps=64)

    config_text = (run_dir / "config.yaml").read_text()
    (run_dir / "checkpoints/latest.json").write_text(
        json.dumps({"sha256": checkpoints.file_sha256(checkpoint), "config_identity": "other", "steps": 32})
    )
    with pytest.raises(UsageError, match="different config"):
        run_module.resume(run_dir, steps=64)
    assert (run_dir / "config.yaml").read_text() == config_text  # nothing rewritten on refusal


def test_on_policy_training_on_several_worlds(tmp_path):
    """n_envs = 4: PPO collects from 4 batched fast worlds; steps count every world's steps,
    monitor.csv gets every world's episodes, and resume continues on 4 worlds."""
    config = _config(
        n_envs=4, steps=128, eval_every=64, hyperparams={"n_steps": 16, "batch_size": 32, "n_epochs": 1}
    )
    run_dir = run_module.train(config, tmp_path)
    manifest = json.loads((run_dir / "checkpoints/latest.json").read_text())
    assert manifest["steps"] == 128
    episodes = (run_dir / "monitor.csv").read_text().strip().splitlines()[2:]
    assert len(episodes) >= 4  # 8 s episodes of 1 s steps: every world finished some
    with zipfile.ZipFile(run_dir / "model.zip") as archive:
        assert json.loads(archive.read("sb3.json"))["n_envs"] == 4
    run_module.resume(run_dir, steps=192)
    assert json.loads((run_dir / "checkpoints/latest.json").read_text())["steps"] == 192
    assert len((run_dir / "monitor.csv").read_text().strip().splitlines()[2:]) > len(episodes)


def test_n_envs_is_refused_for_single_world_agents(tmp_path):
    with pytest.raises(UsageError, match="trains in one world: n_envs must be 1"):
        run_module.train(
            _config(algo="qlearning", env="follow-line", action="seed_line", obs="line", n_envs=2), tmp_path
        )
    assert not any(tmp_path.iterdir())
    with pytest.raises(UsageError, match="'n_envs' must be >= 1"):
        _config(n_envs=0)
