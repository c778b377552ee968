"""The RLAD agent: augmentation reaches the critic, the auxiliary loss learns, determinism,
save/load, and `drivelab train --algo rlad` end to end (tiny budgets)."""

import json

import numpy as np
import pytest
import torch
import yaml
from gymnasium import spaces
from typer.testing import CliRunner

from drivelab.agents.registry import get_algo
from drivelab.agents.rlad.sac import RLAD
from drivelab.cli import app

SPACE = spaces.Dict(
    {
        "camera": spaces.Box(0, 255, (44, 44, 9), np.uint8),
        "waypoints": spaces.Box(-40.0, 40.0, (10, 2), np.float32),
        "measurements": spaces.Box(-1.0, 1.0, (6,), np.float32),
    }
)
ACTIONS = spaces.Box(np.array([0.0, -1.0], np.float32), np.array([1.0, 1.0], np.float32))
SMALL = {"hidden_size": 32, "batch_size": 16, "buffer_size": 64}


def _agent(seed=0, **hyperparams):
    return RLAD(SPACE, ACTIONS, seed, {**SMALL, **hyperparams})


def _host(x):
    """A numpy copy of frames kept on the host or in torch memory (the GPU's included)."""
    return x.cpu().numpy() if isinstance(x, torch.Tensor) else np.asarray(x)


def _batch(seed=0, size=16):
    """A fixed batch whose traffic-light label is written in the image (a bright square's place)."""
    rng = np.random.default_rng(seed)
    labels = rng.integers(0, 3, size)
    images = rng.integers(0, 60, (size, 9, 44, 44), dtype=np.uint8)
    for i, label in enumerate(labels):
        images[i, :, 4 + 10 * label : 12 + 10 * label, 10:26] = 250
    return {
        "images": images, "next_images": np.roll(images, 1, axis=3),
        "waypoints": rng.normal(size=(size, 10, 2)).astype(np.float32),
        "next_waypoints": rng.normal(size=(size, 10, 2)).astype(np.float32),
        "measurements": rng.uniform(-1, 1, (size, 6)).astype(np.float32),
        "next_measurements": rng.uniform(-1, 1, (size, 6)).astype(np.float32),
        "labels": labels.astype(np.int64), "actions": rng.uniform(-1, 1, (size, 2)).astype(np.float32),
        "rewards": rng.normal(size=size).astype(np.float32), "terminated": np.zeros(size, np.float32),
    }  # fmt: skip


def _encoder_inputs(agent, batch):
    """The pixels the image encoder receives during one update: (next_obs for the target, obs for
    the critic and auxiliary losses)."""
    seen = []
    hook = agent.encoder.image.register_forward_pre_hook(lambda module, args: seen.append(args[0].clone()))
    agent.train_step(batch)
    hook.remove()
    assert len(seen) == 2
    return seen


def _is_a_shift(shifted, image, pad):
    padded = np.pad(image, ((0, 0), (pad, pad), (pad, pad)), mode="edge")
    size = image.shape[-1]
    return any(
        np.array_equal(shifted, padded[:, dy : dy + size, dx : dx + size])
        for dy in range(2 * pad + 1)
        for dx in range(2 * pad + 1)
    )


def test_the_critic_sees_augmented_pixels():
    batch = _batch()
    agent = _agent()
    next_seen, seen = _encoder_inputs(agent, batch)
    assert seen.requires_grad is False and seen.dtype == torch.uint8
    for shown, raw in ((seen, batch["images"]), (next_seen, batch["next_images"])):
        shown = _host(shown)
        assert (shown != raw).any(axis=(1, 2, 3)).mean() > 0.5  # most samples shifted
        assert all(_is_a_shift(shown[i], raw[i], agent.pad) for i in range(len(raw)))
    # and the critic's input h is the encoding of those shifted pixels
    plain = _agent(augment=False)
    next_seen, seen = _encoder_inputs(plain, batch)
    np.testing.assert_array_equal(_host(seen), batch["images"])
    np.testing.assert_array_equal(_host(next_seen), batch["next_images"])


def test_auxiliary_loss_decreases_on_a_fixed_labelled_batch():
    agent = _agent(augment=False)
    batch = _batch(seed=1)
    losses = [agent.train_step(batch)["aux_loss"] for _ in range(40)]
    assert losses[0] == pytest.approx(np.log(3.0), abs=0.1)  # chance level at the start
    assert np.mean(losses[-5:]) < 0.6 * np.mean(losses[:5])
    no_aux = _agent(aux=False)
    assert "aux_loss" not in no_aux.train_step(batch)


