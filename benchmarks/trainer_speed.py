"""Training speed of drivelab's on-policy trainer against the environment alone and SB3 PPO.

    .venv/bin/python benchmarks/trainer_speed.py [--repeats 3] [--threads 1 2]

K = 64 worlds of one ``VectorDriveEnv`` (``autoreset_mode="same_step"``). Per observation case:

- **environment alone**: random actions, stepped as arrays (what the trainer reads);
- **ppo_own**: drivelab's PPO on the worlds' arrays (``agents/onpolicy.py``), with the same
  hyper-parameters as SB3, and with one 64×64 encoder shared by actor and critic (MLP cases);
  on highway also with the recipe of the leaderboard's merge and roundabout rows (64 worlds,
  rollouts of 32 steps, minibatch 256, 10 epochs, learning rate 5e-4, one 64×64 encoder);
- **SB3 PPO, same hyper-parameters and nets**: the same rollout, minibatch, epochs, learning
  rate, discount and network (``MlpPolicy`` with separate 64×64 actor and critic, which ppo_own
  gets with ``shared_encoder=false``; seed 003's CNN as SB3 features extractor for pixels),
  through ``SB3VecEnv``;
- **SB3 PPO, the leaderboard's highway recipe** (highway only): n_steps 256, batch 64, 10 epochs,
  256×256 actor and critic; and **ppo_own with those values and nets** (separate 256×256 actor and
  critic), the other regime of equal hyper-parameters: minibatches of 64, so that the update's
  small matrix products, not the simulator, take most of the time.

Rates are training env-steps/s over whole rollouts after a warm-up rollout (numba compiled, torch
warmed); every repeat runs every row once, interleaved, and the table gives medians. ``--threads``
sets torch's and numba's thread counts together (the simulator's kernels run in parallel over
worlds, the update's matrix products over rows).
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

sys.path.insert(0, str(Path(__file__).resolve().parent))
from provenance import Parser, command_line, cpu_isa, whole  # noqa: E402

RESULTS = Path(__file__).parent / "results"
K = 64
CASES = {  # name: (scenario, obs, action, rollout steps per world, rollouts timed, minibatch, note)
    "highway, kinematics (MLP)": ("highway", "kinematics", "meta", 128, 3, 2048),
    "town, privileged (MLP)": ("town", "waypoints,measurements,affordances", "target_speed", 128, 3, 2048),
    "block maps, LiDAR (MLP)": ("blocks", "lidar", "continuous", 128, 3, 2048),
    "highway, topdown 84×84 (CNN)": ("highway", "topdown", "meta", 16, 2, 256),
}
SHARED = {"learning_rate": 3e-4, "gamma": 0.99, "gae_lambda": 0.95, "n_epochs": 4, "clip_range": 0.2}
JUNCTION_RECIPE = {"n_steps": 32, "batch_size": 256, "n_epochs": 10, "learning_rate": 5e-4, "gamma": 0.8}
LEADERBOARD = {"n_steps": 256, "batch_size": 64, "n_epochs": 10, "learning_rate": 5e-4, "gamma": 0.8,
               "gae_lambda": 0.95, "clip_range": 0.2, "net_arch": [256, 256]}  # fmt: skip
OWN_LEADERBOARD = {**LEADERBOARD, "net_arch": "256,256", "shared_encoder": False}  # the same nets, ppo_own's


def make_env(scenario: str, obs: str, action: str):
    from drivelab.envs.vector import VectorDriveEnv

    env = VectorDriveEnv(K, scenario, obs=obs, action=action, autoreset_mode="same_step", backend="fast")
    env.reset(seed=0)
    return env


def env_alone(case: tuple, steps: int) -> float:
    scenario, obs, action = case[:3]
    env = make_env(scenario, obs, action)
    env.action_space.seed(0)
    actions = [env.action_space.sample() for _ in range(64)]
    for t in range(16):  # warm-up
        env.step(actions[t % 64])
    start = time.perf_counter()
    for t in range(steps):
        env.step(actions[t % 64])
    return steps * K / (time.perf_counter() - start)


def own(case: tuple, equal: bool, recipe: dict | None = None) -> float:
    from drivelab.agents.ppo import OwnPPO

    scenario, obs, action, n_steps, rollouts, batch = case
    env = make_env(scenario, obs, action)
    hyperparams = {**SHARED, "n_steps": n_steps, "batch_size": batch, "shared_encoder": not equal}
    if "topdown" in obs:
        hyperparams["shared_encoder"] = True  # SB3's CNN policy shares its extractor too
    if recipe is not None:
        hyperparams = dict(recipe)
        n_steps, rollouts = recipe["n_steps"], rollouts * case[3] // recipe["n_steps"]  # as many steps
    agent = OwnPPO(env.single_observation_space, env.single_action_space, 0, hyperparams, env)
    agent.learn(n_steps * K)  # warm-up rollout
    start = time.perf_counter()
    agent.learn(rollouts * n_steps * K, reset_num_timesteps=False)
    return rollouts * n_steps * K / (time.perf_counter() - start)


def sb3(case: tuple, hyperparams: dict, rollouts: int) -> float:
    from stable_baselines3 import PPO

    from drivelab.agents.networks import SeedCnnExtractor
    from drivelab.agents.sb3_env import SB3VecEnv

    scenario, obs, action = case[:3]
    venv = SB3VecEnv(make_env(scenario, obs, action))
    hyperparams = dict(hyperparams)
    arch = hyperparams.pop("net_arch", [64, 64])
    if "topdown" in obs:
        policy, kwargs = "CnnPolicy", {"features_extractor_class": SeedCnnExtractor, "net_arch": []}
    else:
        policy = "MultiInputPolicy" if "," in obs else "MlpPolicy"
        kwargs = {"net_arch": {"pi": arch, "vf": arch}}
    model = PPO(policy, venv, seed=0, device="cpu", verbose=0, policy_kwargs=kwargs, **hyperparams)
    n_steps = hyperparams["n_steps"]
    model.learn(n_steps * K)  # warm-up rollout
    start = time.perf_counter()
    model.learn(rollouts * n_steps * K, reset_num_timesteps=False)
    return rollouts * n_steps * K / (time.perf_counter() - start)


def measure(case: tuple, leaderboard: bool) -> dict:
    n_steps, rollouts, batch = case[3:6]
    row = {
        "env_alone": env_alone(case, 200 if "topdown" not in case[1] else 40),
        "own_equal": own(case, equal=True),
        "own_default": own(case, equal=False) if "topdown" not in case[1] else None,
        "sb3_equal": sb3(case, {**SHARED, "n_steps": n_steps, "batch_size": batch}, rollouts),
    }
    if leaderboard:
        row["own_recipe"] = own(case, equal=False, recipe=JUNCTION_RECIPE)
        row["sb3_leaderboard"] = sb3(case, LEADERBOARD, 1)
        row["own_leaderboard"] = own(case, equal=True, recipe=OWN_LEADERBOARD)
    return row


def set_threads(threads: int) -> None:
    import numba
    import torch

    torch.set_num_threads(threads)
    numba.set_num_threads(threads)


def main() -> None:
    parser = Parser(description=__doc__.splitlines()[0])
    parser.add_argument("--report-only", action="store_true", help="write the table again from the JSON")
    parser.add_argument("--repeats", type=whole(), default=3)
    parser.add_argument("--threads", type=whole(), nargs="+", default=[1, 2])
    parser.add_argument("--cases", nargs="+", choices=list(CASES), default=list(CASES))
    args = parser.parse_args()
    if args.report_only:
        result = json.loads((RESULTS / "trainer_speed.json").read_text())
        (RESULTS / "trainer_speed.md").write_text(report(result))
        return
    import numba
    import torch

    if max(args.threads) > numba.config.NUMBA_NUM_THREADS:
        raise SystemExit(f"error: NUMBA_NUM_THREADS is {numba.config.NUMBA_NUM_THREADS}, below --threads")
    runs: dict[tuple[str, int], list[dict]] = {}
    for repeat in range(args.repeats):
        for threads in args.threads:
            set_threads(threads)
            for name in args.cases:
                row = measure(CASES[name], leaderboard=name.startswith("highway, kin") and threads == 1)
                runs.setdefault((name, threads), []).append(row)
                print(repeat, threads, name, {k: None if v is None else round(v) for k, v in row.items()})
    rows = []
    for (name, threads), repeats in runs.items():
        medians = {
            key: (None if repeats[0][key] is None else statistics.median(r[key] for r in repeats))
            for key in repeats[0]
        }
        rows.append({"case": name, "threads": threads, **medians})
    result = {
        "command": command_line(),
        "machine": f"{cpu_isa()}, {os.cpu_count()} cores, Python {platform.python_version()}, "
        f"torch {torch.__version__}",
        "date": time.strftime("%Y-%m-%d"),
        "repeats": args.repeats,
        "worlds": K,
        "cases": {name: dict(zip(("scenario", "obs", "action", "n_steps", "rollouts", "batch_size"), case,
                                 strict=True)) for name, case in CASES.items() if name in args.cases},
        "shared_hyperparams": SHARED,
        "leaderboard_recipe": LEADERBOARD,
        "own_leaderboard_recipe": OWN_LEADERBOARD,
        "junction_recipe": JUNCTION_RECIPE,
        "rows": rows,
    }  # fmt: skip
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / "trainer_speed.json").write_text(json.dumps(result, indent=2))
    (RESULTS / "trainer_speed.md").write_text(report(result))
    print(report(result))


def report(result: dict) -> str:
    def rate(value) -> str:
        return "—" if value is None else f"{value:,.0f}"

    def ratio(a, b) -> str:
        return "—" if a is None or b is None else f"{a / b:.1f}×"

    lines = [
        "# Training speed: drivelab's on-policy trainer, the environment alone, SB3 PPO",
        "",
        f"Command: `{result['command']}`  ",
        f"Machine: {result['machine']}; date {result['date']}; {result['repeats']} interleaved repeats "
        "(medians).",
        "",
        f"K = {result['worlds']} worlds of one VectorDriveEnv. Training env-steps/s over whole rollouts "
        "after a warm-up rollout. Same hyper-parameters for ppo_own and SB3 PPO: "
        + ", ".join(f"{k} {v}" for k, v in result["shared_hyperparams"].items())
        + ", rollout and minibatch per case below; MLP: separate 64×64 actor and critic (ppo_own "
        "`shared_encoder=false`); CNN: seed 003's encoder shared, linear heads. \"ppo_own shared\": "
        "the same with one 64×64 encoder for actor and critic. SB3's leaderboard recipe for highway: "
        + ", ".join(f"{k} {v}" for k, v in result["leaderboard_recipe"].items())
        + "; ppo_own's junction recipe (the leaderboard's merge and roundabout rows), one 64×64 encoder: "
        + ", ".join(f"{k} {v}" for k, v in result["junction_recipe"].items())
        + "; \"ppo_own, SB3's leaderboard values\": ppo_own with those values and separate 256×256 "
        "actor and critic"
        + ". ppo_own's highway recipe (the leaderboard's highway ppo_own row) is \"ppo_own shared\"'s "
        "configuration (rollouts of 128 steps, minibatch 2048, 4 epochs, one 64×64 encoder; its learning "
        "rate and discount do not change the speed). Threads: torch's and numba's.",
        "",
        "| case | threads | rollout (n_steps × K) / minibatch | environment alone | ppo_own, same hp | "
        "ppo_own shared | SB3 PPO, same hp | ppo_own / environment | ppo_own shared / environment | "
        "ppo_own / SB3 same hp | ppo_own junction recipe | SB3 PPO leaderboard recipe | "
        "ppo_own highway recipe / SB3 leaderboard recipe | junction recipe / SB3 leaderboard recipe | "
        "ppo_own, SB3's leaderboard values | ppo_own / SB3, both at the leaderboard values |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for row in result["rows"]:
        case = result["cases"][row["case"]]
        lines.append(
            f"| {row['case']} | {row['threads']} | {case['n_steps']} × {result['worlds']} / "
            f"{case['batch_size']} | {rate(row['env_alone'])} | {rate(row['own_equal'])} | "
            f"{rate(row['own_default'])} | {rate(row['sb3_equal'])} | "
            f"{row['own_equal'] / row['env_alone']:.0%} | "
            + ("—" if row["own_default"] is None else f"{row['own_default'] / row['env_alone']:.0%}")
            + f" | {ratio(row['own_equal'], row['sb3_equal'])} | {rate(row.get('own_recipe'))} | "
            f"{rate(row.get('sb3_leaderboard'))} | {ratio(row['own_default'], row.get('sb3_leaderboard'))} | "
            f"{ratio(row.get('own_recipe'), row.get('sb3_leaderboard'))} | "
            f"{rate(row.get('own_leaderboard'))} | "
            f"{ratio(row.get('own_leaderboard'), row.get('sb3_leaderboard'))} |"
        )
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    main()
