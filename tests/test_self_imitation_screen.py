"""benchmarks/self_imitation_screen.py: the replay keeps the last transitions with their Monte-Carlo
returns; the self-imitation steps move the policy towards an action only where its return beat the
critic; bad settings are one error line and exit 2."""

import importlib.util
import sys
from pathlib import Path

import numpy as np
import pytest
import torch

from drivelab.agents import registry
from tests.agents.test_onpolicy import ScriptedWorlds

pytestmark = pytest.mark.usefixtures("one_torch_thread")
SCRIPT = Path(__file__).parents[1] / "benchmarks" / "self_imitation_screen.py"


@pytest.fixture
def screen(monkeypatch):
    spec = importlib.util.spec_from_file_location("self_imitation_screen", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    monkeypatch.setitem(sys.modules, "self_imitation_screen", module)
    monkeypatch.setitem(registry.ALGORITHMS, "ppo_own", registry.ALGORITHMS["ppo_own"])  # restored after
    module.use_self_imitation()
    return module


def _agent(screen, **hyperparams):
    env = ScriptedWorlds([(3, "terminated"), (3, "terminated")])
    config = {"n_steps": 6, "gamma": 0.9, "bootstrap_time_limits": False, "batch_size": 12, **hyperparams}
    return screen.SelfImitationPPO(env.observation_space, env.action_space, 0, config, env)


def test_the_replay_keeps_the_last_transitions_with_their_discounted_returns(screen):
    screen.SETTINGS.update(capacity=10)
    agent = _agent(screen)
    agent.learn(24)  # two rollouts of 6 steps x 2 worlds, two 3-step episodes a world each
    observations, actions, returns = agent._replay
    episode = [1 + 0.9 + 0.81, 1 + 0.9, 1.0]  # reward 1 a step, γ 0.9
    expected = np.repeat(episode * 2, 2)[-10:]  # time-major: both worlds at each step
    np.testing.assert_allclose(returns.numpy(), expected, rtol=1e-6)
    np.testing.assert_array_equal(observations.numpy()[:, 0], np.repeat([0, 1, 2] * 2, 2)[-10:])
    assert len(actions) == 10


def test_self_imitation_raises_only_actions_that_beat_the_critic(screen, monkeypatch):
    screen.SETTINGS.update(updates=20, batch_size=12, value_coef=0.0)
    monkeypatch.setattr(screen.OwnPPO, "update", lambda self, rollout: {})  # only the self-imitation steps
    obs, ones, zeros = (
        torch.zeros((12, 1)),
        torch.ones(12, dtype=torch.int64),
        torch.zeros(12, dtype=torch.int64),
    )

    def log_prob_of_one(agent):
        with torch.no_grad():
            return float(agent.policy.log_prob_entropy(agent.policy(obs)[0], ones, entropy=False)[0].mean())

    better = _agent(screen, learning_rate=0.01)
    better._replay = (obs, ones, torch.full((12,), 100.0))  # action 1 paid far more than V
    before = log_prob_of_one(better)
    assert better.update(None)["sil_fraction"] == 1.0
    assert log_prob_of_one(better) > before + 0.1

    worse = _agent(screen, learning_rate=0.01)
    worse._replay = (obs, zeros, torch.full((12,), -100.0))  # action 0 paid far less than V
    unchanged = [p.detach().clone() for p in worse.policy.parameters()]
    assert worse.update(None)["sil_fraction"] == 0.0
    assert all(torch.equal(a, b) for a, b in zip(unchanged, worse.policy.parameters(), strict=True))


@pytest.mark.parametrize(
    "argv",
    [
        ["--sil-updates", "0", "--", "--algo", "ppo_own"],
        ["--", "--algo", "dqn", "--env", "highway"],
        ["--", "--algo", "ppo_own", "--resume", "RUN"],
        ["--", "--algo", "ppo_own", "-H", "normalize_rewards=true"],
        ["--", "--algo", "ppo_own", "-H", "normalize_rewards=True"],
    ],
)
def test_bad_settings_are_one_error_line_and_exit_2(screen, argv, capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    try:
        code = screen.main(argv)
    except SystemExit as stop:  # bad input stops at once
        code = stop.code
    assert code == 2
    err = capsys.readouterr().err
    assert err.startswith("error:") and err.count("\n") == 1
    assert list(tmp_path.iterdir()) == []
