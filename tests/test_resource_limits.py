"""Settings no machine can hold, or that make no sense, are one ``error:`` line and exit code 2 with
nothing written; so are models whose weights diverged to nan, and foreign tensor files (no torch
warning leaks before the line)."""

import io
import warnings
import zipfile
from pathlib import Path

import numpy as np
import pytest
import torch
from typer.testing import CliRunner

from drivelab.agents.registry import get_algo
from drivelab.cli import app
from drivelab.config import build_config, save_yaml
from drivelab.envs.core import DriveEnv
from drivelab.errors import UsageError
from drivelab.training import checkpoints
from tests.test_untrusted_files import HIGHWAY, SMALL
from tests.training.tiny_runs import rewrite_member

runner = CliRunner()


def _config(algo: str):
    return build_config({"algo": algo, "action": "meta", **HIGHWAY, "name": algo, "hyperparams": SMALL[algo]})


def _built(algo: str):
    config = _config(algo)
    env = DriveEnv(**config.env_kwargs())
    return config, get_algo(algo).build(algo, env, config.seed, dict(config.hyperparams), None)


def _saved_run(tmp_path: Path, algo: str) -> Path:
    """A run directory with its config and a freshly built (untrained) model.zip."""
    config, model = _built(algo)
    run_dir = tmp_path / "runs" / config.name
    run_dir.mkdir(parents=True)
    save_yaml(config, run_dir / "config.yaml")
    model.save(run_dir / "model.zip")
    return run_dir


def _poison(model) -> None:
    """Make the model's first weight nan, as a diverged training run leaves it."""
    network = model.policy if hasattr(model, "policy") else model.q_network
    with torch.no_grad():
        next(network.parameters()).view(-1)[0] = float("nan")


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
    rewrite_member(run_dir / "model.zip", "parameters.pt", foreign.getvalue())
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        result = runner.invoke(app, ["evaluate", str(run_dir), "--episodes", "1"])
    _assert_one_error_line(result, "cannot load model", "objects other than tensors")
    assert [str(w.message) for w in caught if "pickle protocol" in str(w.message)] == []
    assert not (run_dir / "eval.json").exists()


# --- diverged models ----------------------------------------------------------------------------
@pytest.mark.parametrize("algo", ["dqn", "dueling_ddqn"])
def test_a_model_with_nan_weights_is_not_saved(tmp_path, algo):
    config, model = _built(algo)
    _poison(model)
    with pytest.raises(UsageError, match="not saved: the model's tensors hold nan or inf"):
        model.save(tmp_path / "model.zip")
    assert not (tmp_path / "model.zip").exists()


def test_a_checkpoint_with_nan_weights_keeps_the_previous_one(tmp_path):
    config, model = _built("dueling_ddqn")
    run_dir = tmp_path / "run"
    run_dir.mkdir()
    checkpoints.save_checkpoint(model, run_dir, config, save_replay=False)
    before = {path.name: path.read_bytes() for path in (run_dir / "checkpoints").iterdir()}
    _poison(model)
    with pytest.raises(UsageError, match="not saved: the model's tensors hold nan"):
        checkpoints.save_checkpoint(model, run_dir, config, save_replay=False)
    after = {path.name: path.read_bytes() for path in (run_dir / "checkpoints").iterdir()}
    assert after == before  # no temporary file left, the previous checkpoint whole


@pytest.mark.parametrize(("algo", "member"), [("dqn", "parameters.pt"), ("dueling_ddqn", "state.pt")])
def test_a_model_with_nan_weights_is_not_evaluated(tmp_path, algo, member):
    run_dir = _saved_run(tmp_path, algo)
    with zipfile.ZipFile(run_dir / "model.zip") as archive:
        state = torch.load(io.BytesIO(archive.read(member)), weights_only=True)
    tensors = state["state_dicts"]["policy"] if algo == "dqn" else state["q_network"]
    next(iter(tensors.values())).view(-1)[0] = float("inf")
    corrupted = io.BytesIO()
    torch.save(state, corrupted)  # written around the guard, as a diverged run's file would be
    rewrite_member(run_dir / "model.zip", member, corrupted.getvalue())
    result = runner.invoke(app, ["evaluate", str(run_dir), "--episodes", "1"])
    _assert_one_error_line(result, "cannot load model", "nan or inf")
    assert not (run_dir / "eval.json").exists()


