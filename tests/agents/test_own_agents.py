"""Our own agents behind the run machinery: save/load, determinism, callbacks, resume, bad input."""

import csv
import json

import numpy as np
import pytest
import torch
from stable_baselines3.common.callbacks import BaseCallback

from drivelab.agents.registry import check_combination, get_algo
from drivelab.agents.sb3 import build_sb3
from drivelab.config import build_config
from drivelab.envs.core import DriveEnv
from drivelab.errors import UsageError
from drivelab.training import run as run_module
from drivelab.training.evaluate import evaluate_run

ENV = {"backend": "fast", "traffic": "regular", "duration_s": 6}
CASES = {
    "dueling_ddqn": ("lidar:beams=24:stack=3,ego_state:features=10:stack=3", "grid",
                     {"learning_starts": 20, "batch_size": 8, "target_update_interval": 10,
                      "log_interval": 20}),
    "a2c_own": ("topdown:size=36", "continuous", {"n_steps": 8}),
    "ppo_own": ("topdown:size=36,ego_state,lidar:beams=24", "continuous",
                {"n_steps": 16, "batch_size": 8, "n_epochs": 2, "clip_range_value": 0.2}),
}  # fmt: skip


def _env(algo, seed=0):
    obs, action, _ = CASES[algo]
    return DriveEnv("highway", obs=obs, action=action, seed=seed, **ENV)


def _agent(algo, seed=0, **extra):
    env = _env(algo, seed)
    hyperparams = {**CASES[algo][2], **extra}
    return get_algo(algo).build(algo, env, seed, hyperparams, None), env


@pytest.mark.parametrize("algo", sorted(CASES))
def test_save_load_round_trip_gives_identical_actions(algo, tmp_path):
    agent, env = _agent(algo)
    agent.learn(40)
    assert agent.num_timesteps == 40
    agent.save(tmp_path / "agent.zip")
    loaded = get_algo(algo).load(algo, tmp_path / "agent.zip", None)
    assert loaded.num_timesteps == 40
    obs, _ = env.reset(seed=3)
    for _ in range(5):
        action, _ = agent.predict(obs, deterministic=True)
        np.testing.assert_array_equal(action, loaded.predict(obs, deterministic=True)[0])
        obs, _, terminated, truncated, _ = env.step(action)
        if terminated or truncated:  # an ended episode is reset before the next step
            obs, _ = env.reset()


def test_an_agent_writes_nothing_until_a_run_gives_it_a_logger(tmp_path, monkeypatch):
    """SB3's ``configure(None, ...)`` makes a folder under the temp directory: an agent built and
    trained outside a run (tests, notebooks) must leave no such folder behind."""
    monkeypatch.setattr("tempfile.tempdir", str(tmp_path))
    monkeypatch.delenv("SB3_LOGDIR", raising=False)
    agent, _ = _agent("a2c_own")
    agent.learn(8)
    assert sorted(p.name for p in tmp_path.glob("SB3-*")) == []


@pytest.mark.parametrize("algo", ["dueling_ddqn", "ppo_own"])
def test_same_seed_same_training(algo):
    first, _ = _agent(algo, seed=4)
    second, _ = _agent(algo, seed=4)
    first.learn(40)
    second.learn(40)
    for a, b in zip(first._state().values(), second._state().values(), strict=True):
        if isinstance(a, dict) and "state" not in a:  # network state dicts (optimizers differ in layout)
            for key in a:
                torch.testing.assert_close(a[key], b[key])


class StopAt(BaseCallback):
    def __init__(self, steps):
        super().__init__()
        self.steps, self.calls, self.ended = steps, 0, False

    def _on_step(self):
        self.calls += 1
        return self.num_timesteps < self.steps

    def _on_training_end(self):
        self.ended = True


@pytest.mark.parametrize("algo", ["dueling_ddqn", "a2c_own"])
def test_callback_is_called_every_step_and_can_stop(algo):
    agent, _ = _agent(algo)
    callback = StopAt(13)
    agent.learn(100, callback=callback)
    assert agent.num_timesteps == 13 and callback.calls == 13 and callback.ended
    agent.learn(7, reset_num_timesteps=False)  # continues: 7 more steps
    assert agent.num_timesteps == 20


