"""Self-imitation on the on-policy trainer (``-H sil_updates``, ``agents/self_imitation.py``): the
replay keeps the last transitions with their hand-computed discounted returns, in the critic's
scale; the loss by hand; the steps raise only actions whose return beat the critic; the replay's
arrays round-trip and refuse another configuration's; bad settings are refused."""

import numpy as np
import pytest
import torch
from gymnasium import spaces

from drivelab.agents.a2c import OwnA2C
from drivelab.agents.ppo import OwnPPO
from drivelab.agents.self_imitation import SelfImitationReplay, self_imitation_loss
from drivelab.errors import UsageError
from tests.agents.test_onpolicy import ScriptedWorlds

pytestmark = pytest.mark.usefixtures("one_torch_thread")
EPISODE = [1 + 0.9 + 0.81, 1 + 0.9, 1.0]  # returns of a 3-step episode, reward 1 a step, γ 0.9


def _agent(cls=OwnPPO, **hyperparams):
    env = ScriptedWorlds([(3, "terminated"), (3, "terminated")])
    config = {"n_steps": 6, "gamma": 0.9, "bootstrap_time_limits": False, "sil_updates": 1,
              "sil_batch_size": 4, **hyperparams}  # fmt: skip
    if cls is OwnPPO:
        config.setdefault("batch_size", 12)
    return cls(env.observation_space, env.action_space, 0, config, env)


def _kept(replay: SelfImitationReplay):
    """The replay's observations (first feature), actions and returns, oldest first."""
    rows = (replay.position - replay.size + np.arange(replay.size)) % replay.capacity
    return replay.observations[rows, 0], replay.actions[rows], replay.returns[rows]


@pytest.mark.parametrize("cls", [OwnPPO, OwnA2C])
def test_the_replay_keeps_the_last_transitions_with_their_discounted_returns(cls):
    agent = _agent(cls, sil_capacity=10)
    agent.learn(24)  # two rollouts of 6 steps x 2 worlds, two 3-step episodes a world each
    observations, actions, returns = _kept(agent.replay_buffer)
    np.testing.assert_allclose(returns, np.repeat(EPISODE * 2, 2)[-10:], rtol=1e-6)  # time-major
    np.testing.assert_array_equal(observations, np.repeat([0, 1, 2] * 2, 2)[-10:])
    assert len(actions) == len(agent.replay_buffer) == 10


def test_a_rollout_cut_mid_episode_bootstraps_its_returns_from_the_critic():
    agent = _agent(n_steps=2, sil_capacity=4)
    agent.update = agent.self_imitate = lambda *rollout: {}  # the critic stays the one that collected
    agent.learn(4)  # one rollout of 2 steps: both worlds stop at observation 2 of their episodes
    last_value = float(agent._values(np.array([[2.0], [2.0]], np.float32))[0])
    _, _, returns = _kept(agent.replay_buffer)
    np.testing.assert_allclose(returns, np.repeat([1 + 0.9 + 0.81 * last_value, 1 + 0.9 * last_value], 2),
                               rtol=1e-5)  # fmt: skip


def test_with_rewards_normalised_the_returns_are_in_the_critics_scale():
    agent = _agent(sil_capacity=12, normalize_rewards=True)
    agent.learn(12)  # one rollout: the scale is that of the statistics after it
    scale = 1.0 / np.sqrt(float(agent.return_stats[1]) + 1e-8)
    _, _, returns = _kept(agent.replay_buffer)
    np.testing.assert_allclose(returns, np.repeat(EPISODE * 2, 2) * scale, rtol=1e-5)


def test_the_loss_by_hand():
    log_probs = torch.tensor([-1.0, -2.0, -0.5], requires_grad=True)
    values = torch.tensor([1.0, 3.0, 0.0], requires_grad=True)
    returns = torch.tensor([3.0, 2.0, 1.0])  # beats V by 2, falls short by 1, beats it by 1
    loss, count = self_imitation_loss(log_probs, values, returns, value_coef=0.5)
    assert count == 2
    expected = (-(-1.0 * 2 + -0.5 * 1) + 0.25 * (2**2 + 1**2)) / 2
    assert float(loss.detach()) == pytest.approx(expected)
    loss.backward()
    np.testing.assert_allclose(log_probs.grad.numpy(), [-1.0, 0.0, -0.5])  # (R − V)₊ / n, a constant
    np.testing.assert_allclose(values.grad.numpy(), [-0.5, 0.0, -0.25])  # c·(R − V)₊·(−1) / n
    none, zero = self_imitation_loss(log_probs, values, returns - 10, value_coef=0.5)
    assert (float(none.detach()), zero) == (0.0, 0)


