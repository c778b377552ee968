"""The on-policy trainer (``agents/onpolicy.py``): GAE with time-limit bootstrapping against a hand
computation, every action distribution and a Dict observation learning a tiny task, the array path
equal to SB3's VecEnv path, the running statistics saved with the model."""

import numpy as np
import pytest
import torch
from gymnasium import spaces
from stable_baselines3.common.vec_env import VecEnv

from drivelab.agents.a2c import OwnA2C
from drivelab.agents.actor_critic import BETA_EPSILON, ActorCritic, beta_mode
from drivelab.agents.onpolicy import Rollout
from drivelab.agents.ppo import OwnPPO
from drivelab.agents.worlds import Worlds

pytestmark = pytest.mark.usefixtures("one_torch_thread")


class ScriptedWorlds(VecEnv):
    """K worlds whose observation is [steps into the episode]; reward 1 per step. ``ends[k]`` is
    (length, "terminated" or "truncated"): how world k's episodes end."""

    def __init__(self, ends):
        super().__init__(len(ends), spaces.Box(0, 100, (1,), np.float32), spaces.Discrete(2))
        self.ends, self.t = ends, np.zeros(len(ends), dtype=np.float32)

    def reset(self):
        self.t[:] = 0
        return self.t[:, None].copy()

    def step_async(self, actions):
        pass

    def step_wait(self):
        self.t += 1
        infos, dones = [], np.zeros(self.num_envs, dtype=bool)
        for k, (length, how) in enumerate(self.ends):
            info = {}
            if self.t[k] == length:
                dones[k] = True
                info = {"terminal_observation": np.array([self.t[k]], np.float32),
                        "TimeLimit.truncated": how == "truncated"}  # fmt: skip
                self.t[k] = 0
            infos.append(info)
        return self.t[:, None].copy(), np.ones(self.num_envs, np.float32), dones, infos

    def close(self):
        pass

    def get_attr(self, name, indices=None):
        return [None] * self.num_envs

    def set_attr(self, name, value, indices=None):
        pass

    def env_method(self, name, *args, indices=None, **kwargs):
        return [None] * self.num_envs

    def env_is_wrapped(self, wrapper_class, indices=None):
        return [False] * self.num_envs


def _captured_rollout(agent, steps) -> Rollout:
    rollouts = []
    agent.update = lambda rollout: rollouts.append(rollout) or {}
    agent.learn(steps)
    return rollouts[0]


def test_gae_bootstraps_a_time_limit_from_the_final_observation_and_ends_a_termination():
    """World 0 is cut by a time limit after 2 steps, world 1 terminates after 3; V ≡ 0.5."""
    gamma, lam, v = 0.9, 0.8, 0.5
    env = ScriptedWorlds([(2, "truncated"), (3, "terminated")])
    agent = OwnA2C(env.observation_space, env.action_space, 0,
                   {"n_steps": 4, "gamma": gamma, "gae_lambda": lam}, env)  # fmt: skip
    with torch.no_grad():
        agent.policy.value.weight.zero_()
        agent.policy.value.bias.fill_(v)
    rollout = _captured_rollout(agent, 8)
    # world 0: steps 0, 1 | 2, 3 (cut at step 1: r = 1 + γ·V(final)); world 1: steps 0, 1, 2 | 3
    delta_cut = 1 + gamma * v - v  # the cut step: its own reward, the bootstrap, no next value
    delta_on = 1 + gamma * v - v  # a step followed by another of its episode
    delta_end = 1 - v  # a terminated step: nothing after it
    # world 0's last step bootstraps V(s_4) = v
    world0 = [delta_on + gamma * lam * delta_cut, delta_cut,
              delta_on + gamma * lam * delta_on, delta_on]  # fmt: skip
    world1 = [delta_on + gamma * lam * (delta_on + gamma * lam * delta_end),
              delta_on + gamma * lam * delta_end, delta_end, delta_on]  # fmt: skip
    expected = np.array([world0, world1]).T.reshape(-1)  # time-major (T·K,)
    np.testing.assert_allclose(rollout.advantages.numpy(), expected, rtol=1e-6)
    np.testing.assert_allclose(rollout.returns.numpy(), expected + v, rtol=1e-6)


