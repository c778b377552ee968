"""Run directories are data: loading a model, checkpoint or replay never executes code.

Each malicious file carries a payload that creates a marker file when unpickled; a control check
proves that the payload is live (the old loaders would have run it). Through the CLI, every case
must end with exit code 2, one ``error:`` line and no marker. Round trips check that the safe
format restores exactly what further training needs.
"""

import base64
import errno
import io
import json
import pickle
import zipfile
from pathlib import Path

import numpy as np
import pytest
import torch
from stable_baselines3 import DQN
from typer.testing import CliRunner

from drivelab.agents.qlearning import QLearning
from drivelab.agents.registry import get_algo
from drivelab.agents.storage import read_arrays
from drivelab.cli import app
from drivelab.config import build_config, save_yaml
from drivelab.envs.core import DriveEnv
from drivelab.errors import UsageError
from drivelab.training import checkpoints

runner = CliRunner()
FAST = {"duration_s": 6}
HIGHWAY = {"env": "highway", "obs": "kinematics", "traffic": "empty", "steps": 400, "seed": 1,
           "eval_every": 200, "eval_episodes": 1, "env_options": FAST}  # fmt: skip
SMALL = {
    "dqn": {"learning_starts": 20, "buffer_size": 500, "batch_size": 8, "target_update_interval": 10},
    "ppo": {"n_steps": 32, "batch_size": 16, "n_epochs": 1},
    "dueling_ddqn": {"learning_starts": 20, "batch_size": 8, "buffer_size": 500, "log_interval": 20},
}


class Payload:
    """Unpickled, it creates the file ``marker`` (a harmless stand-in for arbitrary code)."""

    def __init__(self, marker: Path) -> None:
        self.marker = marker

    def __reduce__(self):
        return open, (str(self.marker), "w")


def _config(algo, **extra):
    action = "meta" if algo in ("dqn", "dueling_ddqn") else "continuous"
    obs = "lidar:beams=24" if algo == "dueling_ddqn" else "kinematics"
    return build_config({"algo": algo, "action": action, **HIGHWAY, "obs": obs, "name": algo,
                         "hyperparams": SMALL[algo], **extra})  # fmt: skip


def _run_dir(tmp_path, config) -> Path:
    run_dir = tmp_path / "runs" / config.name
    (run_dir / "checkpoints").mkdir(parents=True)
    save_yaml(config, run_dir / "config.yaml")
    return run_dir


def _build(config):
    env = DriveEnv(**config.env_kwargs())
    return get_algo(config.algo).build(config.algo, env, config.seed, dict(config.hyperparams), None), env


def _write_manifest(run_dir, config, steps=100, replay_name=None):
    """A manifest that matches the checkpoint (sha256 and config): only the payload can stop a load."""
    folder = run_dir / "checkpoints"
    manifest = {"steps": steps, "sha256": checkpoints.file_sha256(folder / "latest.zip"),
                "config_identity": config.identity(), "replay_buffer": replay_name is not None}  # fmt: skip
    if replay_name is not None:
        manifest["replay_sha256"] = checkpoints.file_sha256(folder / replay_name)
    (folder / "latest.json").write_text(json.dumps(manifest))


def _malicious_sb3_zip(path: Path, marker: Path) -> None:
    """An SB3-format model whose ``data`` has a ``:serialized:`` entry (cloudpickle on SB3's load)."""
    payload = base64.b64encode(pickle.dumps(Payload(marker))).decode()
    data = {"policy_class": {":type:": "<class 'type'>", ":serialized:": payload}}
    with zipfile.ZipFile(path, "w") as archive:
        archive.writestr("data", json.dumps(data))
        archive.writestr("policy.pth", b"")


def _malicious_own_zip(path: Path, marker: Path) -> None:
    """An own-agent zip of the old format: ``spaces.pkl`` is the payload."""
    with zipfile.ZipFile(path, "w") as archive:
        archive.writestr("agent.json", json.dumps({"algo": "dueling_ddqn", "seed": 1, "hyperparams": {}}))
        archive.writestr("spaces.pkl", pickle.dumps(Payload(marker)))
        archive.writestr("state.pt", b"")


def _torch_payload_zip(config, path: Path, marker: Path) -> None:
    """A new-format own-agent zip whose ``state.pt`` is a torch pickle of the payload."""
    agent, _ = _build(config)
    agent.save(path)
    with zipfile.ZipFile(path) as archive:
        meta = archive.read("agent.json")
    state = io.BytesIO()
    torch.save({"generator": Payload(marker)}, state)
    with zipfile.ZipFile(path, "w") as archive:
        archive.writestr("agent.json", meta)
        archive.writestr("state.pt", state.getvalue())


