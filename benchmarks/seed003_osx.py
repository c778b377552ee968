"""Seed 003 reproduced on its map, MetaDrive's "OSX" (``--env blocks``): five agents × three seeds.

    nice -n 10 env OMP_NUM_THREADS=1 NUMBA_NUM_THREADS=1 python benchmarks/seed003_osx.py \
        [--agents sb3_dqn,dueling_ddqn,a2c_topdown,ppo_topdown,ppo_fusion] [--seeds 0,1,2] \
        [--steps sb3_dqn=6000,...] [--episodes 20] [--report]

Each run is trained by the ordinary CLI, ``python -m drivelab.cli train`` (a subprocess; its
command is kept in the results), into ``benchmarks/runs/seed003-<agent>-s<seed>`` (git-ignored),
with ``--config benchmarks/seed003_osx.yaml`` (map "OSX") and regular traffic (MetaDrive's
density 0.1). A re-run skips complete runs, resumes a run with a checkpoint and no final model
(``drivelab train --resume``) and re-evaluates only runs without ``seed003_eval.json``.

Evaluation: the final model, greedy, on the scenario's fixed evaluation episodes
(``evaluation_seeds``: the same episodes for every run, none a training episode), as
``drivelab evaluate`` plays them; beside the driving metrics it records, every step, the ego's
speed, front-wheel angle and whether it is in a junction or a curve, so that the seed's claims
about steering, curves and junctions can be checked. Writes ``results/seed003_osx.{json,md}``
and ``results/seed003_osx_curves.png`` (training-episode returns against steps).
"""

from __future__ import annotations

import csv
import json
import os
import platform
import resource
import shlex
import shutil
import subprocess
import sys
import time
from pathlib import Path

os.environ.setdefault("PYGAME_HIDE_SUPPORT_PROMPT", "1")

import matplotlib  # noqa: E402

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from provenance import Parser, cpu_isa, names, readable, step_overrides, whole, wholes  # noqa: E402

ROOT = Path(__file__).resolve().parent
RESULTS = ROOT / "results"
RUNS = ROOT / "runs"
MAP_CONFIG = ROOT / "seed003_osx.yaml"
STEER_THRESHOLD_RAD = np.radians(2.0)  # a front-wheel angle above 2° counts as steering

# agent → (what the seed says, CLI arguments). gamma 0.99 for every agent: MetaDrive decides every
# 0.1 s (10 Hz), where drivelab's defaults (0.8) are highway-env's 1 Hz discount.
AGENTS: dict[str, tuple[str, list[str]]] = {
    "sb3_dqn": (
        "SB3 DQN, discrete actions, vector input, the safety reward table",
        [
            "--algo", "dqn", "--obs", "lidar,ego_state:features=10", "--action", "grid",
            "--reward", "safety_dqn",
        ],
    ),
    "sb3_dqn_default": (
        "the same SB3 DQN with MetaDrive's default reward (the seed's \"default DQN\", before its table)",
        [
            "--algo", "dqn", "--obs", "lidar,ego_state:features=10", "--action", "grid",
            "--reward", "metadrive",
        ],
    ),
    "dueling_ddqn": (
        "Dueling Double DQN, prioritised replay, LiDAR 240 + 10 features × 3 frames = 750-D, 18 actions, "
        "the course reward",
        [
            "--algo", "dueling_ddqn", "--obs", "lidar:stack=3,ego_state:features=10:stack=3",
            "--action", "grid", "--reward", "metadrive_course",
        ],
    ),
    "a2c_topdown": (
        "A2C (own), CNN on the 5×84×84 top-down image, continuous (steer, throttle)",
        ["--algo", "a2c_own", "--obs", "topdown", "--action", "continuous", "--reward", "metadrive"],
    ),
    "ppo_topdown": (
        "PPO (own), CNN on the 5×84×84 top-down image, continuous",
        ["--algo", "ppo_own", "--obs", "topdown", "--action", "continuous", "--reward", "metadrive"],
    ),
    "ppo_fusion": (
        "PPO (own), fusion: top-down image + 5-D ego state + LiDAR 120, continuous",
        [
            "--algo", "ppo_own", "--obs", "topdown,ego_state,lidar:beams=120", "--action", "continuous",
            "--reward", "metadrive",
        ],
    ),
}  # fmt: skip
DEFAULT_STEPS = {
    "sb3_dqn": 5000,
    "sb3_dqn_default": 5000,
    "dueling_ddqn": 2500,
    "a2c_topdown": 5000,
    "ppo_topdown": 5000,
    "ppo_fusion": 5000,
}
COMMON = ["--env", "blocks", "--traffic", "regular", "--backend", "fast", "-H", "gamma=0.99"]
METRICS = (
    "success_rate", "crash_rate", "out_of_road_rate", "mean_speed_mps", "mean_return", "route_completion",
    "train_wall_s", "train_cpu_s",
)  # fmt: skip


