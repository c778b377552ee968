"""RLAD's fast update (``-H fast_update=true``; sac.py ``RLAD._fast_update``): ``RLAD.train_step``
written so that a GPU is bound by its arithmetic, not by kernel launches and host round trips.

What differs from the plain update:

- every random number of the update is drawn up front from the agent's CPU generator, in the
  plain update's order and shapes (``draw_update_noise``), so both use the same numbers;
- A-LIX shifts by a device tensor on a GPU and when compiled (``alix.shift_bilinear_tensor``):
  ~1e-7 relative; eager on the CPU it is bitwise the plain update's;
- the auxiliary loss divides by the labelled count, at least 1 (a batch without a label steps the
  head's Adam with zero gradients);
- the actor loss reads the critic through detached parameters (``torch.func.functional_call``);
- Adam is fused (``fused=True``): rounding may differ in the last bit;
- the target EMA is one ``torch._foreach_lerp_``, the losses stay tensors until logged.

Options: ``compile`` (``torch.compile`` of the critic and actor objectives; agrees to float32
rounding; eager, said once, without a C++ compiler or Triton: ``compile_unavailable``), ``bf16``
(autocast of the forward passes: ~1e-2 relative, off by default), ``channels_last`` (NHWC
convolutions).
"""

from __future__ import annotations

import shutil

import torch

from drivelab.agents.rlad.alix import draw_offsets
from drivelab.agents.rlad.augmentation import draw_shifts

COMPILE_MODES = ("none", "default", "reduce-overhead", "max-autotune")


def compile_unavailable(device: torch.device) -> str | None:
    """Why ``torch.compile``'s inductor cannot compile for ``device`` here (None when it can)."""
    if device.type == "cuda":
        from torch.utils._triton import has_triton

        return None if has_triton() else "torch.compile on a GPU needs Triton, which is not installed"
    if device.type == "cpu":
        from torch._inductor.cpp_builder import get_cpp_compiler

        try:
            compiler = get_cpp_compiler()
        except (RuntimeError, OSError) as exc:
            return f"torch.compile on the CPU needs a C++ compiler: {exc}"
        if shutil.which(compiler) is None:
            return f"torch.compile on the CPU needs a C++ compiler; {compiler!r} was not found"
        return None
    return f"torch.compile has no inductor backend for {device.type!r}"


def draw_update_noise(
    generator: torch.Generator, batch: int, actions: int, pad: int, alix_layers: int
) -> dict[str, torch.Tensor | None]:
    """Every random number one update draws, in the plain update's order (CPU tensors).

    :param generator: the agent's generator.
    :param batch: transitions per update B.
    :param actions: action dimensions |A|.
    :param pad: DrQ's shift in pixels (0: no augmentation, no shifts drawn).
    :param alix_layers: A-LIX layers of the encoder (0: A-LIX off).
    :returns: ``shifts``, ``next_shifts`` (B, 2) int64 or None; ``next_offsets``, ``offsets``
        (layers, 2) in [−1, 1]² or None; ``next_noise``, ``noise`` (B, |A|) standard normal.
    """
    noise: dict[str, torch.Tensor | None] = {}
    noise["shifts"] = draw_shifts(batch, pad, generator) if pad > 0 else None
    noise["next_shifts"] = draw_shifts(batch, pad, generator) if pad > 0 else None
    noise["next_offsets"] = draw_offsets(generator, alix_layers) if alix_layers else None
    noise["next_noise"] = torch.randn((batch, actions), generator=generator)
    noise["offsets"] = draw_offsets(generator, alix_layers) if alix_layers else None
    noise["noise"] = torch.randn((batch, actions), generator=generator)
    return noise