def _filled(agent, action: int, value: float) -> None:
    replay = agent.replay_buffer
    replay.add(torch.zeros((12, 1)), torch.full((12,), action, dtype=torch.int64), np.full(12, value))


def test_self_imitation_raises_only_actions_that_beat_the_critic():
    obs, ones = torch.zeros((12, 1)), torch.ones(12, dtype=torch.int64)

    def log_prob_of_one(agent):
        with torch.no_grad():
            return float(agent.policy.log_prob_entropy(agent.policy(obs)[0], ones, entropy=False)[0].mean())

    settings = {"learning_rate": 0.01, "sil_updates": 20, "sil_batch_size": 12, "sil_value_coef": 0.0}
    better = _agent(**settings)
    _filled(better, action=1, value=100.0)  # action 1 paid far more than V
    before = log_prob_of_one(better)
    assert better.self_imitate()["sil_fraction"] == 1.0
    assert log_prob_of_one(better) > before + 0.1

    worse = _agent(**settings)
    _filled(worse, action=0, value=-100.0)  # action 0 paid far less than V
    unchanged = [p.detach().clone() for p in worse.policy.parameters()]
    assert worse.self_imitate()["sil_fraction"] == 0.0
    assert all(torch.equal(a, b) for a, b in zip(unchanged, worse.policy.parameters(), strict=True))

    assert _agent().self_imitate() == {}  # an empty replay: no step


def test_the_ring_keeps_the_newest_and_its_arrays_round_trip():
    space = spaces.Dict({"image": spaces.Box(0, 255, (2, 2), np.uint8), "v": spaces.Box(-1, 1, (3,))})
    replay = SelfImitationReplay(space, 5, (2,), discrete=False)
    for start in (0, 3, 6):  # rollouts of 3: the last 5 of 0..8 stay
        steps = torch.arange(start, start + 3, dtype=torch.float32)
        observations = {
            "image": steps.to(torch.uint8)[:, None, None].expand(3, 2, 2),
            "v": steps[:, None].expand(3, 3),
        }
        replay.add(observations, steps[:, None].expand(3, 2), steps.numpy() * 10)
    rows = (replay.position - replay.size + np.arange(replay.size)) % replay.capacity
    np.testing.assert_array_equal(replay.returns[rows], [40, 50, 60, 70, 80])
    np.testing.assert_array_equal(replay.observations["image"][rows, 0, 0], [4, 5, 6, 7, 8])
    observations, actions, returns = replay.sample(64, torch.Generator().manual_seed(0))
    assert set(returns.tolist()) == {40.0, 50.0, 60.0, 70.0, 80.0}
    assert observations["image"].dtype == torch.uint8 and actions.shape == (64, 2)
    np.testing.assert_array_equal(observations["v"][:, 0].numpy() * 10, returns.numpy())  # rows kept together

    copy = SelfImitationReplay(space, 5, (2,), discrete=False)
    copy.load_state_arrays(replay.state_arrays())
    for name, value in replay.state_arrays().items():
        np.testing.assert_array_equal(copy.state_arrays()[name], value)
    other = SelfImitationReplay(space, 6, (2,), discrete=False)
    with pytest.raises(ValueError, match="replay array 'observations.image'"):
        other.load_state_arrays(replay.state_arrays())
    assert other.size == 0


def test_only_self_imitation_builds_a_replay():
    assert _agent(sil_updates=0).replay_buffer is None
    assert isinstance(_agent().replay_buffer, SelfImitationReplay)


@pytest.mark.parametrize(
    "bad",
    [{"sil_updates": -1}, {"sil_batch_size": 0}, {"sil_capacity": 0}, {"sil_value_coef": -0.1}],
)
def test_bad_settings_are_refused(bad):
    with pytest.raises(UsageError, match="sil_updates >= 0, sil_batch_size and sil_capacity >= 1"):
        _agent(**bad)
    with pytest.raises(UsageError, match="'sil_capacity' of 'ppo_own' asks for a self-imitation replay"):
        _agent(sil_capacity=10**15)