def test_without_time_limit_bootstrapping_a_cut_episode_ends_like_a_termination():
    """bootstrap_time_limits=false (CleanRL's rule): world 0's cut step gets no γ·V(final)."""
    gamma, lam, v = 0.9, 0.8, 0.5
    env = ScriptedWorlds([(2, "truncated"), (2, "terminated")])
    agent = OwnA2C(env.observation_space, env.action_space, 0,
                   {"n_steps": 4, "gamma": gamma, "gae_lambda": lam, "bootstrap_time_limits": False},
                   env)  # fmt: skip
    with torch.no_grad():
        agent.policy.value.weight.zero_()
        agent.policy.value.bias.fill_(v)
    rollout = _captured_rollout(agent, 8)
    delta_on, delta_end = 1 + gamma * v - v, 1 - v
    world = [delta_on + gamma * lam * delta_end, delta_end] * 2  # two episodes of 2 steps each
    expected = np.array([world, world]).T.reshape(-1)  # both worlds alike: a cut is an end
    np.testing.assert_allclose(rollout.advantages.numpy(), expected, rtol=1e-6)


class Bandit(VecEnv):
    """One-step episodes in K worlds: the observation's first number x ~ U(−1, 1) says which action
    pays; Discrete: action 1 when x > 0 (reward 1, else 0); Box: reward 1 − (a₀ − 0.5·sign x)²."""

    def __init__(self, action_space, dict_obs=False, count=16, seed=0):
        box = spaces.Box(-1, 1, (2,), np.float32)
        space = spaces.Dict({"x": spaces.Box(-1, 1, (1,), np.float32), "noise": box}) if dict_obs else box
        super().__init__(count, space, action_space)
        self.dict_obs, self.rng = dict_obs, np.random.default_rng(seed)

    def _draw(self):
        self.x = self.rng.uniform(-1, 1, (self.num_envs, 2)).astype(np.float32)
        if self.dict_obs:
            noise = self.rng.uniform(-1, 1, self.x.shape).astype(np.float32)
            return {"x": self.x[:, :1].copy(), "noise": noise}
        return self.x.copy()

    def reset(self):
        return self._draw()

    def step_async(self, actions):
        self.actions = np.asarray(actions)

    def step_wait(self):
        good = self.x[:, 0] > 0
        if isinstance(self.action_space, spaces.Discrete):
            rewards = (self.actions == good).astype(np.float32)
        else:
            rewards = 1 - (self.actions[:, 0] - np.where(good, 0.5, -0.5)) ** 2
        obs = self._draw()  # (a terminated episode's final observation is not read: it ends the value)
        infos = [{"terminal_observation": _row(obs, k), "TimeLimit.truncated": False}
                 for k in range(self.num_envs)]  # fmt: skip
        return obs, rewards.astype(np.float32), np.ones(self.num_envs, bool), infos

    close = ScriptedWorlds.close
    get_attr, set_attr = ScriptedWorlds.get_attr, ScriptedWorlds.set_attr
    env_method, env_is_wrapped = ScriptedWorlds.env_method, ScriptedWorlds.env_is_wrapped


def _row(obs, k):
    return {key: value[k] for key, value in obs.items()} if isinstance(obs, dict) else obs[k]


@pytest.mark.parametrize(
    ("algo", "action_space", "distribution", "dict_obs"),
    [
        (OwnPPO, spaces.Discrete(2), "auto", False),
        (OwnPPO, spaces.Box(-1, 1, (2,), np.float32), "tanh_gaussian", False),
        (OwnPPO, spaces.Box(-1, 1, (2,), np.float32), "beta", False),
        (OwnPPO, spaces.Discrete(2), "auto", True),
        (OwnA2C, spaces.Discrete(2), "auto", False),
        (OwnA2C, spaces.Box(-1, 1, (2,), np.float32), "beta", True),
    ],
)
def test_every_distribution_and_a_dict_observation_learn_a_tiny_task(
    algo, action_space, distribution, dict_obs
):
    """A2C's Beta is still wide after these steps: its mean, not its mode, is then the best action
    for the bandit's quadratic reward (PPO's, narrower, is read by the default mode)."""
    env = Bandit(action_space, dict_obs)
    hyperparams = {"n_steps": 4, "learning_rate": 3e-3, "distribution": distribution, "gamma": 0.9}
    if algo is OwnA2C and distribution == "beta":
        hyperparams["beta_action"] = "mean"
    if algo is OwnPPO:
        hyperparams.update(batch_size=32, n_epochs=4)
    agent = algo(env.observation_space, env.action_space, 0, hyperparams, env)
    agent.learn(4000)
    probe = Bandit(action_space, dict_obs, count=200, seed=1)
    obs = probe.reset()
    actions = agent.act(obs, deterministic=True)
    good = probe.x[:, 0] > 0
    if isinstance(action_space, spaces.Discrete):
        assert np.mean(actions == good) >= 0.9
    else:
        assert np.mean(np.abs(actions[:, 0] - np.where(good, 0.5, -0.5))) < 0.25
        assert np.all((actions >= -1) & (actions <= 1))


