"""Reward ablations: the variants, refusing bad input, and one tiny ablation end to end."""

import csv

import pytest
import yaml
from typer.testing import CliRunner

from drivelab.cli import _split_rewards, app
from drivelab.errors import UsageError
from drivelab.training.ablate import reward_variants

runner = CliRunner()


def test_drop_terms_make_one_variant_per_term():
    assert reward_variants(None, ["right_lane", "collision"], "highway") == [
        "highway",
        "highway,right_lane=0",
        "highway,collision=0",
    ]
    assert reward_variants(["highway", "metadrive_course"], None, "highway") == [
        "highway",
        "metadrive_course",
    ]


@pytest.mark.parametrize(
    "rewards, drops, message",
    [
        (None, ["on_road"], "cannot drop 'on_road': the reward 'highway' has the terms collision"),
        (None, ["wings"], "cannot drop 'wings'"),
        (["highway"], ["collision"], "exactly one of"),
        (None, None, "exactly one of"),
        (["highway", "nice"], None, "unknown reward preset 'nice'"),
        (None, ["collision", "collision"], "lists a term twice"),
    ],
)
def test_bad_ablations(rewards, drops, message):
    with pytest.raises(UsageError, match=message):
        reward_variants(rewards, drops, "highway")


def test_rewards_option_splitting():
    assert _split_rewards(["highway,metadrive_course"]) == ["highway", "metadrive_course"]
    assert _split_rewards(["highway,right_lane=0,metadrive_course"]) == [
        "highway,right_lane=0",
        "metadrive_course",
    ]
    assert _split_rewards(["collision=-1,high_speed=0.4;crash=-5"]) == [
        "collision=-1,high_speed=0.4",
        "crash=-5",
    ]
    assert _split_rewards(["highway", "safety_dqn"]) == ["highway", "safety_dqn"]


def test_cli_unknown_term_exits_2_and_writes_nothing(tmp_path):
    result = runner.invoke(
        app,
        ["ablate", "--algo", "ppo", "--drop-terms", "wings", "--runs-dir", str(tmp_path / "runs"),
         "-o", str(tmp_path / "report")],
    )  # fmt: skip
    assert result.exit_code == 2
    assert (
        result.output.startswith("error: cannot drop 'wings'")
        and len(result.output.strip().splitlines()) == 1
    )
    assert list(tmp_path.iterdir()) == []


def test_tiny_ablation_end_to_end(tmp_path):
    config = tmp_path / "base.yaml"
    config.write_text(
        yaml.safe_dump(
            {"traffic": "empty", "eval_every": 32, "eval_episodes": 1, "env_options": {"duration_s": 8},
             "hyperparams": {"n_steps": 16, "batch_size": 16, "n_epochs": 1}}
        )
    )  # fmt: skip
    args = ["ablate", "--algo", "ppo", "--env", "highway", "--drop-terms", "right_lane", "--seeds", "1",
            "--steps", "32", "--eval-episodes", "1", "--config", str(config), "--workers", "2",
            "--runs-dir", str(tmp_path / "runs"), "-o", str(tmp_path / "report")]  # fmt: skip
    result = runner.invoke(app, args)
    assert result.exit_code == 0, result.output
    runs = sorted(p.name for p in (tmp_path / "runs").iterdir() if not p.name.startswith("."))
    assert runs == ["ablate-ppo-highway-highway-s0", "ablate-ppo-highway-highway_right_lane_0-s0"]
    saved = yaml.safe_load((tmp_path / "runs" / runs[1] / "config.yaml").read_text())
    assert saved["reward"] == "highway,right_lane=0" and saved["steps"] == 32
    with (tmp_path / "report" / "summary.csv").open() as handle:
        rewards = {row["reward"] for row in csv.DictReader(handle)}
    assert rewards == {"highway", "highway,right_lane=0"}
    assert (
        "Reward ablation: ppo on highway, dropping right_lane"
        in (tmp_path / "report" / "report.md").read_text()
    )
    again = runner.invoke(app, args)  # a re-run trains nothing
    assert again.exit_code == 0 and again.output.count("skip") == 2