def recipe(agent: str, steps: int) -> list[str]:
    """The ``drivelab train`` arguments of an agent's runs, without ``--seed``, ``--runs-dir`` and
    ``--name`` (also the leaderboard's "OSX" rows)."""
    return [
        *AGENTS[agent][1], *COMMON, "--config", str(MAP_CONFIG.relative_to(ROOT.parent)),
        "--steps", str(steps), "--eval-every", str(steps), "--eval-episodes", "1",
        "--checkpoint-every", str(max(steps // 3, 1)),
    ]  # fmt: skip


def train_command(agent: str, seed: int, steps: int) -> list[str]:
    """The ``drivelab train`` arguments of one run (after ``python -m drivelab.cli``)."""
    where = ["--seed", str(seed), "--runs-dir", str(RUNS.relative_to(ROOT.parent))]
    return ["train", *recipe(agent, steps), *where, "--name", f"seed003-{agent}-s{seed}"]


def _children_cpu_s() -> float:
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def train_run(agent: str, seed: int, steps: int) -> dict:
    """Train (or resume, or skip) one run; its ``seed003_train.json``: command, wall and CPU time."""
    run_dir = RUNS / f"seed003-{agent}-s{seed}"
    record = run_dir / "seed003_train.json"
    if (run_dir / "model.zip").is_file() and record.is_file():
        saved = json.loads(record.read_text())
        if saved["steps"] == steps:
            return saved
    arguments = train_command(agent, seed, steps)
    if (run_dir / "checkpoints" / "latest.zip").is_file() and not (run_dir / "model.zip").is_file():
        arguments = ["train", "--resume", str(run_dir.relative_to(ROOT.parent))]
    else:
        shutil.rmtree(run_dir, ignore_errors=True)
    command = [sys.executable, "-m", "drivelab.cli", *arguments]
    cpu_before, start = _children_cpu_s(), time.perf_counter()
    subprocess.run(command, cwd=ROOT.parent, check=True, stdout=subprocess.DEVNULL)
    wall, cpu = time.perf_counter() - start, _children_cpu_s() - cpu_before
    previous = (
        json.loads(record.read_text()) if record.is_file() else {"train_wall_s": 0.0, "train_cpu_s": 0.0}
    )
    saved = {
        "agent": agent,
        "seed": seed,
        "steps": steps,
        "command": "drivelab " + shlex.join(train_command(agent, seed, steps)),
        "train_wall_s": previous["train_wall_s"] + wall,  # a resumed run adds its parts
        "train_cpu_s": previous["train_cpu_s"] + cpu,
    }
    record.write_text(json.dumps(saved, indent=1))
    return saved


def evaluate(run_dir: Path, episodes: int) -> dict:
    """Play the final model on the fixed evaluation episodes; driving metrics and, per block of the
    map (``I`` spawn road, ``O`` roundabout, ``S`` straight, ``X`` intersection), the ego's speed,
    front-wheel angle and steps there, and the block where each failed episode ended."""
    from drivelab.envs.core import DriveEnv
    from drivelab.sim.core.lanes import closest_lane
    from drivelab.training.checkpoints import load_agent
    from drivelab.training.evaluate import aggregate, check_spaces, load_run_config, run_episodes

    path = run_dir / "seed003_eval.json"
    if path.is_file():
        saved = json.loads(path.read_text())
        if saved["episodes"] == episodes:
            return saved
    config = load_run_config(run_dir)
    env = DriveEnv(**config.eval_env_kwargs())
    agent = load_agent(run_dir, config)
    check_spaces(agent, env, run_dir)
    trace: dict[str, list] = {"block": [], "speed": [], "steer": []}
    ends: list[str] = []

    def block() -> str:
        """The letter of the block whose lane is closest to the ego (the map of world 0)."""
        bmap, ego = env.simulator.map_of(0), env.vector.batch.ego
        row = closest_lane(bmap.table.rows, *map(float, ego.position[0]), float(ego.heading[0]))
        return bmap.pg.letters[bmap.pg.lane_block[row]]

    def policy(obs):
        ego = env.vector.batch.ego
        trace["block"].append(block())
        trace["speed"].append(float(ego.speed_mps[0]))
        trace["steer"].append(abs(float(ego.steering[0])))
        return agent.predict(obs, deterministic=True)[0]

    def on_episode(metrics: dict) -> None:  # the terminal world is still the env's (one world)
        ends.append(block())

    results, _ = run_episodes(policy, env, episodes, on_episode=on_episode)
    blocks, speed, steer = np.array(trace["block"]), np.array(trace["speed"]), np.array(trace["steer"])
    letters = env.simulator.map_of(0).pg.letters
    failed = [e for e, r in zip(ends, results, strict=True) if not r["success"]]
    per_block = {}
    for letter in letters:
        here = blocks == letter
        per_block[letter] = {
            "steps": int(here.sum()),
            "speed_mps": float(speed[here].mean()) if here.any() else None,
            "steering_rad": float(steer[here].mean()) if here.any() else None,
            "failures_end_here": failed.count(letter),
        }
    saved = {
        **aggregate(results),
        "out_of_road_rate": float(np.mean([r["off_road_events"] > 0 for r in results])),
        "steering_share": float((steer > STEER_THRESHOLD_RAD).mean()),
        "blocks": per_block,
        "per_episode": results,
    }
    path.write_text(json.dumps(saved, indent=1))
    return saved


def training_curve(run_dir: Path) -> tuple[list[float], list[int]]:
    with (run_dir / "monitor.csv").open() as handle:
        rows = list(csv.DictReader(line for line in handle if not line.startswith("#")))
    return [float(r["r"]) for r in rows], [int(r["l"]) for r in rows]


def _stat(values: list) -> dict:
    """Mean and 90 % percentile-bootstrap interval over seeds (``drivelab.training.stats``) of the
    values that are not None."""
    from drivelab.training.stats import bootstrap_ci

    values = [v for v in values if v is not None]
    low, high = bootstrap_ci(values)
    return {"mean": float(np.mean(values)) if values else None, "low": low, "high": high, "n": len(values)}


def summarise(runs: list[dict]) -> list[dict]:
    """Per agent: mean and 90 % interval over seeds of every metric, and the per-block detail."""
    table = []
    for agent in dict.fromkeys(r["agent"] for r in runs):
        mine = [r for r in runs if r["agent"] == agent]
        row = {"agent": agent, "seeds": [r["seed"] for r in mine], "steps": mine[0]["steps"]}
        for key in METRICS + ("steering_share",):
            row[key] = _stat([r[key] for r in mine if r.get(key) is not None])
        letters = list(mine[0]["blocks"])
        row["blocks"] = {
            letter: {
                "speed_mps": _stat([r["blocks"][letter]["speed_mps"] for r in mine]),
                "steering_rad": _stat([r["blocks"][letter]["steering_rad"] for r in mine]),
                "steps": sum(r["blocks"][letter]["steps"] for r in mine),
                "failures_end_here": sum(r["blocks"][letter]["failures_end_here"] for r in mine),
            }
            for letter in letters
        }
        table.append(row)
    return table


def _cell(stat: dict, digits: int = 2) -> str:
    if stat["mean"] is None:
        return "n/a"
    if stat["n"] < 2 or not np.isfinite(stat["low"]):
        return f"{stat['mean']:.{digits}f}"
    return f"{stat['mean']:.{digits}f} [{stat['low']:.{digits}f}, {stat['high']:.{digits}f}]"


def plot_curves(result: dict, path: Path, bins: int = 10) -> None:
    """Training-episode return against steps: mean over seeds, min-max band (one panel per agent)."""
    agents = list(dict.fromkeys(r["agent"] for r in result["runs"]))
    fig, axes = plt.subplots(1, len(agents), figsize=(3.2 * len(agents), 3.0), dpi=100, squeeze=False)
    for ax, agent in zip(axes[0], agents, strict=True):
        mine = [r for r in result["runs"] if r["agent"] == agent]
        steps = mine[0]["steps"]
        edges = np.linspace(0, steps, bins + 1)
        curves = []
        for r in mine:
            ends, returns = np.cumsum(r["training_lengths"]), np.array(r["training_returns"])
            curve = np.full(bins, np.nan)
            for i in range(bins):
                inside = (ends > edges[i]) & (ends <= edges[i + 1])
                if inside.any():
                    curve[i] = returns[inside].mean()
            curves.append(curve)
        centres = (edges[:-1] + edges[1:]) / 2
        with np.errstate(all="ignore"):
            curves = np.array(curves)
            mean, low, high = np.nanmean(curves, 0), np.nanmin(curves, 0), np.nanmax(curves, 0)
        ax.plot(centres, mean, "o-", ms=3)
        ax.fill_between(centres, low, high, alpha=0.25)
        ax.set_title(f"{agent} ({len(mine)} seeds)", fontsize=9)
        ax.set_xlabel("steps", fontsize=8)
        ax.tick_params(labelsize=7)
        ax.grid(alpha=0.3)
    axes[0][0].set_ylabel("training episode return", fontsize=8)
    fig.suptitle('seed 003 on "OSX": training returns (each agent its own reward)', fontsize=9)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def write_markdown(result: dict, path: Path) -> None:
    lines = [
        '# Seed 003 on its map, MetaDrive\'s "OSX" (`--env blocks`, regular traffic, fast backend)',
        "",
        f"Command: `{result['command']}`  ",
        f"Machine: {result['machine']}; date {result['date']}; one thread per process, niced.  ",
        f"Evaluation: {result['episodes']} fixed evaluation episodes per run (greedy; the same "
        "episodes for every run). Intervals: 90 % percentile bootstrap of the mean over seeds "
        "(`drivelab.training.stats.bootstrap_ci`, as `drivelab compare`).",
        "",
        "| agent | seeds | steps | success | crash | out of road | mean speed m/s | return "
        "| route completion | train wall s | train CPU s |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for row in result["summary"]:
        lines.append(
            f"| {row['agent']} | {','.join(map(str, row['seeds']))} | {row['steps']} "
            f"| {_cell(row['success_rate'])} | {_cell(row['crash_rate'])} | {_cell(row['out_of_road_rate'])} "
            f"| {_cell(row['mean_speed_mps'], 1)} | {_cell(row['mean_return'], 1)} "
            f"| {_cell(row['route_completion'])} | {_cell(row['train_wall_s'], 0)} "
            f"| {_cell(row['train_cpu_s'], 0)} |"
        )
    lines += [
        "",
        "Returns are each agent's own reward (the table below) and are not comparable across agents.",
        "",
        "| agent | what (seed 003) | arguments |",
        "|---|---|---|",
    ]
    for agent in dict.fromkeys(r["agent"] for r in result["runs"]):
        lines.append(f"| {agent} | {AGENTS[agent][0]} | `{' '.join(AGENTS[agent][1])}` |")
    lines += [
        "",
        "Per block of the map (`I` spawn road, `O` roundabout, `S` straight, `X` intersection; the "
        "block of the lane closest to the ego), over all evaluation steps: mean ego speed (m/s) and "
        "mean front-wheel angle |δ| (rad), means over seeds; evaluation steps spent there and failed "
        "episodes that ended there, summed over seeds. Last column: share of steps steering more "
        "than 2°.",
        "",
    ]
    letters = list(result["summary"][0]["blocks"]) if result["summary"] else []
    header = " | ".join(f"{x}: speed / \\|δ\\| / steps / failures" for x in letters)
    lines += [f"| agent | {header} | steering > 2° |", "|---" * (len(letters) + 2) + "|"]
    for row in result["summary"]:
        cells = []
        for letter in letters:
            b = row["blocks"][letter]
            speed, steer = b["speed_mps"]["mean"], b["steering_rad"]["mean"]
            cells.append(
                f"{'–' if speed is None else f'{speed:.1f}'} / {'–' if steer is None else f'{steer:.3f}'} "
                f"/ {b['steps']} / {b['failures_end_here']}"
            )
        lines.append(f"| {row['agent']} | {' | '.join(cells)} | {_cell(row['steering_share'])} |")
    lines += [
        "",
        "Per run:",
        "",
        "| agent | seed | success | crash | out of road | speed | return | route completion "
        "| episode length | train wall s |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in result["runs"]:
        lines.append(
            f"| {r['agent']} | {r['seed']} | {r['success_rate']:.2f} | {r['crash_rate']:.2f} "
            f"| {r['out_of_road_rate']:.2f} | {r['mean_speed_mps']:.1f} | {r['mean_return']:.1f} "
            f"| {r['route_completion']:.2f} | {r['mean_length']:.0f} | {r['train_wall_s']:.0f} |"
        )
    lines += ["", "Training commands (from the repository root):", "", "```bash"]
    lines += [r["command"] for r in result["runs"]]
    lines += ["```", "", "Learning curves: `seed003_osx_curves.png` (training-episode returns).", ""]
    if result.get("findings"):
        lines += [result["findings"].rstrip(), ""]
    path.write_text("\n".join(lines))


def write_outputs(result: dict) -> None:
    result["summary"] = summarise(result["runs"])
    (RESULTS / "seed003_osx.json").write_text(json.dumps(result, indent=1))
    write_markdown(result, RESULTS / "seed003_osx.md")
    plot_curves(result, RESULTS / "seed003_osx_curves.png")


def main() -> None:
    parser = Parser(description=__doc__.splitlines()[0])
    parser.add_argument("--agents", type=names(AGENTS), default=",".join(AGENTS))
    parser.add_argument("--seeds", type=wholes(), default="0,1,2")
    parser.add_argument(
        "--steps", type=step_overrides(AGENTS), default="", help="agent=steps overrides, comma separated"
    )
    parser.add_argument("--episodes", type=whole(), default=20)
    parser.add_argument("--findings", type=readable, help="a Markdown file appended to the results")
    parser.add_argument("--report", action="store_true", help="only rewrite Markdown and plot from the JSON")
    args = parser.parse_args()
    findings = args.findings
    if args.report:
        result = json.loads((RESULTS / "seed003_osx.json").read_text())
        result["findings"] = findings or result.get("findings")
        write_outputs(result)
        return
    import torch

    torch.set_num_threads(1)
    steps = {**DEFAULT_STEPS, **args.steps}
    agents, seeds = args.agents, args.seeds
    RESULTS.mkdir(exist_ok=True)
    result = {
        "command": "python " + shlex.join(sys.argv),
        "machine": f"{cpu_isa()}, {os.cpu_count()} cores (shared with other jobs), "
        f"Python {platform.python_version()}",
        "date": time.strftime("%Y-%m-%d"),
        "episodes": args.episodes,
        "steps": {a: steps[a] for a in agents},
        "findings": findings,
        "runs": [],
    }
    for seed in seeds:  # seeds outermost: an interrupted benchmark has every agent
        for agent in agents:
            trained = train_run(agent, seed, steps[agent])
            run_dir = RUNS / f"seed003-{agent}-s{seed}"
            report = evaluate(run_dir, args.episodes)
            returns, lengths = training_curve(run_dir)
            row = {
                **trained,
                **{k: v for k, v in report.items() if k != "per_episode"},
                "training_returns": returns,
                "training_lengths": lengths,
            }
            result["runs"].append(row)
            print({k: row[k] for k in ("agent", "seed") + METRICS}, flush=True)
            write_outputs(result)  # after every run: an interrupted benchmark keeps what ran


if __name__ == "__main__":
    main()
