"""How the intersection's policies choose where the choice matters: each decision of a policy,
scored by the planner with the simulator as its exact model. Evidence for issue 49 (what limits the
intersection's RL row).

    nice -n 10 env OMP_NUM_THREADS=1 NUMBA_NUM_THREADS=1 \\
        .venv/bin/python benchmarks/intersection_choice_probe.py AGENT [AGENT ...]
        [--episodes 200] [--horizon 3]

AGENT: a run directory of an intersection policy (meta-actions without lane changes), or a shipped
agent's name (``drivelab zoo``), e.g. ``intersection-ppo_own``, the leaderboard row's seed 0.

Each policy plays ``--episodes`` training episodes (seeds 5,000 on: none the planner's or the
imitation probe's) greedily, as ``drivelab evaluate`` plays. Before each of its decisions the
planner of ``planner_probe.py`` plays every sequence of the next H actions from that state, and each
action scores as the best sequence that starts with it. A decision is

- **best** when the policy's action scores as the best action does (ties count);
- **critical** when one action leads to a collision within H decisions and another does not; there
  an **unsafe** choice is a colliding action;
- **slower than needed** when the policy's action does not collide, scores below the best, and the
  best action is a faster one (idle rather than slower, faster rather than either).

Writes ``benchmarks/results/intersection_choice_probe.{json,md}`` (an agent measured again replaces
its row).
"""

from __future__ import annotations

import json
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from intersection_probe import wilson_text  # noqa: E402
from planner_probe import COLLISION, SCENARIOS, sequence_scores  # noqa: E402
from provenance import Parser, command_line, cpu_isa, stop, whole  # noqa: E402

RESULTS = ROOT / "benchmarks" / "results"
FIRST_SEED = 5_000
UNSAFE = COLLISION / 2  # a score below this collided


def action_scores(planner_env, seed: int, taken: list[int], horizon: int) -> np.ndarray | None:
    """(3,) each action's score: the best sequence of ``horizon`` decisions that starts with it, in
    the exact model; None when the actions taken ended the episode."""
    scored = sequence_scores(planner_env, "intersection", seed, taken, horizon)
    if scored is None:
        return None
    sequences, _, score = scored
    return np.array([score[0][sequences[:, 0] == a].max() for a in range(3)])


def load_policy(target: str):
    """The ``Trained`` policy of ``target`` (``zoo.load_trained``); one ``error:`` line and exit 2
    when it cannot be loaded or is not an intersection policy with the three longitudinal actions."""
    from gymnasium import spaces

    from drivelab.errors import UsageError
    from drivelab.training.zoo import load_trained

    try:
        trained = load_trained(target)
    except UsageError as exc:
        stop(str(exc))
    space = trained.env.action_space
    if trained.config.env != "intersection" or not (isinstance(space, spaces.Discrete) and space.n == 3):
        stop(f"{target!r} is not an intersection policy with the three longitudinal actions")
    return trained


def judge(target: str, trained, episodes: int, horizon: int) -> dict:
    """The decisions of ``trained`` (``load_policy``) over ``episodes`` training episodes, counted."""
    from drivelab.envs.vector import VectorDriveEnv

    env, agent = trained.env, trained.agent
    planner_env = VectorDriveEnv(3**horizon, "intersection", **SCENARIOS["intersection"])
    counts = dict.fromkeys(("decisions", "best", "critical", "unsafe", "slower_than_needed"), 0)
    outcomes = {"episodes": episodes, "success": 0, "crash": 0}
    start = time.perf_counter()
    for seed in range(FIRST_SEED, FIRST_SEED + episodes):
        obs, _ = env.reset(options={"episode_seed": seed})
        taken: list[int] = []
        while True:
            scores = action_scores(planner_env, seed, taken, horizon)
            assert scores is not None, "the planner's model ended the episode before the policy's environment"
            action = int(agent.predict(obs, deterministic=True)[0])
            safe, best = scores > UNSAFE, scores.max()
            counts["decisions"] += 1
            counts["best"] += bool(scores[action] == best)
            if safe.any() and not safe.all():
                counts["critical"] += 1
                counts["unsafe"] += bool(not safe[action])
            faster_best = any(scores[a] == best for a in range(action + 1, 3))
            counts["slower_than_needed"] += bool(safe[action] and scores[action] < best and faster_best)
            taken.append(action)
            obs, _, terminated, truncated, info = env.step(action)
            if terminated or truncated:
                metrics = info["episode_metrics"]
                outcomes["success"] += metrics["success"] > 0
                outcomes["crash"] += metrics["collisions"] > 0
                break
    return {"agent": str(target), "command": command_line(), "algo": trained.config.algo,
            "model_steps": int(agent.num_timesteps), **outcomes, **counts,
            "wall_s": round(time.perf_counter() - start, 1)}  # fmt: skip


