"""A run started from another run's policy (``init_from``): PPO fine-tuning of a DAgger policy.

The imitation policy's weights go into ``ppo_own``'s network as they are, so the fine-tuning run
starts acting exactly as the imitation learner; the critic's warm-up (``critic_warmup_steps``)
trains the value alone and leaves the actor untouched; a source that does not fit (other sensors,
action, network or algorithm) is refused before anything is written; and a fine-tuning run that
is interrupted and resumed ends as the one never stopped.
"""

import re
import signal

import numpy as np
import pytest
import torch
from typer.testing import CliRunner

from drivelab.cli import app
from drivelab.config import build_config
from drivelab.envs.core import DriveEnv
from drivelab.errors import UsageError
from drivelab.training import checkpoints
from drivelab.training import run as run_module
from drivelab.training.zoo import load_trained
from tests.training.test_resume import _assert_same_run, _signal_at
from tests.training.tiny_runs import error_line, met_observations

pytestmark = pytest.mark.usefixtures("one_torch_thread")
PRIVILEGED = "waypoints,affordances,measurements"
TOWN = {"env": "town", "obs": PRIVILEGED, "action": "target_speed", "traffic": "regular",
        "env_options": {"duration_s": 4}, "eval_episodes": 1}  # fmt: skip
ACTOR = ("actor_encoder", "head", "log_std")  # what the critic's warm-up must leave as it is


@pytest.fixture(scope="module")
def dagger_run(tmp_path_factory):
    """A tiny DAgger run in the town (its policy is ppo_own's network), trained once."""
    config = build_config(
        {**TOWN, "algo": "dagger", "n_envs": 4, "steps": 240, "seed": 3, "name": "dagger",
         "eval_every": 240, "hyperparams": {"epochs": 2, "batch_size": 64, "round_steps": 80}}
    )  # fmt: skip
    return run_module.train(config, tmp_path_factory.mktemp("source"))


def _fine_tuning(source, name: str, steps: int = 256, **hyperparams):
    return build_config(
        {**TOWN, "algo": "ppo_own", "n_envs": 4, "steps": steps, "seed": 5, "name": name,
         "eval_every": 128, "checkpoint_every": 64, "init_from": str(source),
         "hyperparams": {"n_steps": 16, "batch_size": 32, "n_epochs": 2, "gamma": 0.99, **hyperparams}}
    )  # fmt: skip


def _policy(run_dir, config) -> dict:
    return checkpoints.load_agent(run_dir, config).policy.state_dict()


def _actor_and_critic(state: dict) -> tuple[dict, dict]:
    """(the actor's tensors, the value head's), by ppo_own's names (BC's ``mean`` is its ``head``)."""
    state = {key.replace("mean.", "head.", 1) if key.startswith("mean.") else key: value
             for key, value in state.items()}  # fmt: skip
    actor = {key: value for key, value in state.items() if key.startswith(ACTOR)}
    return actor, {key: value for key, value in state.items() if key.startswith(("value.", "critic_encoder"))}


@pytest.mark.parametrize("shared", [True, False], ids=["shared-encoder", "own-critic-encoder"])
def test_a_fine_tuning_run_starts_as_the_imitation_policy_and_its_warm_up_trains_the_critic_alone(
    dagger_run, tmp_path, shared
):
    """With its own encoder the critic starts from a copy of the imitation policy's (BC's network
    shares one) and trains it; a shared encoder stays the actor's."""
    dagger = load_trained(dagger_run).agent
    config = _fine_tuning(
        dagger_run, "warm-up", critic_warmup_steps=256, shared_encoder=shared
    )  # all warm-up
    run_dir = run_module.train(config, tmp_path)
    tuned = checkpoints.load_agent(run_dir, config)

    dagger_actor, dagger_critic = _actor_and_critic(dagger.policy.state_dict())
    tuned_actor, tuned_critic = _actor_and_critic(tuned.policy.state_dict())
    assert dagger_actor.keys() == tuned_actor.keys() and len(dagger_actor) >= 5
    for key, value in dagger_actor.items():
        torch.testing.assert_close(tuned_actor[key], value, rtol=0, atol=0, msg=key)
    changed = {key for key in dagger_critic if not torch.equal(tuned_critic[key], dagger_critic[key])}
    assert {"value.weight", "value.bias"} <= changed
    assert any(key.startswith("critic_encoder") for key in changed) is not shared

    env = DriveEnv(**config.eval_env_kwargs())
    for obs in met_observations(env, 20):  # it acts as DAgger does (ppo_own's tanh clipped to the box)
        np.testing.assert_array_equal(tuned.predict(obs)[0], dagger.predict(obs)[0])

    progress = (run_dir / "progress.csv").read_text().splitlines()
    assert "train/critic_warmup" in progress[0] and "train/policy_loss" not in progress[0]