def test_the_array_path_steps_and_monitors_as_the_vecenv_path(tmp_path):
    """``drivelab train``'s chain stepped by ``step_arrays`` gives what SB3's ``step`` gives:
    observations, rewards, ends, final observations, episode returns and monitor.csv rows."""
    from stable_baselines3.common.monitor import ResultsWriter

    from drivelab.agents.sb3_env import SB3VecEnv
    from drivelab.envs.vector import VectorDriveEnv
    from drivelab.training.resume_state import ArrayVecMonitor, RecordVecEpisodes

    def chain(name):
        vector = VectorDriveEnv(3, "merge", obs="kinematics", action="meta", autoreset_mode="same_step",
                                backend="fast", duration_s=4)  # fmt: skip
        recorder = RecordVecEpisodes(SB3VecEnv(vector))
        monitor = ArrayVecMonitor(recorder)
        monitor.results_writer = ResultsWriter(str(tmp_path / name), header={"t_start": 0})
        monitor.seed(5)
        return Worlds(monitor), recorder

    (fast, fast_log), (slow, slow_log) = chain("fast"), chain("slow")
    slow.arrays = False
    assert fast.arrays
    np.testing.assert_array_equal(fast.reset(), slow.reset())
    actions = np.random.default_rng(0).integers(0, 5, (30, 3))
    ended = 0
    for step in actions:
        a, b = fast.step(step), slow.step(step)
        for x, y in zip(a[:4], b[:4], strict=True):
            np.testing.assert_array_equal(x, y)
        assert (a[4] is None) == (b[4] is None)
        if a[4] is not None:
            done = a[2] | a[3]
            np.testing.assert_array_equal(a[4][done], b[4][done])
            ended += int(done.sum())
        assert a[5] == b[5]
    assert ended >= 3
    assert fast_log.log.mark() is not None and [len(x) for _, x, _ in fast_log.log.mark()] == [
        len(x) for _, x, _ in slow_log.log.mark()
    ]
    rows = [(tmp_path / f"{name}.monitor.csv").read_text().splitlines()[2:] for name in ("fast", "slow")]
    assert [r.split(",")[:2] for r in rows[0]] == [r.split(",")[:2] for r in rows[1]]
    assert fast.infos[0].keys() >= {"speed_mps", "reward_terms"}  # built when read


def test_observation_statistics_are_saved_with_the_weights_and_used_to_act(tmp_path):
    env = Bandit(spaces.Discrete(2))
    agent = OwnPPO(env.observation_space, env.action_space, 0,
                   {"n_steps": 4, "batch_size": 32, "normalize_observations": True,
                    "normalize_rewards": True}, env)  # fmt: skip
    agent.learn(256)
    norm = agent.policy.norm
    assert norm.count.item() == 16 + 256  # the first batch, then every rollout
    np.testing.assert_allclose(norm.mean.numpy(), 0.0, atol=0.15)  # U(−1, 1): mean 0, variance 1/3
    np.testing.assert_allclose(norm.var.numpy(), 1 / 3, atol=0.1)
    assert agent.return_stats[2].item() == 256
    agent.save(tmp_path / "agent.zip")
    loaded = OwnPPO.load(tmp_path / "agent.zip")
    torch.testing.assert_close(loaded.policy.norm.mean, norm.mean)
    obs = Bandit(spaces.Discrete(2), seed=3).reset()
    np.testing.assert_array_equal(loaded.act(obs, True), agent.act(obs, True))


def test_weights_saved_by_the_tanh_gaussian_networks_load():
    """Behaviour cloning's network (``mean`` head, no statistics) loads into the actor-critic."""
    from drivelab.agents.networks import TanhGaussianActorCritic

    space = spaces.Box(-1, 1, (4,), np.float32)
    old = TanhGaussianActorCritic(space, 2)
    new = ActorCritic(space, spaces.Box(-1, 1, (2,), np.float32))
    new.load_state_dict(old.state_dict())
    obs = torch.rand(5, 4)
    torch.testing.assert_close(new(obs)[0], old(obs)[0])


