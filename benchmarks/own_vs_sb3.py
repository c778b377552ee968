"""Our agents against their stable-baselines3 counterparts: same scenario, observation, reward, budget.

    .venv/bin/python benchmarks/own_vs_sb3.py [--pairs ddqn,a2c,ppo_cnn,ppo_fusion] [--seeds 0,1,2]
        [--steps ddqn=3000,a2c=4000,ppo_cnn=4000,ppo_fusion=4000] [--episodes 10]

Every run is a normal drivelab run directory (``benchmarks/runs/``) trained by
``drivelab.training.run.train`` on highway (fast backend, regular traffic, ``highway`` reward),
then evaluated with ``evaluate_run`` on ``--episodes`` held-out episodes. Per seed and pair the
two algorithms run one after the other in this process, torch on one thread, so their
steps/s ratio is measured under the same load. Writes ``results/own_vs_sb3.{json,md}`` and one
learning-curve plot per pair (training episode returns, mean over seeds with a min-max band).
"""

from __future__ import annotations

import csv
import json
import os
import platform
import shutil
import sys
import time
from pathlib import Path

os.environ.setdefault("PYGAME_HIDE_SUPPORT_PROMPT", "1")

import matplotlib  # noqa: E402

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import torch  # noqa: E402

from drivelab.config import build_config  # noqa: E402
from drivelab.training.evaluate import evaluate_run  # noqa: E402
from drivelab.training.run import train  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from provenance import Parser, cpu_isa, names, step_overrides, whole, wholes  # noqa: E402

RESULTS = Path(__file__).parent / "results"
RUNS = Path(__file__).parent / "runs"

# pair → (observation, action, [(algo, hyperparams), (algo, hyperparams)]): ours first, SB3 second.
# Shared settings are spelled out on both sides so that the comparison is one to one.
PAIRS: dict[str, tuple[str, str, list[tuple[str, dict]]]] = {
    "ddqn": (
        "lidar:stack=3,ego_state:features=10:stack=3",  # 750 inputs, as the seed
        "grid",
        [("dueling_ddqn", {}), ("dqn", {})],  # both: drivelab's DQN defaults (replay, ε, γ 0.8)
    ),
    "a2c": (
        "topdown",
        "continuous",
        [
            ("a2c_own", {"n_steps": 16, "entropy_coef": 0.01}),
            ("a2c", {"n_steps": 16, "ent_coef": 0.01, "features_extractor": "seed"}),
        ],
    ),
    "ppo_cnn": (
        "topdown",
        "continuous",
        [("ppo_own", {}), ("ppo", {"features_extractor": "seed"})],
    ),
    "ppo_fusion": (
        "topdown,ego_state,lidar:beams=120",
        "continuous",
        [("ppo_own", {}), ("ppo", {"features_extractor": "seed"})],
    ),
}
METRICS = ("steps_per_s", "mean_return", "crash_rate", "mean_speed_mps", "mean_length")
DEFAULT_STEPS = {"ddqn": 3000, "a2c": 4000, "ppo_cnn": 4000, "ppo_fusion": 4000}


def run_one(pair: str, algo: str, hyperparams: dict, seed: int, steps: int, episodes: int) -> dict:
    """Train and evaluate one (algorithm, seed); the row of the results table."""
    observation, action, _ = PAIRS[pair]
    name = f"{pair}-{algo}-s{seed}"
    shutil.rmtree(RUNS / name, ignore_errors=True)
    config = build_config(
        {
            "algo": algo, "env": "highway", "obs": observation, "action": action, "reward": "highway",
            "traffic": "regular", "backend": "fast", "steps": steps, "seed": seed, "name": name,
            "eval_every": steps, "eval_episodes": 1, "checkpoint_every": steps, "hyperparams": hyperparams,
        }
    )  # fmt: skip
    start = time.perf_counter()
    run_dir = train(config, RUNS)
    train_s = time.perf_counter() - start
    report = evaluate_run(run_dir, episodes=episodes)
    with (run_dir / "monitor.csv").open() as handle:
        rows = list(csv.DictReader(line for line in handle if not line.startswith("#")))
    return {
        "pair": pair,
        "algo": algo,
        "seed": seed,
        "steps": steps,
        "train_wall_s": train_s,
        "steps_per_s": steps / train_s,
        "eval_episodes": episodes,
        "mean_return": report["mean_return"],
        "std_return": report["std_return"],
        "crash_rate": report["crash_rate"],
        "mean_speed_mps": report["mean_speed_mps"],
        "mean_length": report["mean_length"],
        "mean_distance_km": report["mean_distance_km"],
        "training_returns": [float(r["r"]) for r in rows],
        "training_lengths": [int(r["l"]) for r in rows],
    }


