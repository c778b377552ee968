"""Imitation of the rule-based expert: behaviour cloning learns the expert's actions, DAgger aggregates
the states its mixture policy visits (labelled by the expert), datasets and agents save safely."""

import numpy as np
import pytest
from stable_baselines3.common.vec_env import VecEnvWrapper

from drivelab.agents import bc as bc_module
from drivelab.agents.bc import BehaviourCloning
from drivelab.agents.dagger import DAgger
from drivelab.agents.expert import RuleBasedExpert
from drivelab.agents.imitation_data import Demonstrations, action_agreement, generate_demonstrations
from drivelab.agents.registry import get_algo
from drivelab.agents.sb3_env import SB3VecEnv
from drivelab.agents.storage import read_arrays
from drivelab.envs.actions import make_action
from drivelab.envs.core import DriveEnv
from drivelab.envs.vector import VectorDriveEnv

# the learner sees the expert's own inputs here (a privileged learner, cloned in seconds by an
# MLP); the expert's waypoints and affordances are among them, so its labels can be re-derived
PRIVILEGED = "waypoints,affordances,measurements"
ACTIONS = make_action("target_speed").space
FAST = {"epochs": 40, "batch_size": 64, "learning_rate": 3e-3}


@pytest.fixture(scope="module")
def demonstrations():
    """(training data: 8 worlds of seed 0, held-out data: 8 other worlds of seed 100)."""
    train = generate_demonstrations(1600, num_worlds=8, seed=0, obs=PRIVILEGED, validation_fraction=0.2)
    held_out = generate_demonstrations(400, num_worlds=8, seed=100, obs=PRIVILEGED)
    return train, held_out


def _expert_labels(observations) -> np.ndarray:
    """The expert's actions re-derived from stored observations that contain its inputs."""
    expert = RuleBasedExpert(_expert_space(), ACTIONS)
    views = zip(observations["waypoints"], observations["affordances"], strict=True)
    return np.stack([expert.predict({"waypoints": w, "affordances": a})[0] for w, a in views])


def _expert_space():
    from gymnasium import spaces

    from drivelab.perception.affordances import Affordances
    from drivelab.perception.waypoints import Waypoints

    return spaces.Dict({"waypoints": Waypoints().space, "affordances": Affordances().space})


def test_demonstrations_are_the_experts_actions_in_k_worlds(demonstrations):
    train, _ = demonstrations
    assert len(train) == 1600 and train.actions.shape == (1600, 2)
    assert train.observations["waypoints"].shape == (1600, 10, 2)
    np.testing.assert_array_equal(_expert_labels(train.observations), train.actions)
    assert ACTIONS.contains(train.actions.min(axis=0)) and ACTIONS.contains(train.actions.max(axis=0))
    assert 0.1 < train.validation.mean() < 0.3  # ~ validation_fraction 0.2
    assert train.actions[:, 0].std() > 0.1  # it stops and goes: not one constant action


def test_bc_lowers_its_loss_and_imitates_the_expert_on_held_out_states(demonstrations):
    train, held_out = demonstrations
    agent = BehaviourCloning(train.observation_space, ACTIONS, 0, FAST)
    agent.replay_buffer = train
    training, validation = train.split()
    before = agent.evaluate_on(training)
    metrics = agent.fit()
    assert metrics["loss"] < before["loss"] / 10
    assert metrics["validation_loss"] < before["loss"] / 10
    predicted = agent.act(held_out.observations)
    agreement = action_agreement(predicted, held_out.actions)
    rng = np.random.default_rng(0)
    random_actions = rng.uniform(ACTIONS.low, ACTIONS.high, size=held_out.actions.shape)
    untrained = BehaviourCloning(train.observation_space, ACTIONS, 1, FAST).act(held_out.observations)
    assert agreement >= 0.8, agreement
    assert action_agreement(random_actions, held_out.actions) < 0.1
    assert action_agreement(untrained, held_out.actions) < 0.5
    assert metrics["validation_agreement"] >= 0.8


