"""Seed 004's Q-learning curves on follow-line / follow-lane, trained directly (not through run.py).

    .venv/bin/python benchmarks/qlearning_curves.py --scenario follow-line [--seeds 0,1,2] \
        [--steps 20000] [--eval-episodes 5]

For each seed: a tabular Q-learning agent with the seed's hyper-parameters (α 0.8, γ 0.9, ε0 0.9999,
ε × 0.9998 per step; after 20 000 steps ε ≈ 0.018) trains on the scenario's perception state
(``line`` or ``lane``) with the seed's action table and reward preset; then its greedy policy
drives ``--eval-episodes`` fresh episodes. Writes ``qlearning_<scenario>.json`` / ``.md`` and
the three-panel plot of every seed (``qlearning_<scenario>_s<seed>.png``) into
``benchmarks/results``.

Convergence (our definition; the seed reports "about 550 episodes" for follow-lane from its
reward curve): the first episode at which the mean return of the last 20 episodes reaches 90 % of
the way from the first 20 episodes' mean to the final plateau (the mean of the last 10 % of
episodes).
"""

from __future__ import annotations

import json
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np

os.environ.setdefault("PYGAME_HIDE_SUPPORT_PROMPT", "1")

import torch  # noqa: E402

from drivelab.agents.qlearning import QLearning  # noqa: E402
from drivelab.agents.qlearning_plots import plot_qlearning  # noqa: E402
from drivelab.envs.core import DriveEnv  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from provenance import Parser, cpu_isa, whole, wholes  # noqa: E402

RESULTS = Path(__file__).parent / "results"
SETUPS = {
    "follow-line": {"obs": "line", "action": "seed_line", "reward": "line_follow"},
    "follow-lane": {"obs": "lane", "action": "seed_lane", "reward": "lane_follow"},
    # the tabular baseline on highway: time-to-collision grid, meta-actions, highway-env's reward
    "highway": {"obs": "ttc_grid", "action": "meta", "reward": "highway"},
}
TRAFFIC = {"follow-line": "empty", "follow-lane": "empty", "highway": "regular"}
BACKEND = {"follow-line": "highway", "follow-lane": "highway", "highway": "fast"}
WINDOW = 20
EVAL_SEED_OFFSET = 10_000