# --- sensor sizes -------------------------------------------------------------------------------
OVERSIZED_SENSORS = [
    ("lidar:beams=100000000", "'beams' of 'lidar' must be <= 100000"),
    ("topdown:size=1000000", "'size' of 'topdown' must be <= 1024"),
    ("topdown:history=1000000000", "'history' of 'topdown' must be <= 10000"),
    ("birdeye:size=1000000", "'size' of 'birdeye' must be <= 2048"),
    ("kinematics:stack=1000000000", "'stack' of 'kinematics' must be <= 16777216"),
    ("kinematics:vehicles_count=1000000000", "'vehicles_count' of 'kinematics' must be <= 10000"),
    ("waypoints:count=1000000000", "'count' of 'waypoints' must be <= 100000"),
    ("camera:width=1000000", "'width' of 'camera' must be <= 2048"),
    ("camera:height=1000000", "'height' of 'camera' must be <= 2048"),
    ("line:strips=1000", "'strips' of 'line' must be <= 40"),
    ("lidar:beams=100000:stack=200", "gives 20000000 values per observation, more than 16777216"),
]


@pytest.mark.parametrize(("spec", "message"), OVERSIZED_SENSORS)
def test_oversized_sensors_are_refused_before_they_are_built(spec, message):
    from drivelab.perception.sensors import make_sensor

    with pytest.raises(UsageError, match=message.replace("(", r"\(")):
        make_sensor(spec)


def test_the_largest_allowed_sizes_build():
    from drivelab.perception.sensors import make_sensor

    assert make_sensor("lidar:beams=100000").space.shape == (100_000,)
    assert make_sensor("kinematics:vehicles_count=10000:stack=2").space.shape == (140_000,)


def test_an_oversized_sensor_is_one_error_line_and_no_run(tmp_path):
    result = runner.invoke(app, ["train", "--algo", "ppo", "--steps", "64", "--obs", "lidar:beams=100000000",
                                 "--runs-dir", str(tmp_path / "runs")])  # fmt: skip
    _assert_one_error_line(result, "'beams' of 'lidar' must be <= 100000")
    assert not (tmp_path / "runs").exists()


# --- buffer and rollout sizes -------------------------------------------------------------------
HUGE = "1000000000000"  # 10^12 entries: hundreds of TiB, more than any machine's memory


@pytest.mark.parametrize(
    ("algo", "setting", "message"),
    [
        ("dqn", f"buffer_size={HUGE}", "'buffer_size' of 'dqn' asks for a replay buffer"),
        ("dqn", f"batch_size={HUGE}", "'batch_size' of 'dqn' asks for a training batch"),
        ("dueling_ddqn", f"buffer_size={HUGE}", "'buffer_size' of 'dueling_ddqn' asks for a replay buffer"),
        ("dueling_ddqn", f"batch_size={HUGE}", "'batch_size' of 'dueling_ddqn' asks for a training batch"),
        ("ppo", f"n_steps={HUGE}", "'n_steps' of 'ppo' asks for a rollout"),
        ("ppo_own", f"n_steps={HUGE}", "'n_steps' of 'ppo_own' asks for a rollout"),
        ("a2c_own", f"n_steps={HUGE}", "'n_steps' of 'a2c_own' asks for a rollout"),
    ],
)
def test_buffers_larger_than_the_machine_are_one_error_line_and_no_run(tmp_path, algo, setting, message):
    action = "continuous" if algo.endswith("_own") else "meta"
    result = runner.invoke(app, ["train", "--algo", algo, "--action", action, "--steps", "64", "--traffic",
                                 "empty", "-H", setting, "--runs-dir", str(tmp_path / "runs")])  # fmt: skip
    _assert_one_error_line(result, message, "GiB, more than this machine's")
    assert not (tmp_path / "runs").exists()


def test_rlad_refuses_a_replay_larger_than_the_machine():
    from gymnasium import spaces

    from drivelab.agents.rlad.sac import RLAD

    observations = spaces.Dict({
        "camera": spaces.Box(0, 255, (84, 84, 9), dtype=np.uint8),
        "waypoints": spaces.Box(-50.0, 50.0, (10, 2), dtype=np.float32),
        "measurements": spaces.Box(-1.0, 1.0, (6,), dtype=np.float32),
    })  # fmt: skip
    actions = spaces.Box(-1.0, 1.0, (2,), dtype=np.float32)
    with pytest.raises(UsageError, match="'buffer_size' of 'rlad' asks for a replay buffer"):
        RLAD(observations, actions, 0, {"buffer_size": int(HUGE)})
    with pytest.raises(UsageError, match="'batch_size' of 'rlad' asks for a training batch"):
        RLAD(observations, actions, 0, {"buffer_size": 1000, "batch_size": int(HUGE)})


