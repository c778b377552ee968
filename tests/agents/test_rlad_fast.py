"""RLAD's fast update (fast.py) against the plain one: one update from the same seed gives the same
losses, gradients and parameters, A-LIX's dual gradient included; compiled (inductor on the CPU)
as well as eager.

Tolerances, from what the fast update changes (fast.py's docstring):
- losses and metrics: relative 1e-5. Compiled, the shift A-LIX resamples at is rounded in float32
  instead of a double (~1e-7 relative in the features) and inductor may reorder float additions;
  channels-last convolutions sum in another order; observed ≤ 6e-7. (Eager, with the default Adam,
  the fast update is bitwise the plain one: a test below says so.)
- gradients: 1e-5 of each tensor's largest gradient (observed ≤ 6e-7 eager, the same compiled).
- parameters after one Adam step: Adam's first step is lr·g / (|g| + ε), ε = 1e-8, which for
  |g| near ε turns a gradient difference of 1e-10 into a step difference of ~lr·1e-2 (sign flips
  of gradients that are zero up to rounding move a parameter by up to 2·lr). Where |g| ≥ 1e-6 =
  100 ε the step differs by at most lr·ε·|Δg|/|g|² ≤ 1e-8·max|g|: those parameters are compared
  at 1e-6 (float32 rounding of parameters of order 1 is ~6e-8); the others only move by ≤ lr.
"""

import warnings

import numpy as np
import pytest
import torch

from drivelab.agents.rlad import alix, sac
from drivelab.errors import UsageError
from tests.agents.test_rlad import _agent as _any_device_agent
from tests.agents.test_rlad import _batch

CUDA = pytest.mark.skipif(not torch.cuda.is_available(), reason="needs a CUDA GPU")

LR, STRENGTH_LR, TAU = 1e-3, 2e-3, 0.01  # RLADConfig's learning_rate, alix_learning_rate, tau
MODULES = ("encoder", "actor", "critic", "critic_target", "traffic_light_head")
WITH_OWN_GRADIENTS = ("encoder", "actor", "traffic_light_head")  # the critics' also hold the actor loss's


def _agent(seed=0, device="cpu", **hyperparams):
    """The tolerances above are the CPU's: an agent there unless a test says otherwise."""
    return _any_device_agent(seed, device=device, **hyperparams)


@pytest.fixture
def float32_on_the_gpu():
    """cuDNN's default TF32 rounds convolution inputs to 10 mantissa bits: inputs that differ at
    float32 rounding (the device-side A-LIX shift) would then differ at ~1e-3. Off, a GPU sums in
    float32 as the CPU does, and the CPU's tolerances apply."""
    before = torch.backends.cudnn.allow_tf32, torch.backends.cuda.matmul.allow_tf32
    torch.backends.cudnn.allow_tf32 = torch.backends.cuda.matmul.allow_tf32 = False
    yield
    torch.backends.cudnn.allow_tf32, torch.backends.cuda.matmul.allow_tf32 = before


def _named(agent, module):
    return dict(getattr(agent, module).named_parameters())