def test_one_update_is_deterministic_under_a_seed():
    """On the CPU. Not on a GPU: there cuDNN's backward convolutions and the replicate padding's
    backward sum with atomic adds in an order that varies between calls, and two agents of one
    seed differed after one update (an H100, benchmarks/results/rlad_update_gpu.md)."""
    first, second = _agent(seed=5, device="cpu"), _agent(seed=5, device="cpu")
    assert first.train_step(_batch()) == second.train_step(_batch())
    for a, b in zip(first.encoder.parameters(), second.encoder.parameters(), strict=True):
        assert torch.equal(a, b)
    for a, b in zip(first.actor.parameters(), second.actor.parameters(), strict=True):
        assert torch.equal(a, b)
    third = _agent(seed=6, device="cpu")
    assert third.train_step(_batch()) != first.train_step(_batch())


def test_alix_strength_is_learned_only_by_its_dual_gradient():
    agent = _agent()
    start = agent.encoder.image.strength.item()
    metrics = agent.train_step(_batch())
    assert metrics["alix_strength"] != start and 0.0 <= metrics["alix_strength"] <= 1.0
    groups = agent.critic_optimizer.param_groups
    assert groups[1]["params"] == [agent.encoder.image.strength]
    assert groups[1]["lr"] == 2e-3 and groups[1]["betas"] == (0.5, 0.999)
    assert "alix_strength" not in _agent(alix=False).train_step(_batch())


def test_drq_preset_and_save_load(tmp_path):
    drq = get_algo("drq").build("drq", _Env(), 0, SMALL, None)
    assert (drq.config.alix, drq.config.aux, drq.config.waypoint_encoder) == (False, False, "mlp")
    agent = _agent()
    agent.train_step(_batch())
    agent.save(tmp_path / "rlad.zip")
    loaded = get_algo("rlad").load("rlad", tmp_path / "rlad.zip", None)
    obs = {key: np.asarray(space.sample()) for key, space in SPACE.spaces.items()}
    np.testing.assert_array_equal(agent.predict(obs)[0], loaded.predict(obs)[0])
    assert loaded.encoder.image.strength.item() == agent.encoder.image.strength.item()


class _Env:
    observation_space, action_space = SPACE, ACTIONS


# --- the command line ---------------------------------------------------------------------------
runner = CliRunner()
TOWN = ["--env", "town", "--obs", "camera:width=44:height=44:stack=3,waypoints,measurements:stack=3",
        "--action", "target_speed", "--traffic", "empty"]  # fmt: skip
TINY = ["-H", "learning_starts=12", "-H", "batch_size=4", "-H", "buffer_size=64", "-H", "hidden_size=32",
        "-H", "log_interval=10"]  # fmt: skip


def test_train_and_resume_from_the_command_line(tmp_path):
    config = tmp_path / "run.yaml"
    config.write_text(yaml.safe_dump({"env_options": {"duration_s": 2}}))
    runs = tmp_path / "runs"
    args = ["train", "--algo", "rlad", *TOWN, "--steps", "24", "--seed", "0", "--name", "r", "--config",
            str(config), "--runs-dir", str(runs), "--eval-every", "24", "--eval-episodes", "1",
            "--checkpoint-every", "12", "--waypoint-encoder", "mlp", "--no-augment", *TINY]  # fmt: skip
    result = runner.invoke(app, args, catch_exceptions=False)
    assert result.exit_code == 0, result.output
    run_dir = runs / "r"
    saved = yaml.safe_load((run_dir / "config.yaml").read_text())
    assert saved["hyperparams"]["waypoint_encoder"] == "mlp" and saved["hyperparams"]["augment"] is False
    manifest = json.loads((run_dir / "checkpoints" / "latest.json").read_text())
    assert manifest["steps"] == 24 and manifest["replay_buffer"] is True
    result = runner.invoke(app, ["train", "--resume", str(run_dir), "--steps", "36"], catch_exceptions=False)
    assert result.exit_code == 0, result.output
    assert json.loads((run_dir / "checkpoints" / "latest.json").read_text())["steps"] == 36
    agent = get_algo("rlad").load("rlad", run_dir / "model.zip", None)
    assert agent.num_timesteps == 36 and agent.config.augment is False


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--algo", "rlad", *TOWN[:4], "--action", "grid"], "cannot take 'grid' actions"),
        (["--algo", "rlad", "--env", "town", "--obs", "waypoints,measurements", "--action", "target_speed"],
         "needs a camera, waypoints and measurements"),
        (["--algo", "ppo", *TOWN, "--no-alix"], "unknown hyperparameter 'alix' for 'ppo'"),
        (["--algo", "rlad", *TOWN, "--waypoint-encoder", "lstm"], "waypoint_encoder must be one of"),
    ],
)  # fmt: skip
def test_bad_combinations_are_one_line_usage_errors(tmp_path, args, message):
    result = runner.invoke(app, ["train", *args, "--steps", "10", "--runs-dir", str(tmp_path / "runs")])
    assert result.exit_code == 2
    lines = result.output.strip().splitlines()
    assert len(lines) == 1 and message in lines[0], result.output
    assert not (tmp_path / "runs").exists() or not any((tmp_path / "runs").iterdir())