def _assert_refused(result, marker, *fragments):
    assert not marker.exists(), "the payload ran"
    assert result.exit_code == 2, result.output
    lines = result.output.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), result.output
    for fragment in fragments:
        assert fragment in lines[0]


def test_the_payloads_are_live(tmp_path):
    """Control: the old loaders run each payload (so the refusals below mean something)."""
    markers = [tmp_path / f"marker{i}" for i in range(4)]
    _malicious_sb3_zip(tmp_path / "model.zip", markers[0])
    with pytest.raises(Exception):  # noqa: B017 - SB3 fails after unpickling the payload
        DQN.load(tmp_path / "model.zip")
    _malicious_own_zip(tmp_path / "own.zip", markers[1])
    with zipfile.ZipFile(tmp_path / "own.zip") as archive:
        pickle.loads(archive.read("spaces.pkl"))
    torch.load(io.BytesIO(_torch_bytes(Payload(markers[2]))), weights_only=False)
    np.save(tmp_path / "object.npy", np.array([Payload(markers[3])], dtype=object))
    np.load(tmp_path / "object.npy", allow_pickle=True)
    assert all(marker.exists() for marker in markers)


def _torch_bytes(obj) -> bytes:
    buffer = io.BytesIO()
    torch.save(obj, buffer)
    return buffer.getvalue()


@pytest.mark.parametrize("command", ["evaluate", "resume"])
def test_a_pickled_sb3_model_is_refused_with_the_conversion_command(tmp_path, command):
    config = _config("dqn")
    run_dir, marker = _run_dir(tmp_path, config), tmp_path / "marker"
    target = run_dir / ("model.zip" if command == "evaluate" else "checkpoints/latest.zip")
    _malicious_sb3_zip(target, marker)
    if command == "evaluate":
        result = runner.invoke(app, ["evaluate", str(run_dir), "--episodes", "1"])
    else:
        _write_manifest(run_dir, config)
        result = runner.invoke(app, ["train", "--resume", str(run_dir)])
    _assert_refused(result, marker, "old pickle format", f"drivelab convert-run {run_dir}")
    assert not (run_dir / "eval.json").exists()


def test_nocrash_refuses_a_pickled_model(tmp_path):
    config = build_config({"algo": "ppo", "env": "town", "obs": "waypoints", "action": "target_speed",
                           "traffic": "empty", "steps": 16, "seed": 0, "name": "town"})  # fmt: skip
    run_dir, marker = _run_dir(tmp_path, config), tmp_path / "marker"
    _malicious_sb3_zip(run_dir / "model.zip", marker)
    result = runner.invoke(app, ["benchmark", "nocrash", str(run_dir), "--episodes", "1"])
    _assert_refused(result, marker, "old pickle format", "convert-run")


def test_own_agent_payloads_are_refused(tmp_path):
    config = _config("dueling_ddqn")
    run_dir, marker = _run_dir(tmp_path, config), tmp_path / "marker"
    _malicious_own_zip(run_dir / "model.zip", marker)
    result = runner.invoke(app, ["evaluate", str(run_dir), "--episodes", "1"])
    _assert_refused(result, marker, "old pickle format", "convert-run")
    _torch_payload_zip(config, run_dir / "model.zip", marker)  # the new format, a poisoned state.pt
    result = runner.invoke(app, ["evaluate", str(run_dir), "--episodes", "1"])
    _assert_refused(result, marker, "cannot load model", "objects other than tensors")


@pytest.mark.parametrize("algo", ["dqn", "dueling_ddqn"])
@pytest.mark.parametrize("kind", ["pickle", "object_array"])
def test_malicious_replays_are_refused_on_resume(tmp_path, algo, kind):
    config = _config(algo)
    run_dir, marker = _run_dir(tmp_path, config), tmp_path / "marker"
    model, _ = _build(config)
    model.save(run_dir / "checkpoints/latest.zip")
    if kind == "pickle":  # the old replay.pkl beside a manifest that announces a replay
        (run_dir / "checkpoints/replay.pkl").write_bytes(pickle.dumps(Payload(marker)))
        _write_manifest(run_dir, config)
        manifest = json.loads((run_dir / "checkpoints/latest.json").read_text())
        manifest["replay_buffer"] = True
        (run_dir / "checkpoints/latest.json").write_text(json.dumps(manifest))
        fragments = ("old pickle format", "convert-run")
    else:  # a replay.npz whose observations are an object array
        with open(run_dir / "checkpoints/replay.npz", "wb") as handle:
            np.savez(handle, observations=np.array([Payload(marker)], dtype=object))
        _write_manifest(run_dir, config, replay_name="replay.npz")
        fragments = ("cannot load replay", "replay.npz")
    before = (run_dir / "config.yaml").read_text()
    result = runner.invoke(app, ["train", "--resume", str(run_dir)])
    _assert_refused(result, marker, *fragments)
    assert (run_dir / "config.yaml").read_text() == before


