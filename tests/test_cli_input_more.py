"""More bad input of the command line: each is one ``error:`` line and exit code 2, no traceback,
and the working folder exactly as it was (CliRunner, in-process)."""

from __future__ import annotations

import hashlib
from pathlib import Path

import pytest
import yaml
from typer.testing import CliRunner

from drivelab.cli import app
from tests.test_bad_input import snapshot

runner = CliRunner()


def assert_refused(root: Path, args: list[str], line: str) -> None:
    """``drivelab ARGS``: exit 2, exactly the one line ``line``, nothing under ``root`` changed."""
    before = snapshot(root)
    result = runner.invoke(app, [str(arg) for arg in args])
    assert result.exit_code == 2, result.output
    assert result.output.splitlines() == [line]
    assert snapshot(root) == before


ABLATE = ["ablate", "--algo", "ppo", "--drop-terms", "right_lane", "--seeds", "1", "--steps", "64"]


@pytest.mark.parametrize(("text", "kind"), [("hyperparams: [1, 2]\n", "list"), ("hyperparams: 3\n", "int")])
def test_ablate_config_hyperparams_not_a_mapping(work, text, kind):
    (work / "a.yaml").write_text(text)
    args = [*ABLATE, "--config", "a.yaml", "-H", "gamma=0.9", "--runs-dir", "runs"]
    assert_refused(work, args, f"error: config field 'hyperparams' must be a mapping, got {kind}")


def test_ablate_config_hyperparams_null_takes_the_h_values(work, monkeypatch):
    from drivelab.training import ablate

    given = {}

    def fake_ablate(env, algo, base, **_):
        given.update(base)
        return work / "report", []

    monkeypatch.setattr(ablate, "ablate", fake_ablate)
    (work / "a.yaml").write_text("hyperparams:\n")
    result = runner.invoke(app, [*ABLATE, "--config", "a.yaml", "-H", "gamma=0.9", "--runs-dir", "runs"])
    assert result.exit_code == 0, result.output
    assert given == {"hyperparams": {"gamma": 0.9}}


@pytest.fixture
def no_lane_training(monkeypatch):
    """train-lane must refuse before it generates a frame."""
    from drivelab.training import lane_dataset

    monkeypatch.setattr(lane_dataset, "generate_lane_frames", lambda *_: pytest.fail("frames generated"))
    monkeypatch.setattr(lane_dataset, "available_memory_bytes", lambda: 16 * 2**30, raising=False)


@pytest.mark.parametrize(
    ("args", "line"),
    [
        (["--out", "weights"], "error: --out 'weights' must name a .pt file (the lane CNN's weights)"),
        (["--out", "w.txt"], "error: --out 'w.txt' must name a .pt file (the lane CNN's weights)"),
        (
            ["--out", "missing/x/w.pt"],
            "error: cannot write --out 'missing/x/w.pt': folder 'missing/x' does not exist",
        ),
        (["--seed", "-1"], "error: --seed must be >= 0, got -1"),
        (["--frames", "0"], "error: --frames and --epochs must be >= 1"),
        (
            ["--frames", "1000000000000"],
            "error: --frames 1000000000000 needs about 500679016.1 GiB of memory to train on, "
            "16.0 GiB is available; use fewer frames",
        ),
    ],
)
def test_train_lane_checks_its_arguments_before_training(work, no_lane_training, args, line):
    (work / "weights").mkdir()
    assert_refused(work, ["perception", "train-lane", "--frames", "1", "--epochs", "1", *args], line)


def test_train_lane_writes_only_the_weights_file(work):
    result = runner.invoke(
        app, ["perception", "train-lane", "--frames", "2", "--epochs", "1", "--out", "w.pt"]
    )
    assert result.exit_code == 0, result.output
    assert sorted(snapshot(work)) == ["w.pt"]

    from drivelab.perception.lane_cnn import load_lane_cnn

    load_lane_cnn(work / "w.pt")