def binned_curve(row: dict, steps: int, bins: int) -> np.ndarray:
    """Mean training return of the episodes that ended in each of ``bins`` equal step ranges."""
    ends = np.cumsum(row["training_lengths"])
    returns = np.array(row["training_returns"])
    edges = np.linspace(0, steps, bins + 1)
    curve = np.full(bins, np.nan)
    for i in range(bins):
        inside = (ends > edges[i]) & (ends <= edges[i + 1])
        if inside.any():
            curve[i] = returns[inside].mean()
    return curve


def plot_pair(pair: str, rows: list[dict], path: Path, bins: int = 10) -> None:
    """Learning curves of the pair's two algorithms: mean over seeds, min-max band."""
    fig, ax = plt.subplots(figsize=(7, 4), dpi=100)
    for algo, color in zip(dict.fromkeys(r["algo"] for r in rows), ("tab:blue", "tab:orange"), strict=False):
        mine = [r for r in rows if r["algo"] == algo]
        steps = mine[0]["steps"]
        curves = np.array([binned_curve(r, steps, bins) for r in mine])
        centres = (np.arange(bins) + 0.5) * steps / bins
        with np.errstate(all="ignore"):
            mean, low, high = np.nanmean(curves, 0), np.nanmin(curves, 0), np.nanmax(curves, 0)
        ax.plot(centres, mean, "o-", color=color, label=f"{algo} ({len(mine)} seeds)")
        ax.fill_between(centres, low, high, color=color, alpha=0.2)
    ax.set_xlabel("environment steps")
    ax.set_ylabel("training episode return")
    ax.set_title(f"{pair}: {PAIRS[pair][0]}, {PAIRS[pair][1]} actions, highway")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def summary_rows(rows: list[dict]) -> list[dict]:
    """Per (pair, algo): medians over seeds; per pair: median steps/s ratio ours / SB3."""
    table = []
    for pair in dict.fromkeys(r["pair"] for r in rows):
        algos = list(dict.fromkeys(r["algo"] for r in rows if r["pair"] == pair))
        for algo in algos:
            mine = [r for r in rows if r["pair"] == pair and r["algo"] == algo]
            table.append(
                {
                    "pair": pair,
                    "algo": algo,
                    "seeds": [r["seed"] for r in mine],
                    "steps": mine[0]["steps"],
                    **{f"median_{key}": float(np.median([r[key] for r in mine])) for key in METRICS},
                }
            )
        if len(algos) == 2:
            by_seed = {}
            for r in rows:
                if r["pair"] == pair:
                    by_seed.setdefault(r["seed"], {})[r["algo"]] = r["steps_per_s"]
            ratios = [v[algos[0]] / v[algos[1]] for v in by_seed.values() if len(v) == 2]
            table[-2]["median_speed_ratio_own_over_sb3"] = float(np.median(ratios)) if ratios else None
    return table


