"""``drivelab evaluate RUN --maps START:COUNT``: a blocks run evaluated on another map set (its
training maps, or unseen ones), written to ``eval-maps-START-COUNT.json`` beside eval.json."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest
from typer.testing import CliRunner

from drivelab.cli import app

runner = CliRunner()


@pytest.fixture(scope="module")
def trained(tmp_path_factory) -> Path:
    """A 64-step PPO run on blocks (maps 0 … 3), checkpointed at 32 steps, with eval maps 1000:2."""
    runs = tmp_path_factory.mktemp("blocks-runs")
    config = runs / "maps.yaml"
    config.write_text("env_options: {backend_options: {map: 2, start_seed: 0, num_scenarios: 4}}\n")
    args = ["train", "--algo", "ppo", "--env", "blocks", "--obs", "lidar:beams=16", "--action", "continuous",
            "--steps", "64", "-H", "n_steps=32", "-H", "batch_size=32", "--eval-every", "64",
            "--eval-episodes", "1", "--checkpoint-every", "32", "--eval-maps", "1000:2",
            "--config", str(config), "--runs-dir", str(runs), "--name", "tiny"]  # fmt: skip
    result = runner.invoke(app, args)
    assert result.exit_code == 0, result.output
    return runs / "tiny"


@pytest.fixture
def run_dir(tmp_path, trained) -> Path:
    return Path(shutil.copytree(trained, tmp_path / "tiny"))


def played_maps(monkeypatch) -> list[int]:
    """The map seed of each episode the next evaluation plays (filled as it runs)."""
    import drivelab.training.evaluate as evaluate

    seeds, original = [], evaluate.run_episodes

    def recording(policy, env, episodes, on_episode=None, **kwargs):
        def record(metrics):
            seeds.append(env.vector.simulator.map_of(0).pg.seed)
            if on_episode is not None:  # evaluate's progress bar
                on_episode(metrics)

        return original(policy, env, episodes, on_episode=record, **kwargs)

    monkeypatch.setattr(evaluate, "run_episodes", recording)
    return seeds


def test_maps_plays_each_map_of_the_set_once(run_dir, monkeypatch):
    seeds = played_maps(monkeypatch)
    result = runner.invoke(app, ["evaluate", str(run_dir), "--episodes", "4", "--maps", "0:4"])
    assert result.exit_code == 0, result.output
    assert "eval-maps-0-4.json written" in result.output
    assert sorted(seeds) == [0, 1, 2, 3]  # 4 episodes on 4 maps: each map once
    report = json.loads((run_dir / "eval-maps-0-4.json").read_text())
    assert report["maps"] == "0:4" and report["episodes"] == 4 and len(report["per_episode"]) == 4
    assert not (run_dir / "eval.json").exists()


def test_maps_evaluate_the_latest_checkpoint_of_an_unfinished_run(run_dir, monkeypatch):
    (run_dir / "model.zip").unlink()  # stopped before its end: its latest checkpoint is evaluated
    seeds = played_maps(monkeypatch)
    result = runner.invoke(app, ["evaluate", str(run_dir), "--episodes", "2", "--maps", "0:2"])
    assert result.exit_code == 0, result.output
    assert sorted(seeds) == [0, 1]
    assert json.loads((run_dir / "eval-maps-0-2.json").read_text())["episodes"] == 2


def test_without_maps_the_runs_eval_maps_are_played(run_dir, monkeypatch):
    seeds = played_maps(monkeypatch)
    result = runner.invoke(app, ["evaluate", str(run_dir), "--episodes", "2"])
    assert result.exit_code == 0, result.output
    assert sorted(seeds) == [1000, 1001]
    assert "maps" not in json.loads((run_dir / "eval.json").read_text())


@pytest.mark.parametrize(
    ("maps", "message"),
    [("5", "eval_maps must be START:COUNT"), ("3:0", "eval_maps must be START:COUNT"),
     ("-1:4", "eval_maps must be START:COUNT")],
)  # fmt: skip
def test_bad_maps_are_one_error_line_and_write_nothing(run_dir, maps, message):
    before = sorted(p.name for p in run_dir.iterdir())
    result = runner.invoke(app, ["evaluate", str(run_dir), "--episodes", "1", "--maps", maps])
    lines = result.output.strip().splitlines()
    assert result.exit_code == 2 and len(lines) == 1, result.output
    assert lines[0].startswith("error: ") and message in lines[0]
    assert sorted(p.name for p in run_dir.iterdir()) == before


def test_maps_refused_for_a_single_road_run(tmp_path):
    args = ["train", "--algo", "dqn", "--traffic", "empty", "--steps", "20", "--eval-every", "20",
            "--eval-episodes", "1", "--runs-dir", str(tmp_path), "--name", "highway"]  # fmt: skip
    assert runner.invoke(app, args).exit_code == 0
    before = sorted(p.name for p in (tmp_path / "highway").iterdir())
    result = runner.invoke(app, ["evaluate", str(tmp_path / "highway"), "--maps", "0:2"])
    assert result.exit_code == 2
    assert result.output.strip() == "error: eval_maps is for procedural maps (blocks); 'highway' has one road"
    assert sorted(p.name for p in (tmp_path / "highway").iterdir()) == before


def test_resume_removes_the_older_models_map_evaluations(run_dir):
    result = runner.invoke(app, ["evaluate", str(run_dir), "--episodes", "1", "--maps", "0:1"])
    assert result.exit_code == 0, result.output
    assert (run_dir / "eval-maps-0-1.json").is_file()
    result = runner.invoke(app, ["train", "--resume", str(run_dir), "--steps", "96"])
    assert result.exit_code == 0, result.output
    assert not (run_dir / "eval-maps-0-1.json").exists()  # it evaluated the 64-step model