COMMANDS = (
    "envs, train, evaluate, zoo, enjoy, compare, sweep, tune, ablate, convert-run, export, maps, "
    + "benchmark, perception"
)


@pytest.mark.parametrize(
    ("args", "line"),
    [
        (["benchmark"], "error: benchmark needs a subcommand: nocrash (see `drivelab benchmark --help`)"),
        (
            ["perception"],
            "error: perception needs a subcommand: train-lane (see `drivelab perception --help`)",
        ),
        ([], f"error: drivelab needs a command: {COMMANDS} (see `drivelab --help`)"),
    ],
)
def test_a_missing_command_is_one_error_line(args, line):
    result = runner.invoke(app, args, prog_name="drivelab")
    assert result.exit_code == 2, result.output
    assert result.output.splitlines() == [line]


@pytest.mark.parametrize("args", [["--help"], ["benchmark", "--help"], ["perception", "--help"]])
def test_help_still_shows_the_help(args):
    result = runner.invoke(app, args, prog_name="drivelab")
    assert result.exit_code == 0, result.output
    assert "Usage: drivelab" in result.output and "Commands" in result.output


@pytest.mark.parametrize(
    ("command", "text", "line"),
    [
        (["train", "--config"], "algo: ppo\nsteps: 64\nalgo: dqn\n", "line 3: duplicate key 'algo'"),
        (["train", "--config"], "hyperparams: {gamma: 0.9, gamma: 0.8}\n", "line 1: duplicate key 'gamma'"),
        (["sweep"], "grid: {seed: 1}\nbase: {algo: ppo}\ngrid: {seed: 2}\n", "line 3: duplicate key 'grid'"),
    ],
)  # fmt: skip
def test_a_yaml_file_that_repeats_a_key_is_refused(work, command, text, line):
    (work / "dup.yaml").write_text(text)
    assert_refused(work, [*command, "dup.yaml"], f"error: malformed YAML in 'dup.yaml' at {line}")


def test_yaml_merge_keys_may_still_be_overridden():
    from drivelab.yaml_io import parse_yaml

    text = "base: &b {algo: ppo, steps: 8}\nrun: {<<: *b, algo: dqn}\n"
    assert parse_yaml(text)["run"] == {"algo": "dqn", "steps": 8}
    # a merging mapping that is itself merged later (PyYAML flattens it in place, early)
    nested = "a: &a\n  x: 1\nb:\n  c: &c\n    <<: *a\n    x: 2\nd:\n  <<: *c\n"
    assert parse_yaml(nested)["b"] == {"c": {"x": 2}} and yaml.safe_load(nested) == parse_yaml(nested)


@pytest.mark.parametrize(
    ("reward", "term"), [("crash=1,crash=-5", "crash"), ("highway,right_lane=1,right_lane=2", "right_lane")]
)
def test_a_reward_that_gives_a_term_twice_is_refused(work, reward, term):
    line = f"error: reward {reward!r} gives the term {term!r} twice"
    assert_refused(
        work, ["train", "--algo", "ppo", "--reward", reward, "--steps", "16", "--runs-dir", "runs"], line
    )


def test_dropping_a_term_the_ablated_reward_weighs_itself():
    from drivelab.training.ablate import reward_variants

    assert reward_variants(None, ["right_lane", "collision"], "highway,right_lane=0.5") == [
        "highway,right_lane=0.5",
        "highway,right_lane=0",
        "highway,right_lane=0.5,collision=0",
    ]


def test_compare_refuses_two_copies_of_one_run(work):
    import shutil

    from drivelab.config import build_config, save_yaml

    run = work / "runs" / "ppo-s0"
    run.mkdir(parents=True)
    save_yaml(build_config({"algo": "ppo", "seed": 0, "steps": 20, "name": "ppo-s0"}), run / "config.yaml")
    (run / "eval.json").write_text('{"episodes": 1, "mean_return": 1.0, "success_rate": 1.0}')
    shutil.copytree(run, work / "runs" / "copy")
    line = (
        "error: runs 'runs/copy' and 'runs/ppo-s0' are the same run (one config, seed 0, 20 steps): "
        "a seed counts once in a group; compare one of them"
    )
    assert_refused(work, ["compare", "runs/copy", "runs/ppo-s0", "-o", "report"], line)