def write_markdown(result: dict, path: Path) -> None:
    lines = [
        "# Our agents against stable-baselines3 (highway, fast backend, regular traffic, `highway` reward)",
        "",
        f"Command: `{result['command']}`  ",
        f"Machine: {result['machine']}; date {result['date']}; torch on 1 thread; "
        f"evaluation: {result['episodes']} held-out episodes per run.",
        "",
        "Budgets are tiny (a few thousand steps on a shared 2-core machine): these numbers compare",
        "speed and early learning, not final competence.",
        "",
        "| pair | algorithm | seeds | steps | steps/s (median) | ours/SB3 steps/s (median per-seed ratio) "
        "| eval return "
        "(median) | crash rate (median) | speed m/s (median) | episode length (median) |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for row in result["summary"]:
        ratio = row.get("median_speed_ratio_own_over_sb3")
        lines.append(
            f"| {row['pair']} | {row['algo']} | {','.join(map(str, row['seeds']))} | {row['steps']} "
            f"| {row['median_steps_per_s']:.1f} | {'' if ratio is None else f'{ratio:.2f}x'} "
            f"| {row['median_mean_return']:.2f} | {row['median_crash_rate']:.2f} "
            f"| {row['median_mean_speed_mps']:.1f} | {row['median_mean_length']:.1f} |"
        )
    lines += [
        "",
        "Steps/s is the whole run's wall clock (environment, agent, checkpoints, one evaluation episode)",
        "over its steps. Resets cost more than steps, so a policy with shorter training episodes runs",
        "slower on the same code: compare it with the training episode length below.",
        "",
        "Per run:",
        "",
        "| pair | algorithm | seed | steps/s | training episodes | mean training episode length "
        "| eval return ± std | crash rate |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for r in result["runs"]:
        lengths = r["training_lengths"]
        lines.append(
            f"| {r['pair']} | {r['algo']} | {r['seed']} | {r['steps_per_s']:.1f} | {len(lengths)} "
            f"| {np.mean(lengths) if lengths else float('nan'):.1f} "
            f"| {r['mean_return']:.2f} ± {r['std_return']:.2f} | {r['crash_rate']:.2f} |"
        )
    lines += ["", "Learning curves: " + ", ".join(f"`own_vs_sb3_{p}.png`" for p in result["pairs"]), ""]
    path.write_text("\n".join(lines))


def main() -> None:
    parser = Parser(description=__doc__.splitlines()[0])
    parser.add_argument("--pairs", type=names(PAIRS), default=",".join(PAIRS))
    parser.add_argument("--seeds", type=wholes(), default="0,1,2")
    parser.add_argument(
        "--steps", type=step_overrides(PAIRS), default="", help="pair=steps overrides, comma separated"
    )
    parser.add_argument("--episodes", type=whole(), default=10)
    parser.add_argument("--tag", default="own_vs_sb3", help="results file name")
    parser.add_argument("--report", action="store_true", help="only rewrite Markdown and plots from the JSON")
    args = parser.parse_args()
    if args.report:
        result = json.loads((RESULTS / f"{args.tag}.json").read_text())
        result["summary"] = summary_rows(result["runs"])
        (RESULTS / f"{args.tag}.json").write_text(json.dumps(result, indent=1))
        write_markdown(result, RESULTS / f"{args.tag}.md")
        for pair in dict.fromkeys(r["pair"] for r in result["runs"]):
            rows = [r for r in result["runs"] if r["pair"] == pair]
            plot_pair(pair, rows, RESULTS / f"{args.tag}_{pair}.png")
        return
    torch.set_num_threads(1)
    steps = {**DEFAULT_STEPS, **args.steps}
    pairs, seeds = args.pairs, args.seeds
    RESULTS.mkdir(exist_ok=True)
    runs: list[dict] = []
    result = {
        "command": "python " + " ".join(sys.argv),
        "machine": f"{cpu_isa()}, {os.cpu_count()} cores (shared), "
        f"Python {platform.python_version()}",
        "date": time.strftime("%Y-%m-%d"),
        "episodes": args.episodes,
        "pairs": pairs,
    }
    for seed in seeds:  # seeds outermost: an interrupted benchmark still has every pair
        for pair in pairs:
            for algo, hyperparams in PAIRS[pair][2]:
                row = run_one(pair, algo, hyperparams, seed, steps[pair], args.episodes)
                runs.append(row)
                print({k: v for k, v in row.items() if not k.startswith("training_")}, flush=True)
                # results so far are written after every run, so an interrupted benchmark keeps them
                result.update(runs=runs, summary=summary_rows(runs))
                (RESULTS / f"{args.tag}.json").write_text(json.dumps(result, indent=1))
                write_markdown(result, RESULTS / f"{args.tag}.md")
            plot_pair(pair, [r for r in runs if r["pair"] == pair], RESULTS / f"{args.tag}_{pair}.png")


if __name__ == "__main__":
    main()
