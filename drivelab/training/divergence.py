"""Divergence: a run whose weights became NaN or infinite stops at once, keeping its last finite
checkpoint.

A diverged network acts on NaN without an error, so ``RunCallback`` looks at the weights
(``non_finite_weights``) at its safe points, at most once per ``CHECK_EVERY_STEPS`` steps on a fixed
grid of steps (a resumed run checks where the uninterrupted one did), and before every periodic
evaluation and checkpoint. Q-learning's table is not looked at: with 0 < α <= 1 and γ <= 1 (checked)
its values stay finite."""

from __future__ import annotations

from pathlib import Path

import torch

from drivelab.config import RunConfig
from drivelab.errors import UsageError

# at most one check per this many steps: under 0.1 % of a run (benchmarks/results/divergence_check.md)
CHECK_EVERY_STEPS = 100


def model_weights(model) -> list[tuple[str, torch.Tensor]]:
    """(name, tensor) of every floating-point weight of ``model``, each once: the parameters and
    buffers of its torch modules and its tensor attributes, named from the attribute that holds
    them."""
    weights: dict[int, tuple[str, torch.Tensor]] = {}  # by id: the first name of each tensor
    for attribute, value in vars(model).items():
        if isinstance(value, torch.nn.Module):
            named = [*value.named_parameters(attribute), *value.named_buffers(attribute)]
        elif isinstance(value, torch.Tensor):
            named = [(attribute, value)]
        else:
            continue
        for name, tensor in named:
            if tensor.is_floating_point():
                weights.setdefault(id(tensor), (name, tensor))
    return list(weights.values())


def non_finite_weights(model) -> list[tuple[str, str]]:
    """(name, "nan" or "inf") of each weight tensor of ``model`` holding a NaN or an infinity; empty
    when every weight is finite. One sum per tensor: only a tensor whose sum is not finite is read
    element by element."""
    weights = model_weights(model)
    by_device: dict[torch.device, list[torch.Tensor]] = {}
    for _, tensor in weights:
        by_device.setdefault(tensor.device, []).append(tensor.detach())
    with torch.no_grad():
        sums = [torch.stack([tensor.sum().float() for tensor in group]).sum() for group in by_device.values()]
        if all(bool(torch.isfinite(total)) for total in sums):
            return []
        return [
            (name, "nan" if bool(torch.isnan(tensor).any()) else "inf")
            for name, tensor in weights
            if not bool(torch.isfinite(tensor).all())
        ]


def remedy(model) -> str:
    """What to change in a new run: the hyper-parameters ``model``'s algorithm has for it."""
    config = getattr(model, "config", model)  # drivelab's agents keep theirs in ``config``
    return "lower learning_rate" + (", or limit max_grad_norm" if hasattr(config, "max_grad_norm") else "")


class TrainingDiverged(UsageError):
    """The network's weights (or the action distribution they give) became NaN or infinite: training
    cannot go on. No checkpoint is written from such a model.

    :param steps: the step at which it was found.
    :param checkpoint_steps: the step of the run's latest (finite) checkpoint.
    :param found: ``non_finite_weights``; empty when the weights are finite but what they computed
        is not.
    :param remedy: ``remedy(model)``."""

    def __init__(
        self,
        config: RunConfig,
        steps: int,
        run_dir: Path,
        checkpoint_steps: int,
        found: list[tuple[str, str]],
        remedy: str = "lower learning_rate",
    ) -> None:
        if found:
            name, value = found[0]
            others = f" (and {len(found) - 1} more weight tensors)" if len(found) > 1 else ""
            what = f"{name}{others} became {value}"
        else:
            what = "the network's outputs became NaN or infinite"
        if (run_dir / "checkpoints" / "latest.json").is_file():
            kept = (
                f"{str(run_dir)!r} keeps its last finite checkpoint, of step {checkpoint_steps}, for "
                f"`drivelab evaluate {run_dir}` (a resume would repeat the same steps)"
            )
        else:
            kept = "no checkpoint was written, so the run directory is removed"
        super().__init__(
            f"training of {config.algo!r} diverged at step {steps}: {what}; {remedy} in a new run; {kept}"
        )
        self.steps, self.checkpoint_steps, self.found = steps, checkpoint_steps, found


def raised_by_divergence(model, exc: Exception) -> bool:
    """Whether ``exc``, raised while learning, comes from non-finite numbers: non-finite weights, or
    torch's check of a distribution's parameters."""
    invalid_distribution = isinstance(exc, ValueError) and "found invalid values" in str(exc)
    return invalid_distribution or bool(non_finite_weights(model))