def test_qlearning_refuses_object_arrays(tmp_path):
    env = DriveEnv("follow-line", obs="line", action="seed_line")
    agent = QLearning(env, seed=0)
    agent.save(tmp_path / "q.zip")
    marker = tmp_path / "marker"
    with zipfile.ZipFile(tmp_path / "q.zip") as archive:
        files = {name: archive.read(name) for name in archive.namelist()}
    poisoned = io.BytesIO()
    np.savez(poisoned, returns=np.array([Payload(marker)], dtype=object), lengths=np.zeros(1))
    files["episodes.npz"] = poisoned.getvalue()
    with zipfile.ZipFile(tmp_path / "q.zip", "w") as archive:
        for name, data in files.items():
            archive.writestr(name, data)
    with pytest.raises(ValueError, match="allow_pickle"):
        QLearning.load(tmp_path / "q.zip")
    assert not marker.exists()


# --- round trips ----------------------------------------------------------------------------------
def _state_dicts_equal(one, two):
    if isinstance(one, dict):
        assert one.keys() == two.keys()
        for key in one:
            _state_dicts_equal(one[key], two[key])
    elif isinstance(one, torch.Tensor):
        assert torch.equal(one, two)
    elif isinstance(one, (list, tuple)):
        assert len(one) == len(two)
        for a, b in zip(one, two, strict=True):
            _state_dicts_equal(a, b)
    else:
        assert one == two


@pytest.mark.parametrize("algo", ["dqn", "ppo"])
def test_sb3_round_trip_restores_parameters_counters_and_replay(tmp_path, algo):
    config = _config(algo)
    model, env = _build(config)
    model.learn(100)
    model.save(tmp_path / "model.zip")
    loaded = get_algo(algo).load(algo, tmp_path / "model.zip", env, dict(config.hyperparams), config.seed)
    _state_dicts_equal(model.get_parameters(), loaded.get_parameters())
    for name in ("num_timesteps", "_n_updates", "_episode_num", "_n_calls", "exploration_rate",
                 "_current_progress_remaining", "_total_timesteps"):  # fmt: skip
        assert getattr(loaded, name, None) == getattr(model, name, None), name
    assert list(loaded.ep_info_buffer) == [dict(info) for info in model.ep_info_buffer]
    assert loaded.ep_info_buffer.maxlen == model.ep_info_buffer.maxlen
    obs, _ = env.reset(seed=3)
    for _ in range(5):
        action, _ = model.predict(obs, deterministic=True)
        np.testing.assert_array_equal(action, loaded.predict(obs, deterministic=True)[0])
        obs, *_ = env.step(action)
    with pytest.raises(ValueError, match="hyperparameters"):
        get_algo(algo).load(algo, tmp_path / "model.zip", env, {**config.hyperparams, "gamma": 0.5}, 1)
    if algo == "dqn":
        model.save_replay_buffer(tmp_path / "replay.npz")
        loaded.load_replay_buffer(tmp_path / "replay.npz")
        for name in ("observations", "next_observations", "actions", "rewards", "dones", "timeouts"):
            np.testing.assert_array_equal(getattr(loaded.replay_buffer, name),
                                          getattr(model.replay_buffer, name), err_msg=name)  # fmt: skip
        assert (loaded.replay_buffer.pos, loaded.replay_buffer.full) == (100, False)