def test_device_choice():
    from drivelab.errors import UsageError

    assert _agent(device="cpu").device == torch.device("cpu")
    assert _agent().device.type == ("cuda" if torch.cuda.is_available() else "cpu")
    with pytest.raises(UsageError, match="device must be auto, cpu, cuda or cuda:N"):
        _agent(device="tpu")


def _fill(agent, transitions=40):
    """The same random transitions into ``agent``'s replay whatever its frame store."""
    rng = np.random.default_rng(2)
    replay = agent.replay_buffer

    def record():
        frame = rng.integers(0, 256, (3, 44, 44), dtype=np.uint8)
        return frame, rng.normal(size=(10, 2)), rng.uniform(-1, 1, 6), int(rng.integers(0, 3))

    replay.start_episode(*record())
    for _ in range(transitions):
        replay.add(rng.uniform(-1, 1, 2), float(rng.normal()), False, *record())


def test_replay_frames_on_the_device_train_exactly_as_on_the_host():
    from drivelab.errors import UsageError

    # on the CPU even where a GPU is present: cuDNN's backward passes need not be bit-reproducible
    host = _agent(seed=4, replay_frames="host", device="cpu")
    device = _agent(seed=4, replay_frames="device", device="cpu")
    if not torch.cuda.is_available():  # auto keeps the frames on the host when the networks are on the CPU
        assert _agent().replay_buffer.frame_device is None
    assert host.replay_buffer.frame_device is None and device.replay_buffer.frame_device == device.device
    for agent in (host, device):
        _fill(agent)
    assert isinstance(host.replay_buffer.frames, np.ndarray)
    assert isinstance(device.replay_buffer.frames, torch.Tensor)
    assert device.replay_buffer.frames.device == device.device
    assert [host.train_step() for _ in range(2)] == [device.train_step() for _ in range(2)]
    with pytest.raises(UsageError, match="replay_frames must be one of auto, host, device"):
        _agent(replay_frames="disk")


def test_a_checkpointed_replay_loads_where_the_loading_agent_keeps_frames(tmp_path):
    saved = _agent(replay_frames="device")
    _fill(saved)
    saved.save_replay_buffer(tmp_path / "replay.npz")
    for choice, kind in (("host", np.ndarray), ("device", torch.Tensor)):
        agent = _agent(replay_frames=choice)
        agent.load_replay_buffer(tmp_path / "replay.npz")
        assert isinstance(agent.replay_buffer.frames, kind), choice
        np.testing.assert_array_equal(_host(agent.replay_buffer.frames), _host(saved.replay_buffer.frames))


def test_checkpoints_keep_the_replay_of_a_long_run(monkeypatch):
    """RLAD's replay is checkpointed up to its own limit (100 k transitions at 84x84: 2.2 GB), above
    the 512 MiB under which other agents' replays are; without it a resume would start empty."""
    from drivelab.training import checkpoints

    records = int(100_000 * 1.05) + 1
    assert 2 * records * 3 * 84 * 84 < RLAD.replay_checkpoint_limit_bytes < 2 * records * 3 * 256 * 256
    agent = _agent()
    frames = agent.replay_buffer.observations["frames"].nbytes
    assert checkpoints._replay_fits(agent)
    monkeypatch.setattr(checkpoints, "REPLAY_LIMIT_BYTES", frames)  # the default limit: too small
    assert checkpoints._replay_fits(agent)
    monkeypatch.setattr(type(agent), "replay_checkpoint_limit_bytes", frames)
    assert not checkpoints._replay_fits(agent)
