"""Settings no machine can hold, or that make no sense, are one ``error:`` line and exit code 2 with
nothing written; so are models whose weights diverged to nan, and foreign tensor files (no torch
warning leaks before the line)."""

import io
import warnings
import zipfile
from pathlib import Path

import torch
from typer.testing import CliRunner

from drivelab.agents.registry import get_algo
from drivelab.cli import app
from drivelab.config import build_config, save_yaml
from drivelab.envs.core import DriveEnv

runner = CliRunner()
FAST = {"duration_s": 6}
HIGHWAY = {"env": "highway", "obs": "kinematics", "traffic": "empty", "steps": 400, "seed": 1,
           "eval_every": 200, "eval_episodes": 1, "env_options": FAST}  # fmt: skip
SMALL = {
    "dqn": {"learning_starts": 20, "buffer_size": 500, "batch_size": 8, "target_update_interval": 10},
    "dueling_ddqn": {"learning_starts": 20, "batch_size": 8, "buffer_size": 500, "log_interval": 20},
}


def _config(algo: str):
    return build_config({"algo": algo, "action": "meta", **HIGHWAY, "name": algo, "hyperparams": SMALL[algo]})


def _saved_run(tmp_path: Path, algo: str) -> Path:
    """A run directory with its config and a freshly built (untrained) model.zip."""
    config = _config(algo)
    run_dir = tmp_path / "runs" / config.name
    run_dir.mkdir(parents=True)
    save_yaml(config, run_dir / "config.yaml")
    env = DriveEnv(**config.env_kwargs())
    model = get_algo(algo).build(algo, env, config.seed, dict(config.hyperparams), None)
    model.save(run_dir / "model.zip")
    return run_dir


def _rewrite_member(path: Path, member: str, data: bytes) -> None:
    with zipfile.ZipFile(path) as archive:
        members = {name: archive.read(name) for name in archive.namelist()}
    members[member] = data
    with zipfile.ZipFile(path, "w") as archive:
        for name, value in members.items():
            archive.writestr(name, value)


def _assert_one_error_line(result, *fragments) -> str:
    assert result.exit_code == 2, result.output
    lines = result.output.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), result.output
    for fragment in fragments:
        assert fragment in lines[0], lines[0]
    return lines[0]


# --- foreign tensor files -----------------------------------------------------------------------
def test_a_protocol_4_tensor_file_is_refused_without_torch_warnings(tmp_path):
    run_dir = _saved_run(tmp_path, "dqn")
    foreign = io.BytesIO()  # torch's legacy format pickled with protocol 4: torch warns, then refuses it
    torch.save({"state_dicts": {}}, foreign, _use_new_zipfile_serialization=False, pickle_protocol=4)
    _rewrite_member(run_dir / "model.zip", "parameters.pt", foreign.getvalue())
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        result = runner.invoke(app, ["evaluate", str(run_dir), "--episodes", "1"])
    _assert_one_error_line(result, "cannot load model", "objects other than tensors")
    assert [str(w.message) for w in caught if "pickle protocol" in str(w.message)] == []
    assert not (run_dir / "eval.json").exists()
