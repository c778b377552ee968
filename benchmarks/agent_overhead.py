"""Agent cost per training step, ours against SB3, without the driving simulation.

    .venv/bin/python benchmarks/agent_overhead.py [--steps 1024] [--repeats 3]

``own_vs_sb3.py`` times whole runs, where a policy that crashes early pays for more resets. Here
every agent trains on a stand-in environment with the same observation and action spaces as in
``own_vs_sb3.py`` (random observations drawn once, constant reward, episodes of 150 steps), so
the steps/s measure only acting and learning. Pair members alternate, torch on one thread;
the ratio is the median over repeats. Writes ``results/agent_overhead.{json,md}``.
"""

from __future__ import annotations

import json
import os
import platform
import sys
import time
from pathlib import Path

os.environ.setdefault("PYGAME_HIDE_SUPPORT_PROMPT", "1")

import gymnasium as gym  # noqa: E402
import numpy as np  # noqa: E402
import torch  # noqa: E402

sys.path.insert(0, str(Path(__file__).parent))
from own_vs_sb3 import PAIRS  # noqa: E402
from provenance import Parser, cpu_isa, whole  # noqa: E402

from drivelab.agents.registry import get_algo  # noqa: E402
from drivelab.envs.core import DriveEnv  # noqa: E402

RESULTS = Path(__file__).parent / "results"
WARM_UP_STEPS = 512  # a multiple of every pair's n_steps (16, 256), above DQN's learning_starts (200)


class StandIn(gym.Env):
    """Same spaces as a DriveEnv; cycles through 64 pre-drawn observations; 150-step episodes."""

    def __init__(self, observation_space: gym.Space, action_space: gym.Space) -> None:
        self.observation_space, self.action_space = observation_space, action_space
        self.observation_space.seed(0)
        self.pool = [self.observation_space.sample() for _ in range(64)]
        self.t = 0

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.t = 0
        return self.pool[0], {}

    def step(self, action):
        self.t += 1
        return self.pool[self.t % 64], 0.1, False, self.t >= 150, {}


def steps_per_s(algo: str, hyperparams: dict, env: gym.Env, steps: int) -> float:
    agent = get_algo(algo).build(algo, env, 0, dict(hyperparams), None)
    agent.learn(WARM_UP_STEPS)  # replay past learning_starts; whole rollouts (SB3 always collects n_steps)
    start = time.perf_counter()
    agent.learn(steps, reset_num_timesteps=False)
    return steps / (time.perf_counter() - start)


def main() -> None:
    parser = Parser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=whole(), default=1024, help="timed steps; keep a multiple of 256")
    parser.add_argument("--repeats", type=whole(), default=3)
    args = parser.parse_args()
    torch.set_num_threads(1)
    rows = []
    for pair, (observation, action, members) in PAIRS.items():
        real = DriveEnv("highway", obs=observation, action=action, backend="fast")
        env = StandIn(real.observation_space, real.action_space)
        speeds: dict[str, list[float]] = {algo: [] for algo, _ in members}
        for _ in range(args.repeats):
            for algo, hyperparams in members:
                speeds[algo].append(steps_per_s(algo, hyperparams, env, args.steps))
        (own, _), (sb3, _) = members
        ratios = [a / b for a, b in zip(speeds[own], speeds[sb3], strict=True)]
        row = {
            "pair": pair,
            "own": own,
            "sb3": sb3,
            "own_steps_per_s": speeds[own],
            "sb3_steps_per_s": speeds[sb3],
            "median_ratio_own_over_sb3": float(np.median(ratios)),
        }
        rows.append(row)
        print(row, flush=True)
    result = {
        "command": "python " + " ".join(sys.argv),
        "machine": f"{cpu_isa()}, {os.cpu_count()} cores (shared), "
        f"Python {platform.python_version()}",
        "date": time.strftime("%Y-%m-%d"),
        "steps": args.steps,
        "repeats": args.repeats,
        "rows": rows,
    }
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / "agent_overhead.json").write_text(json.dumps(result, indent=2))
    lines = [
        "# Agent cost per training step, without the simulation (stand-in environment)",
        "",
        f"Command: `{result['command']}`  ",
        f"Machine: {result['machine']}; date {result['date']}; torch on 1 thread; {args.steps} timed steps "
        f"after a warm-up, {args.repeats} repeats alternating ours and SB3.",
        "",
        "| pair | ours | SB3 | ours steps/s (median) | SB3 steps/s (median) | ours/SB3 (median ratio) |",
        "|---|---|---|---|---|---|",
    ]
    for row in rows:
        lines.append(
            f"| {row['pair']} | {row['own']} | {row['sb3']} | {np.median(row['own_steps_per_s']):.1f} "
            f"| {np.median(row['sb3_steps_per_s']):.1f} | {row['median_ratio_own_over_sb3']:.2f}x |"
        )
    (RESULTS / "agent_overhead.md").write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