def _zip(path: Path) -> bytes:
    import zipfile

    path.parent.mkdir(parents=True, exist_ok=True)
    with zipfile.ZipFile(path, "w") as archive:
        archive.writestr("data", "a model")
    return path.read_bytes()


NOT_A_ZIP = "is not a model zip of either format (truncated or corrupted)"
MANIFEST = "checkpoints/latest.json)"


@pytest.mark.parametrize(
    ("damage", "problem"),
    [
        ("garbage model", "model.zip " + NOT_A_ZIP),
        ("truncated checkpoint", "checkpoints/latest.zip " + NOT_A_ZIP),
        ("checksum", "checkpoints/latest.zip is truncated or corrupted (checksum mismatch with " + MANIFEST),
        ("manifest", "its checkpoint manifest checkpoints/latest.json is missing or corrupted"),
    ],
)  # fmt: skip
def test_convert_run_says_what_is_damaged(work, damage, problem):
    from drivelab.config import build_config, save_yaml

    run = work / "run"
    run.mkdir()
    save_yaml(build_config({"algo": "ppo", "seed": 0, "steps": 20, "name": "run"}), run / "config.yaml")
    whole = _zip(run / "checkpoints" / "latest.zip")
    (run / "checkpoints" / "latest.json").write_text(
        f'{{"steps": 20, "sha256": "{hashlib.sha256(whole).hexdigest()}"}}'
    )
    if damage == "garbage model":
        (run / "model.zip").write_bytes(bytes(range(256)))
    elif damage == "truncated checkpoint":
        (run / "checkpoints" / "latest.zip").write_bytes(whole[: len(whole) // 2])
    elif damage == "checksum":
        (run / "checkpoints" / "latest.json").write_text('{"steps": 20, "sha256": "0"}')
    else:
        (run / "checkpoints" / "latest.json").write_text("{corrupt")
    assert_refused(work, ["convert-run", "run"], f"error: cannot convert 'run': {problem}")


@pytest.mark.parametrize("command", [["convert-run"], ["train", "--resume"]])
def test_a_file_given_as_a_run_directory(work, command):
    (work / "notes.txt").write_text("mine")
    assert_refused(work, [*command, "notes.txt"], "error: 'notes.txt' is a file, not a run directory")


@pytest.mark.parametrize(
    "seeds, columns, shape",
    [("0:100000000", "4", "25000000 x 4"), ("0:1025", "4", "257 x 4"), ("3:2", "257", "1 x 257")],
)
def test_a_gallery_too_large_for_one_png_is_refused_before_any_map(work, seeds, columns, shape):
    assert_refused(
        work,
        ["maps", "--seeds", seeds, "--columns", columns, "--out", "g.png"],
        f"error: --seeds {seeds!r} with --columns {columns} draws a gallery of {shape} maps: at most 256 "
        "a side fit in one PNG (matplotlib's 65,536 pixels)",
    )


@pytest.mark.parametrize(
    "args, line",
    [
        (["-H", "gamma=0.9", "-H", "gamma=0.8"], "error: --hyperparams gives 'gamma' twice"),
        (["--obs", "lidar:beams=8:beams=16"], "error: sensor 'lidar' gives option 'beams' twice"),
    ],
)
def test_a_value_given_twice_is_refused_not_overwritten(work, args, line):
    assert_refused(work, ["train", "--algo", "ppo", "--steps", "64", *args], line)


@pytest.mark.parametrize("command", [["evaluate"], ["benchmark", "nocrash"]])
def test_a_file_given_to_evaluate_is_not_said_to_be_missing(work, command):
    (work / "notes.txt").write_text("mine")
    assert_refused(work, [*command, "notes.txt"], "error: 'notes.txt' is a file, not a run directory")
