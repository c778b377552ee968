"""What is reachable on the intersection: a search-based planner that uses drivelab's own simulator
as its model, on the 100 evaluation episodes.

    nice -n 10 env OMP_NUM_THREADS=1 NUMBA_NUM_THREADS=1 \\
        .venv/bin/python benchmarks/planner_probe.py [--episodes 100] [--horizons 3,5]

It plans as rl-agents' deterministic planners do on highway-env, with a copy of the environment as
the model. Before each decision it plays every sequence of the next H actions, each in its own
world of one ``VectorDriveEnv``. Every world starts from the episode's seed and replays the actions
taken so far, so each one reaches the state the episode is in. The planner then takes the first
action of the best sequence. The worlds share the episode's seed, so the model is exact: the
planner knows what the other vehicles will do, and only the horizon limits it. It is an
oracle with a limited horizon. What it reaches shows that a good policy exists for that share of
the episodes; where it fails, no sequence of H actions from there avoids the failure. Each
episode's actions are then played again in one ``DriveEnv``, as ``drivelab evaluate`` plays the
evaluation episodes, and must give the same outcome.

A sequence's score:
- a collision: −10⁶ plus the step it came at (the later, the better);
- an arrival without one: +10⁶ less the step (the sooner, the better);
- otherwise, the route progress at its end (a time-limit end included).

Action space: highway-env's intersection meta-actions without lane changes (slower, idle, faster;
one decision a second, 13 s episodes), regular traffic, as ``intersection_probe.py``. Success and
crash are the leaderboard's: arrival without a collision, and any collision. Writes
``benchmarks/results/planner_probe.{json,md}``.
"""

from __future__ import annotations

import itertools
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

from intersection_probe import header, wilson_text  # noqa: E402
from provenance import Parser, command_line, cpu_isa, whole, wholes  # noqa: E402

from drivelab.training.seeds import evaluation_seeds  # noqa: E402

RESULTS = ROOT / "benchmarks" / "results"
SCENARIO = {"scenario": "intersection", "obs": "kinematics", "action": "meta", "traffic": "regular",
            "action_options": {"lateral": False}}  # fmt: skip
ARRIVAL, COLLISION = 1e6, -1e6


def plan_episode(env, seed: int, horizon: int) -> dict:
    """Play evaluation episode ``seed`` with the planner of horizon ``horizon``: its outcome."""
    actions = env.single_action_space.n
    sequences = np.array(list(itertools.product(range(actions), repeat=horizon)))
    count = len(sequences)
    taken: list[int] = []
    while True:
        env.reset(options={"episode_seeds": np.full(count, seed)})
        for action in taken:  # every world in the episode's state
            env.step(np.full(count, action))
        ended, score = np.zeros(count, dtype=bool), np.zeros(count)
        first: dict[str, np.ndarray] = {}
        for j in range(horizon):
            _, _, terminated, truncated, _ = env.step(sequences[:, j])
            live, events = ~ended, env.batch.events
            collided, arrived = live & events.collided, live & events.arrived & ~events.collided
            score[collided] = COLLISION + j
            score[arrived] = ARRIVAL - j
            going = live & ~collided & ~arrived
            score[going] = env.batch.route.progress_m[going]
            if j == 0:
                first = {"ended": (terminated | truncated).copy(), "collided": collided, "arrived": arrived}
            ended |= terminated | truncated
        best = int(np.argmax(score))
        taken.append(int(sequences[best, 0]))
        if first["ended"][best]:
            return {"actions": taken, "success": bool(first["arrived"][best]),
                    "crash": bool(first["collided"][best])}  # fmt: skip


def replayed(seed: int, actions: list[int]) -> dict:
    """The outcome of ``actions`` played in evaluation episode ``seed`` as ``drivelab evaluate``
    plays it (one ``DriveEnv``): the planner's outcome, checked."""
    import drivelab

    options = dict(SCENARIO)
    env = drivelab.make(options.pop("scenario"), **options)
    env.reset(options={"episode_seed": seed})
    for t, action in enumerate(actions):
        _, _, terminated, truncated, info = env.step(action)
        if (terminated or truncated) != (t == len(actions) - 1):
            raise AssertionError(
                f"episode {seed}: the replay ends at step {t + 1}, the plan at {len(actions)}"
            )
    metrics = info["episode_metrics"]
    return {"actions": actions, "success": metrics["success"] > 0, "crash": metrics["collisions"] > 0}


def play(horizon: int, episodes: int) -> dict:
    from drivelab.envs.vector import VectorDriveEnv

    options = dict(SCENARIO)
    scenario = options.pop("scenario")
    env = VectorDriveEnv(3**horizon, scenario, **options)
    assert env.single_action_space.n == 3, env.single_action_space
    start = time.perf_counter()
    outcomes = []
    for seed in evaluation_seeds(episodes):
        planned = plan_episode(env, int(seed), horizon)
        if replayed(int(seed), planned["actions"]) != planned:
            raise AssertionError(f"episode {seed}: the plan's outcome is not the replay's")
        outcomes.append(planned)
    return {
        "horizon": horizon,
        "episodes": episodes,
        "success": sum(o["success"] for o in outcomes),
        "crash": sum(o["crash"] for o in outcomes),
        "wall_s": round(time.perf_counter() - start, 1),
        "outcomes": outcomes,
    }


def markdown(result: dict) -> str:
    lines = [
        *header(
            "Intersection: a planner with the simulator as its model, on the evaluation episodes", result
        ),
        "Before each decision the planner plays every sequence of the next H meta-actions (slower, idle, "
        "faster; one a second) in its own world, from the episode's seed and the actions taken so far, "
        "and takes the first action of the best: no collision first, then the earliest arrival, then "
        "the most route progress. The model is exact (the worlds share the episode's seed), so this "
        "is an oracle whose only limit is H. What it reaches shows that a good policy exists for "
        "that share of the episodes. 13 s episodes, regular traffic; rates in %, with their 90 % "
        "Wilson interval. Each episode's actions, played again as `drivelab evaluate` plays the "
        "episode, gave the planner's outcome. For comparison: fixed plans in `intersection_probe.md`, "
        "the learners in `leaderboard.md`.",
        "",
        "| horizon H (decisions) | sequences per decision | success % | crash % | wall s |",
        "|---|---|---|---|---|",
    ]
    for row in result["rows"]:
        n = row["episodes"]
        lines.append(
            f"| {row['horizon']} | {3 ** row['horizon']} | {wilson_text(row['success'], n)} | "
            f"{wilson_text(row['crash'], n)} | {row['wall_s']:.0f} |"
        )
    return "\n".join(lines) + "\n"


def main() -> None:
    parser = Parser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=whole(), default=100)
    parser.add_argument("--horizons", type=wholes(1), default=[3, 5], help="comma-separated, e.g. 3,5")
    args = parser.parse_args()
    if max(args.horizons) > 7:
        parser.error("--horizons above 7 play more than 3**7 worlds per decision")
    rows = []
    for horizon in args.horizons:
        rows.append(play(horizon, args.episodes))
        print({k: v for k, v in rows[-1].items() if k != "outcomes"}, flush=True)
    result = {
        "command": command_line(),
        "machine": f"{cpu_isa()}, {os.cpu_count()} cores, Python {platform.python_version()}",
        "date": time.strftime("%Y-%m-%d"),
        "scenario": SCENARIO,
        "rows": rows,
    }
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / "planner_probe.json").write_text(json.dumps(result, indent=1))
    (RESULTS / "planner_probe.md").write_text(markdown(result))
    print(markdown(result))


if __name__ == "__main__":
    main()