def test_after_the_warm_up_the_policy_gradient_moves_the_actor(dagger_run, tmp_path):
    config = _fine_tuning(dagger_run, "tuned", critic_warmup_steps=64)
    tuned_actor, _ = _actor_and_critic(_policy(run_module.train(config, tmp_path), config))
    dagger_actor, _ = _actor_and_critic(load_trained(dagger_run).agent.policy.state_dict())
    assert any(not torch.equal(tuned_actor[key], dagger_actor[key]) for key in dagger_actor)


def test_a_log_std_the_run_gives_replaces_the_sources(dagger_run, tmp_path):
    config = _fine_tuning(dagger_run, "sigma", steps=64, critic_warmup_steps=64, log_std_init=-2.0)
    tuned = _policy(run_module.train(config, tmp_path), config)
    torch.testing.assert_close(tuned["log_std"], torch.full((2,), -2.0), rtol=0, atol=0)
    dagger = load_trained(dagger_run).agent.policy.state_dict()
    torch.testing.assert_close(tuned["head.weight"], dagger["mean.weight"], rtol=0, atol=0)


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"obs": "waypoints,measurements"}, "other sensors (obs)"),
        ({"action": "continuous"}, "other action"),
        ({"env_options": {"duration_s": 4, "action_options": {"max_speed_mps": 20}}}, "other action options"),
        ({"hyperparams": {"n_steps": 16, "net_arch": "32,32"}}, "policy network is not this run's"),
        (
            {"hyperparams": {"n_steps": 16, "normalize_observations": True}},
            "policy network is not this run's",
        ),
        ({"algo": "a2c_own", "hyperparams": {"n_steps": 16, "distribution": "beta"}}, "policy network"),
        (
            {"algo": "ppo", "hyperparams": {"n_steps": 16}},
            "init_from starts ppo_own or a2c_own runs, not 'ppo'",
        ),
    ],
)
def test_a_source_that_does_not_fit_is_refused_before_anything_is_written(
    dagger_run, tmp_path, change, message
):
    config = build_config({**_fine_tuning(dagger_run, "refused").to_dict(), **change})
    with pytest.raises(UsageError, match=re.escape(message)):
        run_module.train(config, tmp_path / "runs")
    assert not (tmp_path / "runs").exists()


def test_the_command_line_names_a_missing_source_in_one_error_line(tmp_path):
    result = CliRunner().invoke(app, [
        "train", "--algo", "ppo_own", "--env", "town", "--obs", PRIVILEGED, "--action", "target_speed",
        "--steps", "256", "-H", "n_steps=64", "--init-from", str(tmp_path / "nowhere"),
        "--runs-dir", str(tmp_path / "runs"),
    ])  # fmt: skip
    assert result.exit_code == 2
    error_line(result.output, "nowhere", "does not exist")
    assert not (tmp_path / "runs").exists()


def test_an_interrupted_and_resumed_fine_tuning_run_equals_the_uninterrupted_one(
    dagger_run, tmp_path, monkeypatch
):
    """The interrupt falls after the warm-up (rollouts of 16 × 4 steps, warm-up 64): the resumed run
    starts from its checkpoint, not from the source's weights again, and its prior (``prior_kl_coef``)
    is the source's policy still."""
    reference = run_module.train(
        _fine_tuning(dagger_run, "reference", critic_warmup_steps=64, prior_kl_coef=0.5), tmp_path
    )
    _signal_at(monkeypatch, 150, signal.SIGINT)
    with pytest.raises(run_module.TrainingInterrupted, match="interrupted at step 128"):
        run_module.train(
            _fine_tuning(dagger_run, "resumed", critic_warmup_steps=64, prior_kl_coef=0.5), tmp_path
        )
    monkeypatch.undo()
    resumed = run_module.resume(tmp_path / "resumed")
    _assert_same_run(
        reference, resumed, _fine_tuning(dagger_run, "reference", critic_warmup_steps=64, prior_kl_coef=0.5)
    )


def test_runs_without_a_source_keep_the_identity_their_checkpoints_recorded():
    """The hashes drivelab computed before ``init_from`` existed: those runs still resume."""
    assert build_config({"algo": "ppo_own", "env": "highway"}).identity() == "751db57171b351aa"
    blocks = {"algo": "ppo_own", "env": "blocks", "n_envs": 4, "eval_maps": "1000:10"}
    assert build_config(blocks).identity() == "eb363b5325a2d27e"
    assert build_config({**blocks, "init_from": "runs/x"}).identity() != "eb363b5325a2d27e"