def _assert_same_update(plain, fast, batch):
    before = {m: {n: p.detach().clone() for n, p in _named(plain, m).items()} for m in MODULES}
    expected, got = plain.train_step(batch), fast.train_step(batch)
    assert expected.keys() == got.keys()
    for key in expected:
        assert got[key] == pytest.approx(expected[key], rel=1e-5, abs=1e-7), key
    for module in WITH_OWN_GRADIENTS:
        for name, p in _named(plain, module).items():
            q = _named(fast, module)[name]
            if p.grad is None:  # not in the update (the auxiliary head without the auxiliary loss)
                assert q.grad is None, (module, name)
                continue
            scale = p.grad.abs().max().item()
            assert (p.grad - q.grad).abs().max().item() <= 1e-5 * scale + 1e-12, (module, name)
    assert fast.log_alpha.grad.item() == pytest.approx(plain.log_alpha.grad.item(), rel=1e-5)
    for module in MODULES:
        for name, p in _named(plain, module).items():
            q = _named(fast, module)[name]
            if module == "critic_target":  # EMA of the critics: τ times their difference
                np.testing.assert_allclose(
                    q.detach().cpu(), p.detach().cpu(), atol=2 * LR * TAU, err_msg=name
                )
                continue
            if q.grad is None:
                assert torch.equal(q, before[module][name]) and torch.equal(p, q), (module, name)
                continue
            lr = STRENGTH_LR if name == "image.strength" else LR
            moved = (p.detach() - before[module][name]).abs()
            assert moved.max().item() <= lr * (1 + 1e-4), (module, name)  # one Adam step
            clear = _named(fast, module)[name].grad.abs() >= 1e-6
            assert clear.any() or p.numel() == 1, (module, name)
            np.testing.assert_allclose(
                q.detach()[clear].cpu(), p.detach()[clear].cpu(), atol=1e-6, err_msg=name
            )
            np.testing.assert_allclose(q.detach().cpu(), p.detach().cpu(), atol=2 * lr, err_msg=name)


@pytest.mark.parametrize("hyperparams", [{}, {"channels_last": True}, {"alix": False, "aux": False}])
def test_one_fast_update_equals_the_plain_update(hyperparams):
    plain = _agent(seed=3, **{k: v for k, v in hyperparams.items() if k != "channels_last"})
    fast = _agent(seed=3, fast_update=True, **hyperparams)
    assert all(g.get("fused") for g in fast.critic_optimizer.param_groups)
    _assert_same_update(plain, fast, _batch(seed=2))
    if plain.config.alix:  # A-LIX's dual gradient reached S in both: β − ND, the same number
        strength = fast.encoder.image.strength
        assert strength.grad.item() == pytest.approx(plain.encoder.image.strength.grad.item(), rel=1e-5)
        assert strength.item() != 0.5
    # and the random streams stayed in step: a second update on a new batch agrees as well
    expected, got = plain.train_step(_batch(seed=4)), fast.train_step(_batch(seed=4))
    assert got == pytest.approx(expected, rel=1e-4, abs=1e-6)


def test_eager_on_the_cpu_with_the_plain_adam_the_fast_update_is_bitwise_the_plain_one():
    """What remains of the difference is fused Adam's rounding: with the default Adam the eager
    fast update (same random numbers, masked auxiliary mean, critics read through detached
    parameters, foreach EMA) gives the plain update's numbers exactly, over two updates."""
    plain, fast = _agent(seed=3), _agent(seed=3, fast_update=True)
    for optimizer in (fast.critic_optimizer, fast.actor_optimizer, fast.alpha_optimizer):
        for group in optimizer.param_groups:
            group["fused"] = None
    for seed in (2, 4):
        assert fast.train_step(_batch(seed=seed)) == plain.train_step(_batch(seed=seed))
    for module in MODULES:
        for name, p in _named(plain, module).items():
            assert torch.equal(_named(fast, module)[name], p), (module, name)
    assert torch.equal(fast.log_alpha, plain.log_alpha)


def test_the_device_side_alix_shift_equals_the_host_one():
    x = torch.randn(3, 4, 9, 11)
    for shift in ((1.25, -0.5), (-2.5, 2.5), (0.0, 0.0), (2.0, -2.5), (-0.75, 1.0)):
        exact = alix.shift_bilinear(x, shift)
        torch.testing.assert_close(alix.shift_bilinear_tensor(x, torch.tensor(shift)), exact, rtol=0, atol=0)
    # a shift that a float32 cannot hold exactly: the same to float32 rounding
    torch.testing.assert_close(
        alix.shift_bilinear_tensor(x, torch.tensor((-0.3, 2.4999))), alix.shift_bilinear(x, (-0.3, 2.4999))
    )