def convergence_episode(returns: np.ndarray) -> int | None:
    """1-based episode where the 20-episode mean first gets 90 % of the way to the final plateau."""
    if len(returns) < 2 * WINDOW:
        return None
    moving = np.convolve(returns, np.ones(WINDOW) / WINDOW, mode="valid")
    start, plateau = moving[0], float(np.mean(returns[-max(len(returns) // 10, WINDOW) :]))
    if plateau <= start:
        return None
    reached = np.flatnonzero(moving >= start + 0.9 * (plateau - start))
    return int(reached[0]) + WINDOW if len(reached) else None


def evaluate(agent: QLearning, env: DriveEnv, episodes: int, seed: int) -> dict:
    """Greedy episodes: mean |lateral error|, distance and laps before leaving the lane, off-lane rate."""
    lateral, distances, laps, left, crashed, lengths = [], [], [], 0, 0, []
    for episode in range(episodes):
        obs, _ = env.reset(seed=seed + episode)
        lap_m = float(np.sum(np.hypot(*np.diff(env.world.route.polyline, axis=0).T)))
        start_m = env.world.route.progress_m
        done, steps = False, 0
        while not done:
            obs, _, terminated, truncated, info = env.step(agent.predict(obs)[0])
            lateral.append(abs(env.world.ego.lateral_offset_m))
            done, steps = terminated or truncated, steps + 1
        left += int(info["off_road"])
        crashed += int(info["crashed"])
        travelled = env.world.route.progress_m - start_m
        distances.append(travelled)
        laps.append(travelled / lap_m)
        lengths.append(steps)
    return {
        "episodes": episodes,
        "mean_abs_lateral_error_m": float(np.mean(lateral)),
        "mean_distance_m": float(np.mean(distances)),
        "mean_laps": float(np.mean(laps)),
        "left_lane_rate": left / episodes,
        "crash_rate": crashed / episodes,
        "mean_episode_steps": float(np.mean(lengths)),
        "episode_time_limit_s": env.duration_s,
    }


def main() -> None:
    parser = Parser(description=__doc__.splitlines()[0])
    parser.add_argument("--scenario", choices=list(SETUPS), default="follow-line")
    parser.add_argument("--seeds", type=wholes(), default="0,1,2")
    parser.add_argument("--steps", type=whole(), default=20_000)
    parser.add_argument("--eval-episodes", type=whole(), default=5)
    args = parser.parse_args()
    torch.set_num_threads(1)
    setup = SETUPS[args.scenario]
    rows = []
    for seed in args.seeds:
        env = DriveEnv(args.scenario, traffic=TRAFFIC[args.scenario], backend=BACKEND[args.scenario], **setup)
        env.reset(seed=seed)
        agent = QLearning(env, seed)
        started = time.perf_counter()
        agent.learn(args.steps)
        train_s = time.perf_counter() - started
        returns = np.asarray(agent.episode_returns)
        plot_qlearning(
            agent.epsilon_history(), agent.episode_returns, agent.episode_lengths,
            RESULTS / f"qlearning_{args.scenario}_s{seed}.png",
            title=f"Q-learning on {args.scenario}, seed {seed}",
        )  # fmt: skip
        eval_env = DriveEnv(
            args.scenario, traffic=TRAFFIC[args.scenario], backend=BACKEND[args.scenario], **setup
        )
        evaluation = evaluate(agent, eval_env, args.eval_episodes, seed + EVAL_SEED_OFFSET)
        row = {
            "seed": seed,
            "train_steps": args.steps,
            "train_wall_s": train_s,
            "episodes": len(returns),
            "final_epsilon": agent.epsilon,
            "first20_mean_return": float(returns[:WINDOW].mean()),
            "last10pct_mean_return": float(returns[-max(len(returns) // 10, WINDOW) :].mean()),
            "convergence_episode": convergence_episode(returns),
            "states_visited": int(np.count_nonzero(np.any(agent.q_table != 0, axis=1))),
            "n_states": int(agent.q_table.shape[0]),
            "greedy": evaluation,
        }
        rows.append(row)
        print(json.dumps(row), flush=True)
    result = {
        "command": "python " + " ".join(sys.argv),
        "machine": f"{cpu_isa()}, {os.cpu_count()} cores (shared), "
        f"Python {platform.python_version()}",
        "date": time.strftime("%Y-%m-%d"),
        "scenario": args.scenario,
        **setup,
        "rows": rows,
    }
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / f"qlearning_{args.scenario}.json").write_text(json.dumps(result, indent=2))
    lines = [
        f"# Tabular Q-learning on {args.scenario} (seed 004)",
        "",
        f"Command: `{result['command']}`  ",
        f"Machine: {result['machine']}; date {result['date']}. Observation `{setup['obs']}`, actions "
        f"`{setup['action']}`, reward `{setup['reward']}`; α 0.8, γ 0.9, ε0 0.9999, ε × 0.9998 per step.",
        "",
        "Convergence: first episode at which the 20-episode mean return gets 90 % of the way from the "
        "first 20 episodes' mean to the final plateau (mean of the last 10 % of episodes).",
        "",
        "| seed | episodes | convergence episode | first-20 mean return | final mean return | greedy: "
        "mean abs lateral error (m) | distance (m) | laps | left lane | crashed | wall time |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
        *[
            f"| {r['seed']} | {r['episodes']} | {r['convergence_episode']} | "
            f"{r['first20_mean_return']:.0f} | "
            f"{r['last10pct_mean_return']:.0f} | {r['greedy']['mean_abs_lateral_error_m']:.2f} | "
            f"{r['greedy']['mean_distance_m']:.0f} | {r['greedy']['mean_laps']:.2f} | "
            f"{r['greedy']['left_lane_rate']:.0%} | {r['greedy']['crash_rate']:.0%} | "
            f"{r['train_wall_s'] / 60:.1f} min |"
            for r in rows
        ],
        "",
        f"Greedy evaluation: {args.eval_episodes} fresh episodes per seed "
        f"({rows[0]['greedy']['episode_time_limit_s']:.0f} s limit, random start on the circuit; distance "
        "driven until the limit or leaving the lane); plots: `qlearning_"
        f"{args.scenario}_s<seed>.png` (ε per step, return per episode, steps per episode).",
        "",
    ]
    (RESULTS / f"qlearning_{args.scenario}.md").write_text("\n".join(lines))
    print("\n".join(lines))


if __name__ == "__main__":
    main()
