"""``drivelab train --algo ppo_own`` with self-imitation learning added to each update: a screen for
issue 49's intersection, where PPO learns to wait rather than to cross promptly. Not a trainer
option and never a leaderboard row; a recipe that needs it gets it in ``ppo_own`` first.

    nice -n 10 env OMP_NUM_THREADS=1 NUMBA_NUM_THREADS=1 \\
        .venv/bin/python benchmarks/self_imitation_screen.py [--sil-updates 4] [--sil-batch-size 512]
        [--sil-capacity 100000] [--sil-value-coef 0.01] -- DRIVELAB-TRAIN-ARGUMENTS

Self-imitation learning (Oh, Guo, Singh and Lee, ICML 2018) keeps the agent's own recent
transitions with their discounted returns R (here the rollout's Monte-Carlo returns: GAE with
λ = 1, bootstrapped only at the rollout's end) and, after each PPO update, takes ``--sil-updates``
gradient steps on minibatches drawn uniformly from the last ``--sil-capacity`` transitions:

    L = −Σ log π(a|s)·(R − V(s))₊ / n  +  c/2 · Σ ((R − V(s))₊)² / n,   n = #{R > V(s)},

so only actions that turned out better than the critic expected are imitated (c is
``--sil-value-coef``). The arguments after ``--`` are ``drivelab train``'s (``--algo ppo_own``);
the run directory is an ordinary ``ppo_own`` run that ``drivelab evaluate`` reads. The replay of
returns is not part of the run's resume state, so ``--resume`` is refused, and so are rewards
normalised by ``-H normalize_rewards=true`` (the returns would be in another scale than the critic).
"""

from __future__ import annotations

import dataclasses
import sys
from operator import itemgetter
from pathlib import Path

import numpy as np
import torch

from drivelab.agents import registry
from drivelab.agents.base import gradient_step
from drivelab.agents.onpolicy import compute_gae
from drivelab.agents.ppo import OwnPPO
from drivelab.agents.worlds import map_obs

sys.path.insert(0, str(Path(__file__).resolve().parent))
from provenance import Parser, positive, stop, whole  # noqa: E402

SETTINGS = {"updates": 4, "batch_size": 512, "capacity": 100_000, "value_coef": 0.01}


class SelfImitationPPO(OwnPPO):
    """``ppo_own`` whose every update ends with self-imitation steps on its recent transitions."""

    _replay = None  # (observations, actions, returns) of the last ``capacity`` transitions

    def collect(self, worlds, callback):
        rollout = super().collect(worlds, callback)
        if rollout is None:
            return None
        storage, steps = self._storage, len(rollout.returns) // worlds.count
        _, returns = compute_gae(
            storage.rewards[:steps] + storage.bootstrap[:steps], storage.values[:steps].double().numpy(),
            storage.ends[:steps], self._values(self._last_obs), self.config.gamma, 1.0,
        )  # fmt: skip
        new = (rollout.observations, rollout.actions, torch.from_numpy(returns.reshape(-1)))
        if self._replay is None:
            self._replay = new
        else:

            def keep(old, fresh):
                return torch.cat([old, fresh])[-SETTINGS["capacity"] :]

            old = self._replay
            self._replay = (map_obs(keep, old[0], new[0]), keep(old[1], new[1]), keep(old[2], new[2]))
        return rollout

    def update(self, rollout):
        metrics = super().update(rollout)
        observations, actions, returns = self._replay
        imitated = []
        for _ in range(SETTINGS["updates"]):
            indices = torch.randint(len(returns), (SETTINGS["batch_size"],), generator=self.generator)
            out, values = self.policy(map_obs(itemgetter(indices), observations))
            log_probs, _ = self.policy.log_prob_entropy(out, actions[indices], entropy=False)
            better = (returns[indices] - values).clamp(min=0.0)
            count = int((better > 0).sum())
            imitation = -(log_probs * better.detach()).sum()
            loss = (imitation + 0.5 * SETTINGS["value_coef"] * (better**2).sum()) / max(count, 1)
            gradient_step(self.optimizer, loss, self.policy.parameters(), self.config.max_grad_norm)
            imitated.append(count / SETTINGS["batch_size"])
        return {**metrics, "sil_fraction": float(np.mean(imitated))}


def use_self_imitation() -> None:
    """``--algo ppo_own`` trains (and names its saved models) with ``SelfImitationPPO`` in this process."""
    spec = registry.ALGORITHMS["ppo_own"]
    implementation = f"{SelfImitationPPO.__module__}:{SelfImitationPPO.__qualname__}"
    registry.ALGORITHMS["ppo_own"] = dataclasses.replace(spec, implementation=implementation)


def main(argv: list[str]) -> int:
    parser = Parser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--sil-updates", type=whole(1), default=SETTINGS["updates"])
    parser.add_argument("--sil-batch-size", type=whole(1), default=SETTINGS["batch_size"])
    parser.add_argument("--sil-capacity", type=whole(1), default=SETTINGS["capacity"])
    parser.add_argument("--sil-value-coef", type=positive, default=SETTINGS["value_coef"])
    split = argv.index("--") if "--" in argv else len(argv)
    args, train = parser.parse_args(argv[:split]), argv[split + 1 :]
    joined = " ".join(train).lower()  # -H values are YAML: True and true alike
    if "--algo ppo_own" not in joined and "--algo=ppo_own" not in joined:
        stop("the arguments after -- must train ppo_own (--algo ppo_own)")
    if "--resume" in train or "normalize_rewards=true" in joined:
        stop("the self-imitation replay is not in the resume state and its returns are unscaled: "
             "no --resume, no -H normalize_rewards=true")  # fmt: skip
    SETTINGS.update(updates=args.sil_updates, batch_size=args.sil_batch_size, capacity=args.sil_capacity,
                    value_coef=args.sil_value_coef)  # fmt: skip
    use_self_imitation()
    from drivelab.cli import main as drivelab

    sys.argv = ["drivelab", "train", *train]
    drivelab()
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