def markdown(result: dict) -> str:
    commands = dict.fromkeys(row["command"] for row in result["rows"])
    lines = [
        "# How the intersection's policies choose where the choice matters",
        "",
        "Commands: " + ", ".join(f"`{command}`" for command in commands) + "  ",
        f"Machine: {result['machine']}; " + ", ".join(dict.fromkeys(r["date"] for r in result["rows"])) + ".",
        "",
        "Each policy plays training episodes greedily (seeds 5,000 on); before each of its decisions the "
        f"planner of `planner_probe.py` scores each action as the best sequence of {result['horizon']} "
        "decisions that starts with it, in the exact model. *Best*: the policy's action scores as the "
        "best one does. *Critical*: one action collides within the horizon and another does not; "
        "*unsafe*: the policy took a colliding one there. *Slower than needed*: the policy's action "
        "does not collide, scores below the best, and the best is a faster action. Rates in % with "
        "their 90 % Wilson interval. The policies: `leaderboard.md` (RL), "
        "`intersection_imitation_probe.md` (imitation of the planner).",
        "",
        "| agent | episodes | success / crash | decisions | best % | critical decisions | unsafe there % | "
        "slower than needed % | wall s |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for r in result["rows"]:
        unsafe = wilson_text(r["unsafe"], r["critical"]) if r["critical"] else "—"
        lines.append(
            f"| `{r['agent']}` ({r['algo']}, {r['model_steps']:,} steps) | {r['episodes']} | "
            f"{r['success']} / {r['crash']} | {r['decisions']:,} | "
            f"{wilson_text(r['best'], r['decisions'])} | {r['critical']:,} | {unsafe} | "
            f"{wilson_text(r['slower_than_needed'], r['decisions'])} | "
            f"{r['wall_s']:.0f} |"
        )
    return "\n".join(lines) + "\n"


def main() -> None:
    parser = Parser(description=__doc__.splitlines()[0])
    parser.add_argument("agents", nargs="+", help="run directories or shipped agents' names")
    parser.add_argument("--episodes", type=whole(), default=200)
    parser.add_argument("--horizon", type=whole(), default=3, help="the planner's horizon H (decisions)")
    args = parser.parse_args()
    if args.horizon > 7:
        parser.error("--horizon: more than 3**7 worlds per decision")
    policies = [load_policy(agent) for agent in args.agents]  # every one checked before any is played
    rows = []
    for agent, trained in zip(args.agents, policies, strict=True):
        rows.append({"date": time.strftime("%Y-%m-%d"), **judge(agent, trained, args.episodes, args.horizon)})
        print(json.dumps(rows[-1]), flush=True)
    path = RESULTS / "intersection_choice_probe.json"
    result = json.loads(path.read_text()) if path.exists() else {"rows": []}
    if result.get("horizon", args.horizon) != args.horizon:
        result["rows"] = []  # another horizon: another measure
    measured = {row["agent"] for row in rows}
    machine = f"{cpu_isa()}, {os.cpu_count()} cores, Python {platform.python_version()}"
    result.update(horizon=args.horizon, machine=machine)
    result["rows"] = [row for row in result["rows"] if row["agent"] not in measured] + rows
    RESULTS.mkdir(exist_ok=True)
    path.write_text(json.dumps(result, indent=1))
    (RESULTS / "intersection_choice_probe.md").write_text(markdown(result))
    print(markdown(result))


if __name__ == "__main__":
    main()