def test_actions_are_in_range_and_greedy_is_deterministic():
    agent, env = _agent("ppo_own")
    obs, _ = env.reset(seed=0)
    sampled = np.array([agent.predict(obs, deterministic=False)[0] for _ in range(20)])
    assert sampled.shape == (20, 2) and np.all(np.abs(sampled) <= 1.0) and sampled.std(axis=0).min() > 0
    np.testing.assert_array_equal(agent.predict(obs)[0], agent.predict(obs)[0])


def _config(case, **overrides):
    obs, action, hyperparams = CASES[case]
    values = {
        "algo": case, "env": "highway", "obs": obs, "action": action, "steps": 60, "seed": 2,
        "name": case, "eval_every": 30, "eval_episodes": 1, "hyperparams": hyperparams,
        "checkpoint_every": 30, "env_options": {"duration_s": 6}, "backend": "fast",
    }  # fmt: skip
    values.update(overrides)
    return build_config(values)


@pytest.mark.parametrize("algo", ["dueling_ddqn", "ppo_own"])
def test_run_directory_resume_and_evaluation(algo, tmp_path):
    run_dir = run_module.train(_config(algo), tmp_path)
    manifest = json.loads((run_dir / "checkpoints/latest.json").read_text())
    assert manifest["steps"] == 60
    assert manifest["replay_buffer"] is (algo == "dueling_ddqn")
    with (run_dir / "progress.csv").open() as handle:
        columns = set(next(csv.reader(handle)))
    expected = (
        {"train/epsilon", "train/td_error", "train/loss"}
        if algo == "dueling_ddqn"
        else {"train/clip_fraction"}
    )
    assert expected | {"train/learning_rate", "time/total_timesteps"} <= columns
    run_module.resume(run_dir, steps=90)
    assert json.loads((run_dir / "checkpoints/latest.json").read_text())["steps"] == 90
    report = evaluate_run(run_dir, episodes=1)
    assert report["algo"] == algo and report["episodes"] == 1


@pytest.mark.parametrize(
    "algo, obs, action, hyperparams, message",
    [
        ("dueling_ddqn", "topdown", "grid", {}, r"cannot read 'image' observations; it reads vectors \("),
        ("ppo_own", "birdeye", "continuous", {}, r"cannot read the observation Box\(.*3\), uint8\)"),
        ("a2c_own", "topdown", "seed_line", {}, "cannot take 'seed_line'"),
        ("ppo_own", "kinematics", "meta", {"distribution": "beta"}, "discrete actions take the categorical"),
        ("a2c_own", "kinematics", "continuous", {"distribution": "gauss"}, "distribution must be one of"),
        ("ppo_own", "kinematics", "meta", {"net_arch": "64,wide"}, "net_arch must be layer widths"),
        ("ppo_own", "kinematics", "continuous", {"clip_range": -1}, "clip_range > 0"),
        ("ppo_own", "kinematics", "continuous", {"n_epoch": 3}, "unknown hyperparameter 'n_epoch'"),
        ("dueling_ddqn", "kinematics", "meta", {"batch_size": "big"}, "must be an integer"),
        ("dueling_ddqn", "kinematics", "meta", {"stream_norm": "group"}, "stream_norm"),
    ],
)
def test_impossible_combinations_fail_before_training(tmp_path, algo, obs, action, hyperparams, message):
    config = _config(algo, obs=obs, action=action, hyperparams=hyperparams)
    with pytest.raises(UsageError, match=message):
        run_module.train(config, tmp_path)
    assert not any(tmp_path.iterdir())


def test_sb3_runs_the_seed_networks():
    env = _env("ppo_own")
    model = build_sb3("ppo", env, 0, {"features_extractor": "seed", "n_steps": 16, "batch_size": 8}, None)
    assert type(model.policy.features_extractor).__name__ == "FusionExtractor"
    model.learn(16)
    with pytest.raises(UsageError, match="features_extractor=seed"):
        build_sb3(
            "ppo",
            DriveEnv("highway", obs="kinematics", backend="fast"),
            0,
            {"features_extractor": "seed"},
            None,
        )
    with pytest.raises(UsageError):
        check_combination("dueling_ddqn", "continuous")