@pytest.mark.parametrize("kind", ["categorical", "tanh_gaussian", "beta"])
def test_the_kl_between_two_policies_is_their_distributions(kind):
    """``kl_to`` is KL(π ‖ π_other) per row: Gaussians before the tanh and categoricals against their
    closed forms, the Beta's zero against itself and positive against another."""
    action_space = spaces.Discrete(3) if kind == "categorical" else spaces.Box(-1, 1, (2,), np.float32)
    space = spaces.Box(-1, 1, (4,), np.float32)
    torch.manual_seed(0)
    policy, other = (ActorCritic(space, action_space, kind, log_std_init=s) for s in (-1.0, -0.5))
    obs = torch.randn(5, 4)
    out, other_out = policy(obs)[0] + 0.3 * torch.randn(5, 1), other(obs)[0]
    kl = policy.kl_to(out, other, other_out)
    assert kl.shape == (5,)
    if kind == "categorical":
        p, q = out.softmax(-1), other_out.softmax(-1)
        torch.testing.assert_close(kl, (p * (p / q).log()).sum(-1))
    elif kind == "tanh_gaussian":
        s, s0 = np.exp(-1.0), np.exp(-0.5)
        expected = np.log(s0 / s) + (s**2 + (out - other_out) ** 2) / (2 * s0**2) - 0.5
        torch.testing.assert_close(kl, expected.sum(-1).float())
    else:
        torch.testing.assert_close(policy.kl_to(out, policy, out), torch.zeros(5), atol=1e-6, rtol=0)
        assert torch.all(kl > 0)


def test_a_prior_kl_keeps_the_policy_near_the_one_it_started_from():
    """With a large ``prior_kl_coef`` PPO barely leaves its initial policy on the bandit it otherwise
    learns; the prior itself never changes, and the KL is logged."""
    env = Bandit(spaces.Discrete(2), False)
    probe = Bandit(spaces.Discrete(2), False, count=200, seed=1).reset()

    def trained(coef: float):
        hyperparams = {"n_steps": 4, "learning_rate": 3e-3, "gamma": 0.9, "batch_size": 32, "n_epochs": 4,
                       "prior_kl_coef": coef}  # fmt: skip
        agent = OwnPPO(env.observation_space, env.action_space, 0, hyperparams, env)
        with torch.no_grad():
            start = agent.policy(torch.as_tensor(probe))[0].softmax(-1)
        prior = {key: value.clone() for key, value in (agent.prior.state_dict() if coef else {}).items()}
        logged = []
        agent._log_progress = lambda metrics: logged.append(metrics)
        agent.learn(2000)
        with torch.no_grad():
            end = agent.policy(torch.as_tensor(probe))[0].softmax(-1)
        for key, value in prior.items():
            assert torch.equal(agent.prior.state_dict()[key], value), key
        return float((end - start).abs().max()), logged

    free, free_log = trained(0.0)
    held, held_log = trained(100.0)
    assert free > 0.3 and held < 0.1 * free
    assert "prior_kl" in held_log[-1] and "prior_kl" not in free_log[-1]


def test_a_deterministic_beta_action_is_its_mode_and_reaches_the_ends_of_the_range():
    """Read deterministically, a Beta acts at its mode (α − 1) / (α + β − 2), as Roach does: at α = 1
    that is the range's bottom exactly, where the mean α / (α + β) stays inside; uniform gives ½."""
    policy = ActorCritic(spaces.Box(-1, 1, (4,), np.float32), spaces.Box(0, 1, (2,), np.float32), "beta")
    # head outputs whose 1 + softplus are α = (3, 1) and β = (5, 20): one Beta inside the range, one
    # with α at its floor
    out = torch.log(torch.expm1(torch.tensor([[2.0, 1.0, 4.0, 19.0]])))
    out[0, 1] = -50.0
    x = policy.sample(out, True, torch.Generator(), np.random.default_rng(0))
    torch.testing.assert_close(x, torch.tensor([[2.0 / 6.0, BETA_EPSILON]]))
    assert policy.to_env(x)[0, 1] < 1e-5  # the mean would be 1 / 21
    torch.testing.assert_close(beta_mode(torch.ones(3), torch.ones(3)), torch.full((3,), 0.5))
    torch.testing.assert_close(beta_mode(torch.tensor([4.0]), torch.tensor([1.0])), torch.tensor([1.0]))
