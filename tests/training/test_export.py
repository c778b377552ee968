"""``drivelab export``: a run's SB3 model in stable-baselines3's own format, which SB3's ``load``
reads and which acts as drivelab's model does; refusals are one line and write nothing."""

import zipfile

import numpy as np
import pytest
import stable_baselines3
import torch
from typer.testing import CliRunner

import drivelab
from drivelab.cli import app
from drivelab.training import run as run_module
from tests.training.tiny_runs import error_line, met_observations, tiny_config, tree

pytestmark = pytest.mark.usefixtures("one_torch_thread")
runner = CliRunner()
NET = {"policy_kwargs": {"net_arch": [16]}}
OFF_POLICY = {"learning_starts": 32, "buffer_size": 500, "batch_size": 16, **NET}
RUNS = {
    "ppo": {},  # tiny_config's own: PPO, meta actions
    "a2c": {"algo": "a2c", "hyperparams": {"n_steps": 8, **NET}},
    "dqn": {"algo": "dqn", "hyperparams": OFF_POLICY},
    "sac": {"algo": "sac", "action": "continuous", "hyperparams": OFF_POLICY},
}


def _observations(env, count: int) -> np.ndarray:
    """A batch of ``count`` observations met along random actions, and as many drawn from the
    observation space (a tiny policy on an empty road acts alike on the first)."""
    env.observation_space.seed(0)
    drawn = [env.observation_space.sample() for _ in range(count)]
    return np.stack(met_observations(env, count) + drawn)


@pytest.mark.parametrize("algo", list(RUNS))
def test_sb3_loads_the_export_and_acts_as_drivelabs_model(tmp_path, algo):
    run_dir = run_module.train(tiny_config(**RUNS[algo]), tmp_path / "runs")
    before = tree(run_dir)
    out = tmp_path / "out" / "model.zip"
    out.parent.mkdir()
    result = runner.invoke(app, ["export", str(run_dir), str(out)])
    assert result.exit_code == 0, result.output
    sb3_class = {"ppo": "PPO", "a2c": "A2C", "dqn": "DQN", "sac": "SAC"}[algo]
    assert f"stable_baselines3.{sb3_class}.load(" in result.output
    assert tree(run_dir) == before  # the run directory is read, not written
    assert "data" in zipfile.ZipFile(out).namelist()  # SB3's own format (its pickles inside)
    assert list(out.parent.iterdir()) == [out]  # no temporary left beside it

    exported = getattr(stable_baselines3, sb3_class).load(out, device="cpu")
    model = drivelab.load(run_dir)
    assert exported.num_timesteps == model.num_timesteps == 128
    observations = _observations(model.make_env(), 32)
    expected, _ = model.predict(observations)
    got, _ = exported.predict(observations, deterministic=True)
    np.testing.assert_array_equal(got, expected)
    if algo != "dqn":  # a Q-network this small ranks the actions alike on every one
        assert len(np.unique(expected, axis=0)) > 1  # observations the policy tells apart
    weights, exported_weights = model.agent.policy.state_dict(), exported.policy.state_dict()
    assert weights.keys() == exported_weights.keys()
    assert all(torch.equal(weights[name], exported_weights[name]) for name in weights)


def test_refusals_are_one_line_and_write_nothing(tmp_path):
    run_dir = run_module.train(tiny_config(), tmp_path / "runs")
    (tmp_path / "folder.zip").mkdir()
    before = tree(tmp_path)
    cases = [
        ([str(run_dir), str(tmp_path / "model.pkl")], "must end in .zip"),
        ([str(run_dir), str(run_dir / "sb3.zip")], "is inside the run directory"),
        ([str(run_dir), str(run_dir / "checkpoints" / "sb3.zip")], "is inside the run directory"),
        ([str(run_dir), str(tmp_path / "missing" / "sb3.zip")], "does not exist"),
        ([str(run_dir), str(tmp_path / "folder.zip")], "is a directory"),
        (["blocks-ppo", str(tmp_path / "sb3.zip")], "'ppo_own' agent, drivelab's own"),
        ([str(tmp_path / "nothing"), str(tmp_path / "sb3.zip")], "does not exist"),
    ]
    for arguments, message in cases:
        result = runner.invoke(app, ["export", *arguments])
        assert result.exit_code == 2, (arguments, result.output)
        error_line(result.output, message)
    assert tree(tmp_path) == before


def test_export_help_says_the_file_is_for_trusted_use():
    result = runner.invoke(app, ["export", "--help"])
    assert result.exit_code == 0
    text = " ".join(result.output.split())
    assert "trusted" in text and "pickles" in text and "never reads the exported file" in text