def test_own_agent_round_trip_restores_state_and_prioritised_replay(tmp_path):
    config = _config("dueling_ddqn")
    agent, env = _build(config)
    agent.learn(60)
    agent.save(tmp_path / "agent.zip")
    agent.save_replay_buffer(tmp_path / "replay.npz")
    loaded = get_algo("dueling_ddqn").load("dueling_ddqn", tmp_path / "agent.zip", env,
                                           dict(config.hyperparams), config.seed)  # fmt: skip
    loaded.load_replay_buffer(tmp_path / "replay.npz")
    _state_dicts_equal(agent._state(), loaded._state())
    assert loaded.rng.bit_generator.state == agent.rng.bit_generator.state
    assert torch.equal(loaded.generator.get_state(), agent.generator.get_state())
    one, two = agent.replay_buffer, loaded.replay_buffer
    np.testing.assert_array_equal(one.tree.nodes, two.tree.nodes)
    assert (one.position, one.size, one.max_priority) == (two.position, two.size, two.max_priority)
    first = one.sample(8, 0.4, np.random.default_rng(5))
    second = two.sample(8, 0.4, np.random.default_rng(5))
    np.testing.assert_array_equal(first[0], second[0])
    np.testing.assert_array_equal(first[2], second[2])
    small = _config("dueling_ddqn", hyperparams={**SMALL["dueling_ddqn"], "buffer_size": 100})
    other, _ = _build(small)
    with pytest.raises(ValueError, match="replay array 'observations'"):
        other.load_replay_buffer(tmp_path / "replay.npz")


def test_qlearning_round_trip(tmp_path):
    env = DriveEnv("follow-line", obs="line", action="seed_line")
    agent = QLearning(env, seed=2)
    agent.learn(150)
    agent.save(tmp_path / "q.zip")
    loaded = get_algo("qlearning").load("qlearning", tmp_path / "q.zip", env, {}, 2)
    np.testing.assert_array_equal(loaded.q_table, agent.q_table)
    assert (loaded.epsilon, loaded.num_timesteps) == (agent.epsilon, agent.num_timesteps)
    assert loaded.rng.bit_generator.state == agent.rng.bit_generator.state
    assert loaded.episode_returns == agent.episode_returns


# --- failed writes and conversion -------------------------------------------------------------------
def test_a_failed_checkpoint_write_leaves_the_previous_checkpoint_and_no_debris(tmp_path):
    config = _config("dqn")
    run_dir = _run_dir(tmp_path, config)
    model, _ = _build(config)
    model.learn(50)
    checkpoints.save_checkpoint(model, run_dir, config, save_replay=True)
    before = {path.name: path.read_bytes() for path in (run_dir / "checkpoints").iterdir()}
    model.learn(20, reset_num_timesteps=False)

    def disk_full(path):
        Path(path).write_bytes(b"partial")
        raise OSError(errno.ENOSPC, "No space left on device")

    model.save_replay_buffer = disk_full
    full = r"cannot write checkpoint in .*: no space left on device \(the disk is full\)"
    with pytest.raises(UsageError, match=full):
        checkpoints.save_checkpoint(model, run_dir, config, save_replay=True)
    after = {path.name: path.read_bytes() for path in (run_dir / "checkpoints").iterdir()}
    assert after == before  # no *.tmp* file, the old checkpoint untouched
    manifest = checkpoints.verify_checkpoint(run_dir, config)
    assert manifest["steps"] == 50 and manifest["replay_buffer"]


def test_convert_run_rewrites_a_trusted_old_run_that_then_loads(tmp_path):
    config = _config("dqn")
    run_dir = _run_dir(tmp_path, config)
    model, env = _build(config)
    model.learn(50)
    DQN.save(model, run_dir / "model.zip")  # SB3's own pickle format, as earlier drivelab wrote it
    DQN.save(model, run_dir / "checkpoints/latest.zip")
    DQN.save_replay_buffer(model, run_dir / "checkpoints/replay.pkl")
    _write_manifest(run_dir, config, steps=50)
    result = runner.invoke(app, ["evaluate", str(run_dir), "--episodes", "1"])
    assert result.exit_code == 2 and "convert-run" in result.output
    result = runner.invoke(app, ["convert-run", str(run_dir)])
    assert result.exit_code == 0, result.output
    assert not (run_dir / "checkpoints/replay.pkl").exists()
    loaded = checkpoints.load_agent(run_dir, config)
    _state_dicts_equal(model.get_parameters(), loaded.get_parameters())
    manifest = checkpoints.verify_checkpoint(run_dir, config)
    checkpoint = checkpoints.load_agent(run_dir, config, env, run_dir / "checkpoints/latest.zip")
    checkpoints.load_replay(checkpoint, run_dir, manifest)
    np.testing.assert_array_equal(checkpoint.replay_buffer.observations, model.replay_buffer.observations)
    assert checkpoint.num_timesteps == 50 and checkpoint.exploration_rate == model.exploration_rate
    arrays = read_arrays(run_dir / "checkpoints/replay.npz")
    assert all(array.dtype != object for array in arrays.values())
