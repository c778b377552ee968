"""Reward ablations: the same agent trained under several rewards (or a reward minus one term at
a time) over seeds, then compared. A thin layer over sweeps and comparisons."""

from __future__ import annotations

from pathlib import Path

from drivelab.errors import UsageError
from drivelab.rewards.shapers import parse_reward
from drivelab.training.compare import load_run, write_report
from drivelab.training.sweep import expand_sweep, run_dirs, run_sweep


def reward_variants(rewards: list[str] | None, drop_terms: list[str] | None, base_reward: str) -> list[str]:
    """The rewards to train under.

    :param rewards: explicit reward specs (presets or ``term=weight`` lists), used as given.
    :param drop_terms: terms of ``base_reward`` to drop one at a time: ``base_reward`` itself, then
        ``"<base_reward>,<term>=0"`` for each term.
    :param base_reward: the reward that ``drop_terms`` refers to."""
    if bool(rewards) == bool(drop_terms):
        raise UsageError("give exactly one of --rewards or --drop-terms")
    if rewards:
        if len(set(rewards)) != len(rewards):
            raise UsageError("--rewards lists a reward twice")
        for reward in rewards:
            parse_reward(reward)
        return list(rewards)
    weights = parse_reward(base_reward).weights
    for term in drop_terms:
        if term not in weights:
            raise UsageError(
                f"cannot drop {term!r}: the reward {base_reward!r} has the terms {', '.join(weights)}"
            )
    if len(set(drop_terms)) != len(drop_terms):
        raise UsageError("--drop-terms lists a term twice")
    variants = [base_reward] + [_dropped(base_reward, term) for term in drop_terms]
    for variant in variants[1:]:
        parse_reward(variant)  # dropping the only term leaves no reward
    return variants


def _dropped(reward: str, term: str) -> str:
    """``"<reward>,<term>=0"``, without the weight ``reward`` itself gives ``term``."""
    items = [item.strip() for item in reward.split(",") if item.strip()]
    kept = [item for item in items if "=" not in item or item.partition("=")[0].strip() != term]
    return ",".join([*kept, f"{term}=0"]) if len(kept) < len(items) else f"{reward},{term}=0"


def ablation_spec(
    env: str,
    algo: str,
    variants: list[str],
    seeds: int,
    steps: int,
    base: dict | None = None,
    eval_episodes: int = 10,
) -> dict:
    """The sweep mapping of an ablation: rewards × seeds for one algorithm on one scenario.

    :param base: further run fields shared by every run (obs, action, traffic, backend,
        hyperparams, env_options, ...).
    """
    if seeds < 1:
        raise UsageError(f"--seeds must be >= 1, got {seeds}")
    if eval_episodes < 1:  # a sweep's 0 skips the final evaluation, which is what the report compares
        raise UsageError(
            f"--eval-episodes must be >= 1 (the report compares the final evaluations), got {eval_episodes}"
        )
    return {
        "name": "ablate",
        "base": {**(base or {}), "algo": algo, "env": env, "steps": steps},
        "grid": {"reward": variants, "seed": seeds},
        "eval_episodes": eval_episodes,
    }


def ablate(
    env: str,
    algo: str,
    rewards: list[str] | None = None,
    drop_terms: list[str] | None = None,
    base_reward: str = "highway",
    seeds: int = 3,
    steps: int = 10_000,
    base: dict | None = None,
    runs_dir: str | Path = "runs",
    out_dir: str | Path | None = None,
    eval_episodes: int = 10,
    executor: str = "pool",
    workers: int | None = None,
    address: str | None = None,
    command: str | None = None,
) -> tuple[Path | None, list[dict]]:
    """Run a reward ablation as a sweep (finished runs skipped on a re-run) and compare its runs;
    (report directory, sweep outcomes), the report None when a run failed.

    :param out_dir: report directory (default ``reports/ablate-<algo>-<env>``).
    :param command: the command line, quoted in the report."""
    variants = reward_variants(rewards, drop_terms, base_reward)
    spec = ablation_spec(env, algo, variants, seeds, steps, base, eval_episodes)
    sweep = expand_sweep(spec, runs_dir)
    outcomes = run_sweep(sweep, executor=executor, workers=workers, address=address)
    if not all(outcome["ok"] for outcome in outcomes):
        return None, outcomes
    what = f"dropping {', '.join(drop_terms)} from {base_reward!r}" if drop_terms else "rewards"
    title = f"Reward ablation: {algo} on {env}, {what}, {seeds} seeds x {steps} steps"
    out_dir = Path(out_dir) if out_dir is not None else Path("reports") / f"ablate-{algo}-{env}"
    report = write_report([load_run(d) for d in run_dirs(sweep)], out_dir, title=title, command=command)
    return report, outcomes
