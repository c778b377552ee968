"""RLAD's networks: Table I's encoder, A-LIX (identity, dual strength update), WayConv1D."""

import numpy as np
import pytest
import torch

from drivelab.agents.rlad.alix import (
    TARGET_DISCONTINUITY,
    adaptive_local_signal_mixing,
    normalized_discontinuity,
    shift_bilinear,
)
from drivelab.agents.rlad.encoder import ImageEncoder, encoder_strides
from drivelab.agents.rlad.waypoints import MeasurementEncoder, WayConv1D, WaypointMLP

TABLE_I_INPUTS = [(9, 256, 256), (32, 127, 127), (32, 63, 63), (32, 31, 31), (64, 15, 15), (64, 13, 13),
                  (64, 11, 11), (64, 9, 9), (64, 7, 7)]  # fmt: skip


def test_encoder_follows_table_one_at_256():
    encoder = ImageEncoder(9, 256, 256).eval()
    seen = []
    for conv in encoder.convs:
        conv.register_forward_pre_hook(lambda module, args: seen.append(tuple(args[0].shape[1:])))
    latent = encoder(torch.zeros(2, 9, 256, 256, dtype=torch.uint8))
    assert seen == TABLE_I_INPUTS
    assert encoder.feature_shape == (64, 5, 5) and encoder.head[0].in_features == 1600
    assert latent.shape == (2, 256) and latent.abs().max() <= 1.0
    # Table I's layers: convs + Linear(1600, 256) + LayerNorm(256), and A-LIX's strength
    convs = sum(
        9 * i * o + o
        for i, o in zip(
            (9, 32, 32, 32, 64, 64, 64, 64, 64), (32, 32, 32, 64, 64, 64, 64, 64, 64), strict=True
        )
    )
    expected = convs + 1600 * 256 + 256 + 2 * 256 + 1
    parameters = sum(p.numel() for p in encoder.parameters())
    assert parameters == expected == 634_625
    assert 0.5e6 < parameters < 1.5e6  # the paper's "around 1M"


def test_smaller_images_keep_nine_layers_and_a_small_feature_map():
    assert encoder_strides(84) == (2, 2, 1, 1, 1, 1, 1, 1, 1)
    encoder = ImageEncoder(9, 84, 84).eval()
    assert len(encoder.convs) == 9 and encoder.feature_shape == (64, 6, 6)
    assert encoder(torch.zeros(3, 9, 84, 84, dtype=torch.uint8)).shape == (3, 256)
    assert encoder_strides(128) == (2, 2, 2, 1, 1, 1, 1, 1, 1)
    with pytest.raises(ValueError, match="too small"):
        encoder_strides(20)


def _features(seed=0):
    return torch.rand(4, 8, 12, 12, generator=torch.Generator().manual_seed(seed))


def test_alix_is_the_identity_at_zero_strength_and_in_eval_mode():
    x = _features()
    strength = torch.nn.Parameter(torch.tensor(0.0))
    out = adaptive_local_signal_mixing(x, strength, torch.Generator().manual_seed(1), learn_strength=True)
    assert torch.equal(out, x)
    encoder = ImageEncoder(9, 36, 36)
    images = torch.randint(0, 256, (2, 9, 36, 36), dtype=torch.uint8)
    with torch.no_grad():
        evaluated = encoder.eval()(images)
        mixed = encoder.train()(images)
        encoder.strength.fill_(0.0)
        unmixed = encoder.train()(images)
    assert torch.equal(unmixed, evaluated)
    assert not torch.allclose(mixed, evaluated)  # S = 0.5 in training does mix


def test_alix_shift_is_bilinear_resampling():
    x = _features()
    shifted = shift_bilinear(x, (1.25, -0.5))
    height, width = x.shape[-2:]
    rows = torch.arange(height, dtype=torch.float32) + 1.25
    cols = torch.arange(width, dtype=torch.float32) - 0.5
    grid = torch.stack(
        torch.meshgrid((cols + 0.5) / width * 2 - 1, (rows + 0.5) / height * 2 - 1, indexing="xy"), -1
    )
    reference = torch.nn.functional.grid_sample(x, grid[None].expand(4, -1, -1, -1), mode="bilinear",
                                                padding_mode="border", align_corners=False)  # fmt: skip
    torch.testing.assert_close(shifted, reference)


def _strength_after_one_step(gradient: torch.Tensor, start: float) -> tuple[float, float]:
    strength = torch.nn.Parameter(torch.tensor(start))
    optimizer = torch.optim.Adam([strength], lr=2e-3, betas=(0.5, 0.999))
    x = torch.zeros_like(gradient, requires_grad=True)
    out = adaptive_local_signal_mixing(x, strength, torch.Generator().manual_seed(0), learn_strength=True)
    (out * gradient).sum().backward()
    torch.testing.assert_close(x.grad, gradient)  # at S = 0 the features' gradient passes unchanged
    grad = float(strength.grad)
    optimizer.step()
    return strength.item(), grad


def test_alix_strength_grows_on_discontinuous_gradients_and_shrinks_on_smooth_ones():
    noisy = torch.randn(4, 8, 12, 12, generator=torch.Generator().manual_seed(3))
    nd = float(normalized_discontinuity(noisy))
    assert nd > TARGET_DISCONTINUITY
    grown, grad = _strength_after_one_step(noisy, 0.0)
    assert grad == pytest.approx(TARGET_DISCONTINUITY - nd, rel=1e-5) and grown > 0.0
    ramp = torch.linspace(1.0, 2.0, 12)[None, None, None, :].expand(4, 8, 12, 12)
    assert float(normalized_discontinuity(ramp)) < TARGET_DISCONTINUITY
    strength = torch.nn.Parameter(torch.tensor(0.5))
    optimizer = torch.optim.Adam([strength], lr=2e-3, betas=(0.5, 0.999))
    x = torch.zeros(4, 8, 12, 12, requires_grad=True)
    (
        adaptive_local_signal_mixing(x, strength, torch.Generator(), learn_strength=True) * ramp
    ).sum().backward()
    optimizer.step()
    assert strength.item() < 0.5


def test_normalized_discontinuity_known_values():
    assert float(normalized_discontinuity(torch.ones(2, 3, 5, 5))) == 0.0
    stripes = torch.tensor([(-1.0) ** j for j in range(6)]).expand(6, 6)[None, None]
    # inner columns: 6 of 8 neighbours differ by 2 → noise 3, signal 1 → log 4; the two border
    # columns see 3 differing neighbours (replicate padding) → noise 1.5 → log 2.5
    expected = (4 * np.log(4.0) + 2 * np.log(2.5)) / 6
    assert float(normalized_discontinuity(stripes)) == pytest.approx(expected, rel=1e-6)


def test_vector_encoders():
    waypoints = torch.randn(5, 10, 2)
    wayconv = WayConv1D(10, 32)
    assert wayconv.conv.weight.shape == (20, 2, 2) and wayconv.latent[0].in_features == 180
    assert wayconv(waypoints).shape == (5, 32) and WaypointMLP(10, 32)(waypoints).shape == (5, 32)
    assert MeasurementEncoder(6, 16)(torch.randn(5, 6)).shape == (5, 16)
