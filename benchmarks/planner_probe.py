"""What is reachable: a search-based planner that uses drivelab's own simulator as its model, on
the 100 evaluation episodes of the intersection and the highway.

    nice -n 10 env OMP_NUM_THREADS=1 NUMBA_NUM_THREADS=1 \\
        .venv/bin/python benchmarks/planner_probe.py [--scenario intersection|highway]
        [--episodes 100] [--horizons 3,5]

It plans as rl-agents' deterministic planners do on highway-env, with a copy of the environment as
the model. Before each decision it plays every sequence of the next H meta-actions, each in its own
world of one ``VectorDriveEnv``. Every world starts from the episode's seed and replays the actions
taken so far, so each one reaches the state the episode is in. The planner then takes the first
action of the best sequence. The worlds share the episode's seed, so the model is exact: the
planner knows what the other vehicles will do, and only the horizon limits it. It is an oracle
with a limited horizon: what it reaches shows that a good policy exists for that share of the
episodes. Each episode's actions are then played again in one ``DriveEnv``, as ``drivelab
evaluate`` plays the evaluation episodes, and must give the same outcome.

A sequence's score:
- **a collision**: −10⁶ plus the step it came at (the later, the better);
- **intersection**: an arrival without a collision scores +10⁶ less the step (the sooner, the
  better); otherwise, the route progress at the sequence's end, a time-limit end included;
- **highway**: the ego's summed speed over the sequence, the leaderboard's mean speed, to be as high
  as no collision allows; with ``--speed-cap V`` a speed counts up to V m/s only, so that the
  planner keeps its margins instead of driving faster than V.

Action spaces: the intersection's meta-actions without lane changes (slower, idle, faster), as
``intersection_probe.py``; the highway's five, with lane changes. One decision a second, regular
traffic. Writes ``benchmarks/results/planner_probe.{json,md}``. A scenario run again replaces its
section.
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

from intersection_probe import wilson_text  # noqa: E402
from provenance import Parser, command_line, cpu_isa, whole, wholes  # noqa: E402

from drivelab.training.seeds import evaluation_seeds  # noqa: E402
from drivelab.training.stats import bootstrap_ci  # noqa: E402

RESULTS = ROOT / "benchmarks" / "results"
SCENARIOS = {  # name: the environment's keywords
    "intersection": {"obs": "kinematics", "action": "meta", "traffic": "regular",
                     "action_options": {"lateral": False}},
    "highway": {"obs": "kinematics", "action": "meta", "traffic": "regular"},
}  # fmt: skip
ARRIVAL, COLLISION = 1e6, -1e6


def sequence_scores(
    env, scenario: str, seed: int, taken: list[int], horizon: int, speed_cap: float = np.inf, futures: int = 0
) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """Every sequence of the next ``horizon`` actions played from episode ``seed``'s state after the
    actions ``taken``: (the sequences (S, H), whether each collides (M, S), each one's score (M, S)),
    over the M = ``futures`` sampled futures of the arrivals (M = 1 with ``futures`` 0: the exact
    model); None when the actions taken ended the episode (world 0's ``env.batch.events`` then holds
    the ending). On the highway a speed counts up to ``speed_cap`` (m/s) in a sequence's score."""
    actions = env.single_action_space.n
    sequences = np.array(list(itertools.product(range(actions), repeat=horizon)))
    count = len(sequences)
    plans = np.tile(sequences, (max(futures, 1), 1))  # world m · count + i plays sequence i
    worlds = len(plans)
    env.reset(options={"episode_seeds": np.full(worlds, seed)})
    for action in taken:  # every world in the episode's state
        _, _, terminated, truncated, _ = env.step(np.full(worlds, action))
    if taken and (terminated[0] or truncated[0]):  # the last action taken ended the episode
        return None
    for m in range(futures):  # arrivals from here on drawn afresh: the same M futures per sequence
        for world in range(m * count, (m + 1) * count):
            env.simulator.rngs[world] = np.random.default_rng([seed, len(taken), m])
    ended, collided, score = np.zeros(worlds, dtype=bool), np.zeros(worlds, dtype=bool), np.zeros(worlds)
    for j in range(horizon):
        _, _, terminated, truncated, _ = env.step(plans[:, j])
        live, events = ~ended, env.batch.events
        crashed, arrived = live & events.collided, live & events.arrived & ~events.collided
        collided |= crashed
        score[crashed] = COLLISION + j
        going = live & ~crashed
        if scenario == "intersection":
            score[arrived] = ARRIVAL - j
            going &= ~arrived
            score[going] = env.batch.route.progress_m[going]
        else:
            score[going] += np.minimum(env.batch.ego.speed_mps[going], speed_cap)
        ended |= terminated | truncated
    shape = (max(futures, 1), count)
    return sequences, collided.reshape(shape), score.reshape(shape)


def plan_action(
    env, scenario: str, seed: int, taken: list[int], horizon: int, speed_cap: float = np.inf, futures: int = 0
) -> int | None:
    """The planner's next action in episode ``seed`` after the actions ``taken`` (the first of the
    best sequence of ``sequence_scores``), or None when they ended the episode. With the exact model
    the best sequence scores highest; with ``futures`` M > 0 (the intersection: the model knows the
    state now but not the vehicles still to arrive, whose arrival generators are reseeded after the
    replay, the same M seeds for every sequence) it collides in the fewest futures, then has the
    highest mean score over the others."""
    scored = sequence_scores(env, scenario, seed, taken, horizon, speed_cap, futures)
    if scored is None:
        return None
    sequences, collided, score = scored
    if futures:
        crashes = collided.sum(0)
        others = np.where(collided, 0.0, score).sum(0) / np.maximum(futures - crashes, 1)
        best = int(np.lexsort((-others, crashes))[0])
    else:
        best = int(np.argmax(score[0]))
    return int(sequences[best, 0])


def plan_episode(
    env, scenario: str, seed: int, horizon: int, speed_cap: float = np.inf, futures: int = 0
) -> dict:
    """Play evaluation episode ``seed`` with the planner of horizon ``horizon`` (``plan_action``):
    its outcome."""
    taken: list[int] = []
    while (action := plan_action(env, scenario, seed, taken, horizon, speed_cap, futures)) is not None:
        taken.append(action)
    events = env.batch.events
    crash, arrived = bool(events.collided[0]), bool(events.arrived[0] and not events.collided[0])
    return replayed(scenario, seed, taken, crash, arrived)


def replayed(scenario: str, seed: int, actions: list[int], crash: bool, arrived: bool) -> dict:
    """The metrics of ``actions`` played in evaluation episode ``seed`` as ``drivelab evaluate``
    plays it (one ``DriveEnv``), checked against the planner's ending (``crash``, ``arrived``); the
    actions kept as a string of their digits."""
    import drivelab

    env = drivelab.make(scenario, **SCENARIOS[scenario])
    env.reset(options={"episode_seed": seed})
    for t, action in enumerate(actions):
        _, _, terminated, truncated, info = env.step(action)
        if (terminated or truncated) != (t == len(actions) - 1):
            raise AssertionError(
                f"episode {seed}: the replay ends at step {t + 1}, the plan at {len(actions)}"
            )
    metrics = info["episode_metrics"]
    outcome = {"actions": "".join(map(str, actions)), "success": metrics["success"] > 0,
               "crash": metrics["collisions"] > 0, "mean_speed_mps": metrics["mean_speed_mps"]}  # fmt: skip
    if outcome["crash"] != crash or (scenario == "intersection" and outcome["success"] != arrived):
        raise AssertionError(f"episode {seed}: the plan's outcome is not the replay's")
    return outcome


def play(scenario: str, horizon: int, episodes: int, speed_cap: float = np.inf, futures: int = 0) -> dict:
    from drivelab.envs.vector import VectorDriveEnv

    actions = 3 if scenario == "intersection" else 5
    env = VectorDriveEnv(actions**horizon * max(futures, 1), scenario, **SCENARIOS[scenario])
    assert env.single_action_space.n == actions, env.single_action_space
    start = time.perf_counter()
    seeds = evaluation_seeds(episodes)
    outcomes = [plan_episode(env, scenario, int(seed), horizon, speed_cap, futures) for seed in seeds]
    speeds = [o["mean_speed_mps"] for o in outcomes]
    low, high = bootstrap_ci(speeds)
    return {
        "horizon": horizon,
        "speed_cap_mps": None if np.isinf(speed_cap) else speed_cap,
        "sequences": actions**horizon,
        "futures": futures,
        "episodes": episodes,
        "date": time.strftime("%Y-%m-%d"),
        "success": sum(o["success"] for o in outcomes),
        "crash": sum(o["crash"] for o in outcomes),
        "mean_speed_mps": float(np.mean(speeds)),
        "mean_speed_interval": [low, high],
        "wall_s": round(time.perf_counter() - start, 1),
        "outcomes": outcomes,
    }


INTRODUCTION = (
    "Before each decision the planner plays every sequence of the next H meta-actions (one a second) in "
    "its own world, from the episode's seed and the actions taken so far, and takes the first action of "
    "the best. The model is exact (the worlds share the episode's seed), so this is an oracle whose only "
    "limit is H: what it reaches shows that a good policy exists for that share of the episodes. On the "
    "intersection, where vehicles keep arriving at random, a row with sampled futures knows the state now "
    "(every vehicle, its route and how it drives) but not the arrivals to come: each sequence is played "
    "in M worlds whose arrivals are drawn afresh after the replay, and the best collides in the fewest. Each "
    "episode's actions, played again as `drivelab evaluate` plays the episode, gave the planner's "
    "outcome. Rates in %, with their 90 % Wilson interval; speed: the mean over episodes of each "
    "episode's mean speed, with its 90 % bootstrap interval."
)
SECTIONS = {
    "intersection": (
        "Intersection",
        "Meta-actions without lane changes (slower, idle, faster), 13 s episodes, regular traffic. "
        "The best sequence: no collision first, then the earliest arrival, then the most route "
        "progress. Success: arrival without a collision. Fixed plans: `intersection_probe.md`; the "
        "learners: `leaderboard.md`.",
    ),
    "highway": (
        "Highway",
        "The five meta-actions (lane changes, idle, faster, slower), 30 s episodes, regular traffic. "
        "The best sequence: no collision first, then the highest summed speed, each speed counted up "
        "to the row's cap. The meta-actions' target speeds are 20, 25 and 30 m/s, so a cap between 25 "
        "and 30 m/s still makes 30 the best. A hand-written privileged driver: `highway_probe.md`; "
        "the learners: `leaderboard.md`.",
    ),
}


def cap_text(cap: float | None) -> str:
    return "—" if cap is None else f"{cap:g} m/s"


def futures_text(scenario: str, row: dict) -> str:
    futures = row.get("futures", 0)
    if scenario != "intersection":
        return "—"
    return "known (the episode's own)" if not futures else f"unknown: {futures} futures sampled"


def markdown(result: dict) -> str:
    lines = ["# What is reachable: a planner with the simulator as its model, on the evaluation episodes",
             "", INTRODUCTION]  # fmt: skip
    for scenario, section in result["scenarios"].items():
        title, text = SECTIONS[scenario]
        lines += [
            "",
            f"## {title}",
            "",
            "Commands: "
            + ", ".join(f"`{c}`" for c in dict.fromkeys(row["command"] for row in section["rows"])),
            "",
            f"Machine: {section['machine']}; "
            + ", ".join(dict.fromkeys(row.get("date", section["date"]) for row in section["rows"]))
            + ".",
            "",
            text,
            "",
            "| horizon H (decisions) | speed counted up to | arrivals to come | sequences per decision | "
            "success % | crash % | mean speed m/s | wall s |",
            "|---|---|---|---|---|---|---|---|",
        ]
        for row in section["rows"]:
            n = row["episodes"]
            low, high = row["mean_speed_interval"]
            lines.append(
                f"| {row['horizon']} | {cap_text(row.get('speed_cap_mps'))} | "
                f"{futures_text(scenario, row)} | {row['sequences']} | "
                f"{wilson_text(row['success'], n)} | "
                f"{wilson_text(row['crash'], n)} | {row['mean_speed_mps']:.1f} [{low:.1f}, {high:.1f}] | "
                f"{row['wall_s']:.0f} |"
            )
    return "\n".join(lines) + "\n"


def main() -> None:
    parser = Parser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenario", choices=list(SCENARIOS), default="intersection")
    parser.add_argument("--episodes", type=whole(), default=100)
    parser.add_argument("--horizons", type=wholes(1), default=[3, 5], help="comma-separated, e.g. 3,5")
    parser.add_argument("--speed-cap", type=whole(), default=None, help="highway: m/s a speed counts up to")
    parser.add_argument(
        "--futures", type=whole(0), default=0,
        help="intersection: plan over this many sampled futures of the arrivals to come (0: the exact model)",
    )  # fmt: skip
    args = parser.parse_args()
    if args.speed_cap is not None and args.scenario != "highway":
        parser.error("--speed-cap is the highway's")
    if args.futures and args.scenario != "intersection":
        parser.error("--futures is the intersection's (its arrivals are the model's only randomness)")
    speed_cap = np.inf if args.speed_cap is None else float(args.speed_cap)
    actions = 3 if args.scenario == "intersection" else 5
    if actions ** max(args.horizons) * max(args.futures, 1) > 3**7:
        parser.error("--horizons, --futures: more than 3**7 worlds per decision")
    rows = []
    for horizon in args.horizons:
        rows.append(
            {
                "command": command_line(),
                **play(args.scenario, horizon, args.episodes, speed_cap, args.futures),
            }
        )
        print({k: v for k, v in rows[-1].items() if k != "outcomes"}, flush=True)
    path = RESULTS / "planner_probe.json"
    result = json.loads(path.read_text()) if path.exists() else {"scenarios": {}}
    section = result["scenarios"].get(args.scenario, {})
    kept = [{"date": section.get("date"), **row} for row in section.get("rows", [])]

    def key(row: dict) -> tuple:
        return row["horizon"], row.get("speed_cap_mps"), row.get("futures", 0)

    run = {key(row) for row in rows}  # a row run again is replaced
    result["scenarios"][args.scenario] = {
        "machine": f"{cpu_isa()}, {os.cpu_count()} cores, Python {platform.python_version()}",
        "date": time.strftime("%Y-%m-%d"),
        "environment": SCENARIOS[args.scenario],
        "rows": [row for row in kept if key(row) not in run] + rows,
    }
    RESULTS.mkdir(exist_ok=True)
    path.write_text(json.dumps(result, indent=1))
    (RESULTS / "planner_probe.md").write_text(markdown(result))
    print(markdown(result))


if __name__ == "__main__":
    main()
