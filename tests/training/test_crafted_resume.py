"""A run directory's counters, steps and config are checked before they are used.

Counters in a resume state or a checkpoint's ``sb3.json`` were set on the model as any attribute
(``gamma: 50``, ``ent_coef: 1e9``, ``n_epochs: 0`` past the hyper-parameter checks; a traceback
after model.zip was deleted), of any value (``nan``, ``"abc"``, -1000, 1e30: training began and
wrote files, or a ``resume-1e30.json``); a manifest of ``steps: -5`` deleted every row of
evaluations.csv; and an edited config.yaml (traffic, n_envs) was evaluated silently. Now each is
one ``error:`` line (exit 2) and nothing changes (``agents/counters.py``,
``checkpoints.check_trained_config``); compare takes no eval.json of an earlier model.
"""

import hashlib
import json
import shutil
import zipfile
from pathlib import Path

import pytest
import yaml
from typer.testing import CliRunner

from drivelab.cli import app
from drivelab.errors import UsageError
from drivelab.training import checkpoints
from drivelab.training import run as run_module
from drivelab.training.compare import load_run
from tests.training.tiny_runs import error_line, rewrite_member, tiny_config, tree

runner = CliRunner()
RESUME = ["train", "--resume"]


@pytest.fixture(scope="module")
def finished_run(tmp_path_factory) -> Path:
    """A finished tiny run with checkpoints (and a resume state) at step 128."""
    return run_module.train(tiny_config(), tmp_path_factory.mktemp("runs"))


@pytest.fixture
def run_dir(finished_run, tmp_path) -> Path:
    return Path(shutil.copytree(finished_run, tmp_path / "run"))


def _edit_json(path: Path, edit) -> None:
    data = json.loads(path.read_text())
    edit(data)
    path.write_text(json.dumps(data))


def _refused(command: list[str], root: Path, *fragments: str) -> None:
    before = tree(root)
    result = runner.invoke(app, command)
    assert result.exit_code == 2, result.output
    error_line(result.output, *fragments)
    assert tree(root) == before


# --- the resume state's counters -------------------------------------------------------------------
STATE_COUNTERS = {
    "gamma": ("gamma", 50, "'gamma' is not a counter of a learning loop"),
    "ent_coef": ("ent_coef", 1e9, "'ent_coef' is not a counter"),
    "n_epochs": ("n_epochs", 0, "'n_epochs' is not a counter"),
    "progress nan": ("_current_progress_remaining", float("nan"), "'_current_progress_remaining' holds nan"),
    # an int beyond float's range: math.isfinite would raise OverflowError, a traceback
    "progress -1e400": ("_current_progress_remaining", -(10**400), "holds -1000"),
    "steps -1000": ("num_timesteps", -1000, "'num_timesteps' holds -1000, not a whole number"),
    "steps 1e30": ("num_timesteps", 10**30, "'num_timesteps' holds 1000000000000000000000000000000"),
    "steps text": ("num_timesteps", "abc", "'num_timesteps' holds 'abc'"),
    "steps of another checkpoint": ("num_timesteps", 64, "counter num_timesteps is malformed"),
    "updates 1e30": ("_n_updates", 1e30, "'_n_updates' holds 1e+30"),
}


@pytest.mark.parametrize("case", list(STATE_COUNTERS))
def test_crafted_resume_state_counters_are_one_line_and_change_nothing(run_dir, case):
    name, value, message = STATE_COUNTERS[case]
    state = run_dir / "checkpoints" / "resume-128.json"
    _edit_json(state, lambda meta: meta["counters"].__setitem__(name, value))
    damaged = f"resume state {str(state)!r} is damaged"
    _refused([*RESUME, str(run_dir), "--steps", "192"], run_dir, damaged, message)


@pytest.mark.parametrize("steps", [-5, 64, "128", True, 1.5])
def test_a_manifest_whose_steps_are_not_the_checkpoints_is_refused(run_dir, steps):
    """-5 deleted every row of evaluations.csv (no resume state of that step: a warning only);
    another step than the model's would cut the logs to a step the model is not at."""
    _edit_json(run_dir / "checkpoints" / "latest.json", lambda manifest: manifest.__setitem__("steps", steps))
    message = "holds a model of 128 steps, but its manifest says 64" if steps == 64 else "is corrupted"
    _refused([*RESUME, str(run_dir), "--steps", "192"], run_dir, message)


# --- the checkpoint's own counters (sb3.json) ----------------------------------------------------------
@pytest.mark.parametrize(
    ("name", "value", "message"),
    [
        ("num_timesteps", "abc", "counter 'num_timesteps' holds 'abc'"),
        ("gamma", 50, "'gamma' is not a counter of a learning loop"),  # a hyper-parameter injected
        ("num_timesteps", 1000, "holds a model of 1000 steps, but its manifest says 128"),
    ],
)
def test_crafted_checkpoint_counters_are_one_line_and_change_nothing(run_dir, name, value, message):
    checkpoint = run_dir / "checkpoints" / "latest.zip"
    with zipfile.ZipFile(checkpoint) as archive:
        meta = json.loads(archive.read("sb3.json"))
    meta["counters"][name] = value
    rewrite_member(checkpoint, "sb3.json", json.dumps(meta).encode())
    manifest = run_dir / "checkpoints" / "latest.json"  # its checksum made to match: a deliberate edit
    _edit_json(manifest, lambda data: data.__setitem__("sha256", checkpoints.file_sha256(checkpoint)))
    _refused([*RESUME, str(run_dir), "--steps", "192"], run_dir, message)


# --- config.yaml edited after training --------------------------------------------------------------
EDITS = {  # an edit of the spaces fails as the model loads; the others fail on the manifest's identity
    "traffic": ("dense", "is not the config the run was trained with (its checkpoint records another)"),
    "n_envs": (2, "is not the config the run was trained with (its checkpoint records another)"),
    "obs": (["lidar"], "(was config.yaml edited after training?)"),
}


@pytest.mark.parametrize("field", list(EDITS))
def test_evaluating_a_run_whose_config_was_edited_is_refused(run_dir, field):
    value, message = EDITS[field]
    config = yaml.safe_load((run_dir / "config.yaml").read_text())
    config[field] = value
    (run_dir / "config.yaml").write_text(yaml.safe_dump(config))
    _refused(["evaluate", str(run_dir), "--episodes", "1"], run_dir, message)
    with pytest.raises(UsageError, match="was made with a different config"):
        run_module.resume(run_dir, 192)  # as before: the checkpoint's identity


def test_an_evaluation_records_the_step_of_its_model_and_compare_takes_only_the_final_one(run_dir):
    result = runner.invoke(app, ["evaluate", str(run_dir), "--episodes", "1"])
    assert result.exit_code == 0, result.output
    report = json.loads((run_dir / "eval.json").read_text())
    assert report["model_steps"] == 128 and load_run(run_dir).source == "eval.json"
    assert report["model_sha256"] == hashlib.sha256((run_dir / "model.zip").read_bytes()).hexdigest()
    report["model_steps"] = 64  # as an evaluation of the checkpoint at 64, made while it trained
    (run_dir / "eval.json").write_text(json.dumps(report))
    with pytest.raises(UsageError, match="evaluated the model of step 64, not the run's final one of 128"):
        load_run(run_dir)
    del report["model_steps"]  # an eval.json of an older drivelab: taken as before
    (run_dir / "eval.json").write_text(json.dumps(report))
    assert load_run(run_dir).final["mean_return"] == report["mean_return"]
