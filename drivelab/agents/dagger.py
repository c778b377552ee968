"""DAgger (Ross, Gordon & Bagnell, AISTATS 2011) with the rule-based expert (``--algo dagger``).

Iteration i drives the training worlds with the mixture πᵢ = βᵢ·π* + (1 − βᵢ)·π̂ᵢ (in each world
and step the expert acts with probability βᵢ, else the deterministic learner), labels every
visited state with the expert's action, and retrains the learner on all the labelled states so
far. β₁ = 1 (behaviour cloning), βᵢ = p^(i−1) with p = ``beta_decay``; everything else is ``bc.py``'s.
"""

from __future__ import annotations

from dataclasses import dataclass

from drivelab.agents.bc import BCConfig, BehaviourCloning
from drivelab.errors import UsageError


@dataclass(frozen=True)
class DAggerConfig(BCConfig):
    """Behaviour cloning's hyper-parameters (``bc.BCConfig``) and the mixture's decay.

    :param beta_decay: p of βᵢ = p^(i−1) (0: the learner alone acts from the second iteration on).
    """

    beta_decay: float = 0.5

    def check(self, algo: str) -> None:
        super().check(algo)
        if not 0 <= self.beta_decay <= 1:
            raise UsageError(f"{algo!r} needs 0 <= beta_decay <= 1, got {self.beta_decay}")


class DAgger(BehaviourCloning):
    """Dataset aggregation: the learner drives (mixed with the expert), the expert labels."""

    config_class = DAggerConfig

    def beta(self, iteration: int) -> float:
        """βᵢ = p^(i−1): 1 at the first iteration."""
        return float(self.config.beta_decay ** (iteration - 1))