def test_gaussian_nll_loss_also_learns(demonstrations):
    train, _ = demonstrations
    agent = BehaviourCloning(train.observation_space, ACTIONS, 0, {**FAST, "loss": "nll", "epochs": 20})
    agent.replay_buffer = train
    before = agent.evaluate_on(train.split()[1])["loss"]
    metrics = agent.fit()
    assert metrics["validation_loss"] < before - 2.0  # log-likelihood units
    assert agent.policy.log_std[1].item() < -1.5  # the steering's σ shrank from its e⁻¹ start


class RecordActions(VecEnvWrapper):
    """Keeps every action batch sent to the worlds."""

    def __init__(self, venv) -> None:
        super().__init__(venv)
        self.sent: list[np.ndarray] = []

    def reset(self):
        return self.venv.reset()

    def step_async(self, actions):
        self.sent.append(np.array(actions, copy=True))
        self.venv.step_async(actions)

    def step_wait(self):
        return self.venv.step_wait()


def test_dagger_aggregates_the_states_its_mixture_visits(monkeypatch):
    worlds = 4
    env = RecordActions(
        SB3VecEnv(VectorDriveEnv(worlds, scenario="town", obs=PRIVILEGED, action="target_speed",
                                 autoreset_mode="same_step"))
    )  # fmt: skip
    env.seed(5)
    learner_actions = []
    original = bc_module.collect

    def collect(*args, learner=None, **kwargs):
        def recorded(obs):
            actions = learner(obs)
            learner_actions.append(actions)
            return actions

        return original(*args, learner=recorded, **kwargs)

    monkeypatch.setattr(bc_module, "collect", collect)
    agent = DAgger(env.observation_space, env.action_space, 0, {**FAST, "epochs": 2, "round_steps": 80,
                                                               "beta_decay": 0.0}, env)  # fmt: skip
    sizes = []
    for _ in range(3):
        agent.learn(80, reset_num_timesteps=False)
        sizes.append(len(agent.demonstrations))
    assert sizes == [80, 160, 240]  # each iteration adds the states it visited, nothing is dropped
    data = agent.demonstrations
    np.testing.assert_array_equal(np.bincount(data.iterations), [0, 80, 80, 80])
    np.testing.assert_array_equal(_expert_labels(data.observations), data.actions)  # expert labels
    sent = np.concatenate(env.sent)
    # β₁ = 1: the expert drove the first iteration; β = 0 after: the learner drove every world
    np.testing.assert_array_equal(sent[:80], data.actions[:80])
    np.testing.assert_array_equal(sent[80:], np.concatenate(learner_actions))
    assert not np.allclose(sent[80:], data.actions[80:])  # the learner went its own way somewhere


def test_dagger_beta_schedule():
    agent = DAgger(_expert_space(), ACTIONS, 0, {"beta_decay": 0.5})
    assert [agent.beta(i) for i in (1, 2, 3)] == [1.0, 0.5, 0.25]
    assert BehaviourCloning(_expert_space(), ACTIONS, 0).beta(5) == 1.0


@pytest.mark.parametrize("algo", ["bc", "dagger"])
def test_save_load_gives_identical_predictions(algo, tmp_path):
    env = DriveEnv("town", obs="topdown:size=36:lights=true,waypoints,measurements", action="target_speed",
                   duration_s=6, seed=0)  # fmt: skip
    agent = get_algo(algo).build(algo, env, 0, {"round_steps": 30, "epochs": 1, "batch_size": 16}, None)
    agent.learn(60)
    assert agent.num_timesteps == 60 and len(agent.demonstrations) == 60 and agent._n_updates == 2
    agent.save(tmp_path / "agent.zip")
    loaded = get_algo(algo).load(algo, tmp_path / "agent.zip", None)
    assert loaded.num_timesteps == 60 and loaded._n_updates == 2
    observations = agent.demonstrations.observations
    np.testing.assert_array_equal(agent.act(observations), loaded.act(observations))
    obs, _ = env.reset(seed=3)
    np.testing.assert_array_equal(agent.predict(obs)[0], loaded.predict(obs)[0])
    # the dataset: an npz of plain arrays that reloads to the same samples
    agent.save_replay_buffer(tmp_path / "data.npz")
    assert all(array.dtype != object for array in read_arrays(tmp_path / "data.npz").values())
    loaded.load_replay_buffer(tmp_path / "data.npz")
    for key, value in agent.demonstrations.state_arrays().items():
        np.testing.assert_array_equal(loaded.demonstrations.state_arrays()[key], value)