def test_sb3_reads_the_vehicles_as_a_set_with_attention():
    """``features_extractor=attention``: SB3's DQN on the ego-attention encoder (its Q layers after
    it), acting and learning on kinematics rows + the clock; a flat observation is refused."""
    env = DriveEnv("intersection", obs="kinematics:flatten=false,clock", action="meta", backend="fast")
    model = build_sb3(
        "dqn", env, 0, {"features_extractor": "attention", "learning_starts": 8, "batch_size": 8}, None
    )
    extractor = model.policy.q_net.features_extractor
    assert type(extractor).__name__ == "AttentionExtractor" and extractor.features_dim == 128
    obs, _ = env.reset(seed=0)
    shuffled = {**obs, "kinematics": obs["kinematics"][[0, 2, 1, *range(3, len(obs["kinematics"]))]]}
    assert model.predict(shuffled, deterministic=True)[0] == model.predict(obs, deterministic=True)[0]
    model.learn(32)
    with pytest.raises(
        UsageError, match="features_extractor=attention: encoder attention needs the vehicles"
    ):
        build_sb3("dqn", DriveEnv("highway", obs="kinematics", backend="fast"), 0,
                  {"features_extractor": "attention"}, None)  # fmt: skip


def test_sb3_dqn_on_a_dict_observation_checkpoints_its_replay(tmp_path):
    # the seed's DDQN input given to SB3's DQN (a DictReplayBuffer) must checkpoint like ours
    config = _config("dueling_ddqn", algo="dqn", name="dqn", hyperparams={"learning_starts": 20})
    run_dir = run_module.train(config, tmp_path)
    assert json.loads((run_dir / "checkpoints/latest.json").read_text())["replay_buffer"] is True


@pytest.mark.parametrize("algo", ["a2c_own", "ppo_own"])
def test_on_policy_agents_collect_from_k_worlds(algo, monkeypatch):
    """K = 4 worlds of one VectorDriveEnv (behind SB3's VecEnv): every update sees n_steps x K
    transitions, and the steps of all worlds count."""
    from stable_baselines3.common.vec_env import VecMonitor

    from drivelab.agents.sb3_env import SB3VecEnv
    from drivelab.envs.vector import VectorDriveEnv

    obs, action, hyperparams = CASES[algo]
    vector = VectorDriveEnv(4, "highway", obs=obs, action=action, autoreset_mode="same_step", **ENV)
    env = VecMonitor(SB3VecEnv(vector))
    env.seed(2)
    agent = get_algo(algo).build(algo, env, 0, hyperparams, None)
    sizes, update = [], type(agent).update
    monkeypatch.setattr(
        type(agent),
        "update",
        lambda self, rollout: sizes.append(len(rollout.returns)) or update(self, rollout),
    )
    n_steps = hyperparams["n_steps"]
    agent.learn(3 * n_steps * 4)
    assert agent.num_timesteps == 3 * n_steps * 4
    assert sizes == [n_steps * 4] * 3
    assert agent.episode_returns  # 6 s episodes: some ended during the rollouts
    batch = env.reset()
    first = {key: value[0] for key, value in batch.items()} if isinstance(batch, dict) else batch[0]
    action, _ = agent.predict(first)
    assert action.shape == env.action_space.shape


def test_dueling_ddqn_acts_in_k_worlds_at_one_worlds_updates_per_transition(monkeypatch):
    from stable_baselines3.common.vec_env import VecMonitor

    from drivelab.agents.sb3_env import SB3VecEnv
    from drivelab.envs.vector import VectorDriveEnv

    obs, action, hyperparams = CASES["dueling_ddqn"]
    vector = VectorDriveEnv(3, "highway", obs=obs, action=action, autoreset_mode="same_step", **ENV)
    env = VecMonitor(SB3VecEnv(vector))
    env.seed(1)
    agent = get_algo("dueling_ddqn").build("dueling_ddqn", env, 0, {**hyperparams, "train_freq": 2}, None)
    updates, train_step = [], type(agent).train_step
    monkeypatch.setattr(type(agent), "train_step", lambda self, p: updates.append(1) or train_step(self, p))
    agent.learn(60)
    assert agent.num_timesteps == agent.replay_buffer.size == 60
    # from the first step of 3 that ends past learning_starts (18 -> 21) on: one update per
    # multiple of train_freq = 2 passed, i.e. 2 updates on every other step of 3 transitions
    assert len(updates) == 60 // 2 - 18 // 2
    terminals = agent.replay_buffer.terminals[:60]
    assert set(np.unique(terminals)) <= {0.0, 1.0}