def test_ordinary_buffer_sizes_are_accepted():
    from drivelab.agents.buffer_memory import check_buffer_memory

    check_buffer_memory(
        "dqn", "buffer_size", 1_000_000, 2 * 4 * 35
    )  # SB3's default size, kinematics: 0.3 GiB


# --- settings that train nothing ----------------------------------------------------------------
@pytest.mark.parametrize("algo", ["dqn", "sac"])
def test_zero_gradient_steps_are_refused(algo):
    from drivelab.agents.sb3_params import check_sb3_hyperparams

    with pytest.raises(UsageError, match=f"'gradient_steps' of '{algo}' must be -1 .* or >= 1, got 0"):
        check_sb3_hyperparams(algo, {"gradient_steps": 0})
    assert check_sb3_hyperparams(algo, {"gradient_steps": -1}) == {"gradient_steps": -1}
    assert check_sb3_hyperparams(algo, {"gradient_steps": 2.0}) == {"gradient_steps": 2}


@pytest.mark.parametrize(
    ("algo", "net_arch"),
    [("ppo", [0]), ("ppo", [64, -1]), ("a2c", {"pi": [64], "vf": [0]}), ("dqn", [32, 0]),
     ("sac", {"pi": [64], "qf": [64, 0]}), ("ppo", [64.5]), ("ppo", {"pi": 64})],
)  # fmt: skip
def test_non_positive_layer_widths_are_refused(algo, net_arch):
    from drivelab.agents.sb3_params import check_sb3_hyperparams

    with pytest.raises(
        UsageError, match=f"policy_kwargs net_arch of '{algo}' must be a list of layer widths"
    ):
        check_sb3_hyperparams(algo, {"policy_kwargs": {"net_arch": net_arch}})


def test_positive_layer_widths_are_accepted():
    from drivelab.agents.sb3_params import check_sb3_hyperparams

    for net_arch in ([], [64, 64], {"pi": [32], "vf": [64, 64]}):
        kwargs = {"policy_kwargs": {"net_arch": net_arch}}
        assert check_sb3_hyperparams("ppo", kwargs) == kwargs


@pytest.mark.parametrize(
    ("algo", "setting", "message"),
    [("dqn", "gradient_steps=0", "'gradient_steps' of 'dqn'"),
     ("ppo", "policy_kwargs={net_arch: [0]}", "net_arch of 'ppo' must be a list of layer widths >= 1")],
)  # fmt: skip
def test_settings_that_train_nothing_are_one_error_line_and_no_run(tmp_path, algo, setting, message):
    arguments = ["--algo", algo, "--steps", "64", "--traffic", "empty", "-H", setting]
    result = runner.invoke(app, ["train", *arguments, "--runs-dir", str(tmp_path / "runs")])
    _assert_one_error_line(result, message)
    assert not (tmp_path / "runs").exists()


# --- sensors that need a road's paint ------------------------------------------------------------
@pytest.mark.parametrize(
    ("scenario", "obs", "message"),
    [("highway", "line", "only the follow-line circuit has painted"),
     ("follow-lane", "line", "only the follow-line circuit has painted"),
     ("town", "kinematics,line", "only the follow-line circuit has painted"),
     ("highway", "lane:detector=classical", "calibrated to the 3.5 m lanes of the follow-lane circuit"),
     ("follow-line", "lane:detector=classical", "calibrated to the 3.5 m lanes of the follow-lane circuit")],
)  # fmt: skip
def test_line_and_lane_sensors_are_refused_off_their_circuits(scenario, obs, message):
    sensor = obs.split(",")[-1].split(":")[0]
    with pytest.raises(
        UsageError, match=f"sensor '{sensor}' cannot observe scenario '{scenario}': .*{message}"
    ):
        DriveEnv(scenario, obs=obs)


def test_line_and_lane_sensors_build_on_their_circuits():
    assert DriveEnv("follow-line", obs="line").observation_space.n == 1296
    assert DriveEnv("follow-lane", obs="lane:detector=classical").observation_space.n == 6


def test_a_line_sensor_on_the_highway_is_one_error_line_and_no_run(tmp_path):
    arguments = ["--algo", "dqn", "--obs", "line", "--steps", "64", "--runs-dir", str(tmp_path / "runs")]
    result = runner.invoke(app, ["train", *arguments])
    _assert_one_error_line(result, "sensor 'line' cannot observe scenario 'highway'")
    assert not (tmp_path / "runs").exists()