def test_the_compiled_fast_update_equals_the_plain_update():
    """inductor on the CPU (~1 min to compile on an idle 2-core machine, seconds once cached)."""
    reason = sac.compile_unavailable(torch.device("cpu"))
    if reason is not None:  # the fallback is tested below
        pytest.skip(reason)
    plain = _agent(seed=3)
    fast = _agent(seed=3, fast_update=True, compile="default")
    assert fast._critic_objective_fn is not fast._critic_objective  # compiled
    _assert_same_update(plain, fast, _batch(seed=2))
    strength = fast.encoder.image.strength
    assert strength.grad.item() == pytest.approx(plain.encoder.image.strength.grad.item(), rel=1e-5)


def test_without_inductor_the_fast_update_runs_eagerly_and_says_so(monkeypatch):
    monkeypatch.setattr(sac, "compile_unavailable", lambda device: "no C++ compiler here")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        fast = _agent(seed=3, fast_update=True, compile="reduce-overhead")
    assert any(
        "no C++ compiler here; the fast update runs without torch.compile" in str(w.message) for w in caught
    )
    assert fast._critic_objective_fn == fast._critic_objective
    _assert_same_update(_agent(seed=3), fast, _batch(seed=2))


def test_bf16_autocast_changes_the_losses_only_slightly():
    """bfloat16 keeps 8 mantissa bits: the losses move at ~1e-2 relative, more than float32's
    rounding (so the option is off by default and named wherever used)."""
    expected = _agent(seed=3).train_step(_batch(seed=2))
    got = _agent(seed=3, fast_update=True, bf16=True).train_step(_batch(seed=2))
    assert all(np.isfinite(v) for v in got.values())
    for key in ("critic_loss", "aux_loss", "actor_loss"):
        assert got[key] == pytest.approx(expected[key], rel=0.1), key


@pytest.mark.parametrize(
    ("hyperparams", "message"),
    [
        ({"compile": "default"}, "compile, bf16 and channels_last need fast_update=true"),
        ({"bf16": True}, "compile, bf16 and channels_last need fast_update=true"),
        ({"fast_update": True, "compile": "fastest"}, "compile must be one of none, default"),
    ],
)
def test_bad_fast_update_options_are_usage_errors(hyperparams, message):
    with pytest.raises(UsageError, match=message):
        _agent(**hyperparams)


@CUDA
@pytest.mark.parametrize(
    "hyperparams",
    [{}, {"channels_last": True}, {"compile": "reduce-overhead"}],
    ids=["eager", "nhwc", "graphs"],
)
def test_on_a_gpu_the_fast_update_equals_the_plain_update(hyperparams, float32_on_the_gpu):
    """On CUDA: eager, channels-last, and inductor with CUDA graphs (compiled on the first update,
    recorded on the next ones), against the plain update on the same GPU, over three updates."""
    plain = _agent(seed=3, device="cuda")
    fast = _agent(seed=3, device="cuda", fast_update=True, **hyperparams)
    _assert_same_update(plain, fast, _batch(seed=2))
    for seed in (4, 5):  # the graphs are recorded and replayed with the streams still in step
        expected, got = plain.train_step(_batch(seed=seed)), fast.train_step(_batch(seed=seed))
        assert got == pytest.approx(expected, rel=1e-4, abs=1e-6)


@CUDA
def test_on_a_gpu_bf16_with_cuda_graphs_changes_the_losses_only_slightly():
    expected = _agent(seed=3, device="cuda").train_step(_batch(seed=2))
    fast = _agent(seed=3, device="cuda", fast_update=True, compile="reduce-overhead", bf16=True)
    got = fast.train_step(_batch(seed=2))
    assert all(np.isfinite(v) for v in got.values())
    for key in ("critic_loss", "aux_loss", "actor_loss"):
        assert got[key] == pytest.approx(expected[key], rel=0.1), key
