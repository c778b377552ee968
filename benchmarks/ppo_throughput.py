"""PPO training throughput on K batched highway worlds, and where its time goes.

    OMP_NUM_THREADS=1 NUMBA_NUM_THREADS=1 .venv/bin/python benchmarks/ppo_throughput.py \
        [--n-envs 64 8] [--timesteps 32768] [--repeats 3]

SB3 PPO (MlpPolicy, highway-env's documented PPO settings scaled so one rollout is 2,048 steps
whatever K is: ``n_steps = 2048 / K``, batch 64, 10 epochs) on highway kinematics, one
``VectorDriveEnv`` of K worlds behind ``SB3VecEnv``. Training env-steps/s over ``--timesteps``;
the time split into the environment (``step_wait``), the rest of the rollout (policy forward,
buffer, callbacks) and the update (``train``). Repeats interleave the K values; medians.
"""

from __future__ import annotations

import json
import os
import platform
import statistics
import sys
import time
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("NUMBA_NUM_THREADS", "1")

import torch  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from provenance import Parser, command_line, cpu_isa, whole  # noqa: E402

RESULTS = Path(__file__).parent / "results"
ROLLOUT_STEPS = 2048


def measure(n_envs: int, timesteps: int, seed: int) -> dict:
    from stable_baselines3 import PPO

    from drivelab.agents.sb3_env import SB3VecEnv
    from drivelab.envs.vector import VectorDriveEnv

    torch.set_num_threads(1)
    venv = SB3VecEnv(VectorDriveEnv(n_envs, scenario="highway", obs="kinematics", autoreset_mode="same_step"))
    model = PPO(
        "MlpPolicy", venv, n_steps=max(ROLLOUT_STEPS // n_envs, 1), batch_size=64, n_epochs=10,
        learning_rate=5e-4, gamma=0.8, seed=seed, device="cpu", verbose=0,
    )  # fmt: skip
    clocks = {"env_s": 0.0, "rollout_s": 0.0, "update_s": 0.0}

    def timed(function, key):
        def wrapper(*args, **kwargs):
            start = time.perf_counter()
            try:
                return function(*args, **kwargs)
            finally:
                clocks[key] += time.perf_counter() - start

        return wrapper

    venv.step_wait = timed(venv.step_wait, "env_s")
    model.collect_rollouts = timed(model.collect_rollouts, "rollout_s")
    model.train = timed(model.train, "update_s")
    start = time.perf_counter()
    model.learn(timesteps)
    total = time.perf_counter() - start
    venv.close()
    return {
        "n_envs": n_envs,
        "steps_per_s": model.num_timesteps / total,
        "env_share": clocks["env_s"] / total,
        "policy_and_buffer_share": (clocks["rollout_s"] - clocks["env_s"]) / total,
        "update_share": clocks["update_s"] / total,
    }


def main() -> None:
    parser = Parser(description=__doc__.splitlines()[0])
    parser.add_argument("--n-envs", type=whole(), nargs="+", default=[64, 8])
    parser.add_argument("--timesteps", type=whole(), default=32768)
    parser.add_argument("--repeats", type=whole(), default=3)
    args = parser.parse_args()
    runs: dict[int, list[dict]] = {k: [] for k in args.n_envs}
    for repeat in range(args.repeats):
        for k in args.n_envs:
            runs[k].append(measure(k, args.timesteps, repeat))
            print(runs[k][-1])
    rows = [{key: statistics.median(r[key] for r in runs[k]) for key in runs[k][0]} for k in args.n_envs]
    result = {
        "command": command_line(),
        "machine": f"{cpu_isa()}, {os.cpu_count()} cores, "
        f"Python {platform.python_version()}, torch {torch.__version__}",
        "date": time.strftime("%Y-%m-%d"),
        "repeats": args.repeats,
        "rows": rows,
    }
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / "ppo_throughput.json").write_text(json.dumps(result, indent=2))
    lines = [
        "# PPO training throughput on batched highway worlds",
        "",
        f"Command: `{result['command']}`  ",
        f"Machine: {result['machine']}; date {result['date']}; {args.repeats} interleaved repeats (medians).",
        "",
        f"SB3 PPO, MlpPolicy, highway kinematics, {args.timesteps} steps per run, rollouts of",
        f"{ROLLOUT_STEPS} steps (n_steps = 2048 / K), batch 64, 10 epochs, one torch and one numba thread.",
        "",
        "| K worlds | training env-steps/s | environment | policy forward + buffer | update |",
        "|---|---|---|---|---|",
        *[
            f"| {r['n_envs']:.0f} | {r['steps_per_s']:.0f} | {r['env_share']:.0%} | "
            f"{r['policy_and_buffer_share']:.0%} | {r['update_share']:.0%} |"
            for r in rows
        ],
        "",
    ]
    (RESULTS / "ppo_throughput.md").write_text("\n".join(lines))
    print("\n".join(lines))


if __name__ == "__main__":
    main()