def test_demonstrations_file_round_trip_and_shape_check(demonstrations, tmp_path):
    train, _ = demonstrations
    train.save(tmp_path / "demos.npz")
    again = Demonstrations.load(tmp_path / "demos.npz", train.observation_space, 2)
    assert len(again) == len(train) and again.validation_fraction == train.validation_fraction
    np.testing.assert_array_equal(again.observations["affordances"], train.observations["affordances"])
    np.testing.assert_array_equal(again.validation, train.validation)
    other = DriveEnv("town", obs="waypoints:count=5,affordances,measurements", action="target_speed")
    with pytest.raises(ValueError, match="demonstrations of shape"):
        Demonstrations.load(tmp_path / "demos.npz", other.observation_space, 2)


def test_cloned_weights_load_into_ppo_own():
    """BC's policy is PPO's network: its weights are a starting point for fine-tuning."""
    env = DriveEnv("town", obs="topdown:size=36,waypoints,measurements", action="target_speed")
    cloned = BehaviourCloning(env.observation_space, env.action_space, 0)
    ppo = get_algo("ppo_own").agent_class()(env.observation_space, env.action_space, 1)
    ppo.policy.load_state_dict(cloned.policy.state_dict())
    obs, _ = env.reset(seed=0)
    ppo_action = np.clip(ppo.predict(obs)[0], env.action_space.low, env.action_space.high)
    np.testing.assert_array_equal(ppo_action, cloned.predict(obs)[0])


def test_evaluations_during_training_leave_the_learner_unchanged(tmp_path):
    """Acting greedily (an evaluation) draws nothing from the agent's random stream, so a DAgger run
    evaluated every round learns exactly the weights of one evaluated only at its end."""
    import torch

    from drivelab.config import build_config
    from drivelab.training import run as run_module

    def trained(eval_every: int) -> dict:
        config = build_config(
            {"algo": "dagger", "env": "town", "obs": PRIVILEGED, "action": "target_speed", "n_envs": 4,
             "steps": 240, "seed": 3, "name": f"every-{eval_every}", "eval_every": eval_every,
             "eval_episodes": 1, "env_options": {"duration_s": 4},
             "hyperparams": {**FAST, "epochs": 2, "round_steps": 80}}
        )  # fmt: skip
        run_dir = run_module.train(config, tmp_path)
        return get_algo("dagger").load("dagger", run_dir / "model.zip", None).policy.state_dict()

    every_round, at_the_end = trained(80), trained(240)
    assert every_round.keys() == at_the_end.keys()
    for name, tensor in every_round.items():
        torch.testing.assert_close(tensor, at_the_end[name], rtol=0, atol=0, msg=name)


def test_dagger_on_the_racetrack_labels_with_its_teacher_at_the_actions_speed():
    """On the racetrack the teacher is the expert with the run's rules (``expert_*``) and the
    target_speed action's ``max_speed_mps``: its labels are that expert's actions."""
    vector = VectorDriveEnv(2, scenario="racetrack", obs=PRIVILEGED, action="target_speed",
                            action_options={"max_speed_mps": 20.0}, autoreset_mode="same_step")  # fmt: skip
    env = SB3VecEnv(vector)
    env.seed(3)
    rules = {"expert_cruise_speed_mps": 15.0, "expert_lateral_accel_mps2": 6.0}
    agent = DAgger(env.observation_space, env.action_space, 0, {**rules, "round_steps": 60, "epochs": 1}, env)
    agent.learn(120)
    data = agent.demonstrations
    assert len(data) == 120 and agent._n_updates == 2
    teacher = {"cruise_speed_mps": 15.0, "lateral_accel_mps2": 6.0, "max_speed_mps": 20.0}
    expert = RuleBasedExpert(_expert_space(), ACTIONS, 0, teacher)
    views = zip(data.observations["waypoints"], data.observations["affordances"], strict=True)
    expected = np.stack([expert.predict({"waypoints": w, "affordances": a})[0] for w, a in views])
    np.testing.assert_array_equal(expected, data.actions)
    assert not np.array_equal(expected, _expert_labels(data.observations))  # the town's rules differ
