"""RLAD's fast update (``-H fast_update=true``; sac.py ``RLAD._fast_update``): the same update as
``RLAD.train_step`` written so that a GPU is bound by its arithmetic, not by kernel launches and
host round trips.

What changes against the plain update, and what it does to the result:

- every random number of the update (DrQ shifts, A-LIX offsets, the actor's ε for the target and
  for the actor loss) is drawn up front from the agent's CPU generator, in the plain update's order
  and shapes, so both updates use the same numbers (``draw_update_noise``); they reach the device
  in a few copies;
- A-LIX resamples at a shift computed on the device (``alix.shift_bilinear_tensor``) on a GPU
  and when compiled: no ``float(S)`` per layer. The shift is rounded in float32 instead of a
  Python double: the features differ from the plain update's by ~1e-7 relative. Eager on the CPU
  (where reading a number costs nothing) it shifts as the plain update does, bitwise;
- the auxiliary loss is the summed cross-entropy over the labelled samples divided by their
  count, at least 1 (no branch on whether the batch holds a labelled sample). A
  batch without any labelled sample steps the head's Adam with zero gradients where the plain
  update leaves the head out (the town labels every observation, so this does not arise there);
- the actor loss reads the critic through detached parameters (``torch.func.functional_call``):
  the plain update computes the critics' weight gradients of the actor loss and throws them away
  at the next critic step; the actor's gradients are the same;
- Adam is the fused implementation (``fused=True``, one kernel per parameter group on a GPU,
  also on the CPU in torch ≥ 2.4); the plain update uses the default (single-tensor on the CPU,
  foreach on a GPU). Same formula, rounding may differ in the last bit;
- the target critics' EMA is one ``torch._foreach_lerp_`` (bitwise the per-tensor ``lerp_``);
- the losses are kept as tensors: the only host synchronisation is when metrics are logged.

Options on top (``compile``, ``bf16``):

- ``compile``: ``torch.compile`` (inductor) of the two pure-tensor parts, the critic + auxiliary
  objective (target included) and the actor objective, forward and backward. ``reduce-overhead``
  adds CUDA graphs on a GPU (``torch.compile``'s CUDA-graph trees; on a CPU it is inductor's default
  mode). Inductor fuses element-wise chains (A-LIX's mixing, the losses) and may reorder float
  additions: results agree with the eager fast update to float32 rounding, not bitwise. Inductor
  needs a C++ compiler on the CPU and Triton on a GPU; without them (``compile_unavailable``) the
  fast update runs eagerly and says so once;
- ``bf16``: the objectives' forward under ``torch.autocast(bfloat16)`` (convolutions and matrix
  products in bfloat16, losses and A-LIX's dual gradient in float32). This changes the result:
  bfloat16 keeps 8 bits of mantissa, so losses and gradients differ from float32 at ~1e-2
  relative; it is off by default and stated wherever used;
- ``channels_last``: the image encoder's convolutions in NHWC (``torch.channels_last``), the
  layout cuDNN's fastest kernels use on a GPU; the same arithmetic, summed in another order.
"""

from __future__ import annotations

import shutil

import torch

from drivelab.agents.rlad.alix import draw_offsets
from drivelab.agents.rlad.augmentation import draw_shifts

COMPILE_MODES = ("none", "default", "reduce-overhead", "max-autotune")
NOISE_KEYS = ("shifts", "next_shifts", "next_offsets", "next_noise", "offsets", "noise")


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
