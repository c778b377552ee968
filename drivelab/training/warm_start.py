"""Starting a run from another run's policy (``init_from``, ``drivelab train --init-from``).

The imitation learners (``bc``, ``dagger``) train the very network of drivelab's on-policy agents
(``agents/actor_critic.py`` loads their weights), so a PPO or A2C run can start from an imitation
policy and improve on it by reinforcement learning: expert → imitation → RL, the lineage of Roach
and CaRL. Only the weights travel: the optimiser, the step count and the critic's training start
afresh (``-H critic_warmup_steps`` trains the critic first). The source is read as any run is, so
nothing is unpickled.
"""

from __future__ import annotations

import torch

from drivelab.config import RunConfig
from drivelab.errors import UsageError

FINE_TUNERS = ("ppo_own", "a2c_own")  # the agents whose network an imitation policy's weights fit
# what the source run and this one must share for the policy's inputs and outputs to mean the same
SHARED = {
    "sensors (obs)": lambda config: list(config.obs),
    "action": lambda config: config.action,
    "action options": lambda config: config.env_options.get("action_options") or {},
}


def initial_policy(config: RunConfig) -> dict[str, torch.Tensor]:
    """The weights of the policy of ``config.init_from`` (a run directory or a shipped agent),
    after checking that it reads the same sensors and acts with the same action as ``config``; a
    ``log_std_init`` the run gives replaces the source's log σ (a tanh-Gaussian's exploration)."""
    from drivelab.training.zoo import load_trained

    source = config.init_from
    if config.algo not in FINE_TUNERS:
        raise UsageError(f"init_from starts {' or '.join(FINE_TUNERS)} runs, not {config.algo!r}")
    trained = load_trained(source)
    for what, value in SHARED.items():
        if value(trained.config) != value(config):
            raise UsageError(
                f"init_from {source!r} was trained with other {what} ({value(trained.config)!r}) than this "
                f"run's ({value(config)!r})"
            )
    policy = getattr(trained.agent, "policy", None)
    if not isinstance(policy, torch.nn.Module):
        raise UsageError(f"init_from {source!r}: a {trained.config.algo!r} agent has no policy network")
    weights = {key: value.detach().clone() for key, value in policy.state_dict().items()}
    if "log_std_init" in config.hyperparams and "log_std" in weights:  # the run's own exploration
        weights["log_std"] = torch.full_like(weights["log_std"], float(config.hyperparams["log_std_init"]))
    return weights


def load_initial_policy(agent, weights: dict[str, torch.Tensor], source: str) -> None:
    """Put ``weights`` (``initial_policy``) into ``agent``'s policy, every tensor in place: a
    UsageError naming the first mismatch when the networks differ."""
    try:
        agent.start_from(weights)
    except RuntimeError as exc:  # missing or unexpected keys, or other shapes
        detail = " ".join(str(exc).split())
        raise UsageError(
            f"init_from {source!r}: its policy network is not this run's (net_arch, shared_encoder, "
            f"distribution and normalize_observations must match): {detail[:300]}"
        ) from None
