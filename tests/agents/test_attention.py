"""The ego-attention encoder (``networks.EgoAttentionEncoder``, ``-H encoder=attention``): blind to
the other vehicles' order and to absent rows, reads a Dict's other entries, learns a task that
needs the whole set, and is saved and loaded with the policy."""

import numpy as np
import pytest
import torch
from gymnasium import spaces
from stable_baselines3.common.vec_env import VecEnv

from drivelab.agents.actor_critic import ActorCritic
from drivelab.agents.networks import EgoAttentionEncoder
from drivelab.agents.ppo import OwnPPO
from tests.agents.test_onpolicy import ScriptedWorlds

pytestmark = pytest.mark.usefixtures("one_torch_thread")

ROWS = spaces.Box(-1, 1, (6, 3), np.float32)


def _rows(batch, present, seed=0):
    """(batch, 6, 3) vehicle sets: row 0 the ego, then ``present`` others, the rest all zero."""
    rng = np.random.default_rng(seed)
    rows = np.zeros((batch, 6, 3), np.float32)
    rows[:, : present + 1, 0] = 1.0
    rows[:, : present + 1, 1:] = rng.uniform(-1, 1, (batch, present + 1, 2))
    return torch.from_numpy(rows)


def test_the_features_ignore_the_others_order_and_the_absent_rows():
    torch.manual_seed(0)
    encoder = EgoAttentionEncoder(ROWS, (16, 16))
    raw = _rows(8, present=3)
    features = encoder(raw)
    assert features.shape == (8, 16)
    shuffled = raw[:, [0, 3, 1, 2, 4, 5]]
    torch.testing.assert_close(encoder(shuffled), features)
    normed = raw.clone()
    normed[:, 4:] = torch.randn(8, 2, 3)  # what normalisation makes of absent rows does not count
    torch.testing.assert_close(encoder(normed, raw), features)
    moved = raw.clone()
    moved[:, 2, 1] += 0.5  # a present vehicle does
    assert not torch.allclose(encoder(moved), features)


def test_a_dict_observation_joins_the_other_entries_and_a_flat_set_is_refused():
    space = spaces.Dict({"kinematics": ROWS, "clock": spaces.Box(0, 1, (1,), np.float32)})
    policy = ActorCritic(space, spaces.Discrete(3), hidden=(16, 16), encoder="attention")
    obs = {"kinematics": _rows(4, present=2), "clock": torch.rand(4, 1)}
    logits, value = policy(obs)
    assert logits.shape == (4, 3) and value.shape == (4,)
    assert policy.actor_encoder.features == 32
    later = {**obs, "clock": obs["clock"] + 0.5}
    assert not torch.allclose(policy(later)[0], logits)
    with pytest.raises(ValueError, match="kinematics with flatten=false"):
        ActorCritic(spaces.Box(-1, 1, (18,), np.float32), spaces.Discrete(3), encoder="attention")
    with pytest.raises(ValueError, match="divisible by 2 heads"):
        ActorCritic(ROWS, spaces.Discrete(3), hidden=(15,), encoder="attention")


def test_output_layers_mix_the_set_with_the_other_entries():
    """``attention_output``: ReLU layers over the joined features of the set and the other entries
    (rl-agents' output layer), whose last width the heads read; refused for any other encoder."""
    space = spaces.Dict({"kinematics": ROWS, "clock": spaces.Box(0, 1, (1,), np.float32)})
    torch.manual_seed(0)
    policy = ActorCritic(
        space, spaces.Discrete(3), hidden=(16, 16), encoder="attention", attention_output=(24, 8)
    )
    encoder = policy.actor_encoder
    assert encoder.features == 8
    obs = {"kinematics": _rows(4, present=2), "clock": torch.rand(4, 1)}
    output, encoder.output = encoder.output, None
    joined = encoder(obs)  # the set's 16 features and the clock's 16
    encoder.output = output
    assert joined.shape == (4, 32)
    expected = torch.relu(output[2](torch.relu(output[0](joined))))
    torch.testing.assert_close(encoder(obs), expected)
    assert policy(obs)[0].shape == (4, 3)
    with pytest.raises(ValueError, match="attention_output needs encoder attention"):
        ActorCritic(spaces.Box(-1, 1, (18,), np.float32), spaces.Discrete(3), attention_output=(8,))


class AnyAhead(VecEnv):
    """One-step episodes: 1 to 5 other vehicles in random rows; action 1 pays when any of them
    has its second feature above 0.5, action 0 when none has: a question about the whole set."""

    def __init__(self, count=32, seed=0):
        super().__init__(count, ROWS, spaces.Discrete(2))
        self.rng = np.random.default_rng(seed)

    def _draw(self):
        rows = np.zeros((self.num_envs, 6, 3), np.float32)
        rows[:, 0, 0] = 1.0
        for k in range(self.num_envs):
            others = 1 + self.rng.permutation(5)[: self.rng.integers(1, 6)]
            rows[k, others, 0] = 1.0
            rows[k, others, 1:] = self.rng.uniform(-1, 1, (len(others), 2))
        self.good = (rows[:, 1:, 1] > 0.5).any(1)
        return rows

    def reset(self):
        return self._draw()

    def step_async(self, actions):
        self.actions = np.asarray(actions)

    def step_wait(self):
        rewards = (self.actions == self.good).astype(np.float32)
        obs = self._draw()
        infos = [{"terminal_observation": obs[k], "TimeLimit.truncated": False} for k in range(self.num_envs)]
        return obs, rewards, np.ones(self.num_envs, bool), infos

    close = ScriptedWorlds.close
    get_attr, set_attr = ScriptedWorlds.get_attr, ScriptedWorlds.set_attr
    env_method, env_is_wrapped = ScriptedWorlds.env_method, ScriptedWorlds.env_is_wrapped


def test_ppo_with_attention_learns_a_question_about_the_set_and_reloads(tmp_path):
    env = AnyAhead()
    hyperparams = {"n_steps": 4, "batch_size": 64, "n_epochs": 4, "learning_rate": 3e-3, "gamma": 0.9,
                   "encoder": "attention", "net_arch": "32,32", "normalize_observations": True}  # fmt: skip
    agent = OwnPPO(env.observation_space, env.action_space, 0, hyperparams, env)
    agent.learn(12_000)
    probe = AnyAhead(count=400, seed=1)
    obs = probe.reset()
    actions = agent.act(obs, deterministic=True)
    assert np.mean(actions == probe.good) >= 0.93  # an MLP on the flattened rows: 0.87-0.89
    agent.save(tmp_path / "agent.zip")
    loaded = OwnPPO.load(tmp_path / "agent.zip")
    np.testing.assert_array_equal(loaded.act(obs, True), actions)
