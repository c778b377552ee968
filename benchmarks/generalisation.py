"""Generalisation across procedural maps (MetaDrive's experiment): PPO trained on 1, 10 and 100
maps, evaluated on 100 unseen maps and on its own training maps.

    OMP_NUM_THREADS=1 NUMBA_NUM_THREADS=1 python benchmarks/generalisation.py \\
        [--steps 50000] [--seeds 0,1,2] [--maps 1,10,100] [--report-only]

Each run is what ``drivelab train`` makes (the library call behind it, with the shipped PPO
hyper-parameters; the equivalent command is written into the results):

    drivelab train --algo ppo --env blocks --obs lidar,measurements,waypoints --action continuous \\
        --reward metadrive --n-envs 8 --steps STEPS --seed SEED --eval-maps 1000:100 \\
        --config benchmarks/maps-N.yaml   # N = 1, 10, 100: env_options of N maps

then evaluated as ``drivelab evaluate RUN --episodes 100 --maps 1000:100`` (the unseen maps, one
episode on each) and ``drivelab evaluate RUN --episodes 100 --maps 0:N`` (its training maps: each
of the N maps 100 / N times, with other traffic than in training).

Resumable: a run whose directory holds model.zip is not trained again (one without it is resumed
from its checkpoint, or started over), an evaluation whose JSON is there is not played again.
A larger ``--steps`` continues complete runs (``drivelab train --resume RUN --steps STEPS``) and
keeps their earlier evaluations in ``RUN/steps-<steps>/``: the report shows both budgets.
``--report-only`` writes the report from what is there.

Intervals: per run, the success rate's 90 % Wilson interval over its episodes, and the train−test
gap's 90 % percentile bootstrap over episodes (train and test episodes resampled independently);
per number of maps, the mean over the seeds with a 90 % percentile bootstrap over seeds
(``drivelab.training.stats.bootstrap_ci``).
"""

from __future__ import annotations

import json
import math
import os
import platform
import shlex
import shutil
import sys
import time
from pathlib import Path

import numpy as np

os.environ.setdefault("PYGAME_HIDE_SUPPORT_PROMPT", "1")

from drivelab.config import build_config  # noqa: E402
from drivelab.errors import UsageError  # noqa: E402
from drivelab.hyperparams import with_shipped_hyperparams  # noqa: E402
from drivelab.training.evaluate import evaluate_run, load_run_config, report_name  # noqa: E402
from drivelab.training.run import resume, train  # noqa: E402
from drivelab.training.stats import bootstrap_ci  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parent))
from provenance import Parser, command_line, cpu_isa, whole, wholes  # noqa: E402

RESULTS = Path(__file__).parent / "results"
RUNS = Path(__file__).parent / "runs" / "generalisation"
OBS = "lidar,measurements,waypoints"
N_ENVS = 8
BLOCKS = 3  # MetaDrive's default map=3
TEST_MAPS = "1000:100"  # disjoint from every training set (seeds 0 … 99)
Z90 = 1.6448536269514722  # the standard normal's 95th percentile: two-sided 90 %
RESAMPLES = 10_000


def run_values(maps: int, seed: int, steps: int) -> dict:
    """The run's config values, as ``drivelab train`` builds them from its options."""
    return {
        "algo": "ppo", "env": "blocks", "obs": OBS, "action": "continuous", "reward": "metadrive",
        "n_envs": N_ENVS, "steps": steps, "seed": seed, "eval_maps": TEST_MAPS,
        "eval_every": steps, "eval_episodes": 1, "name": f"ppo-maps{maps}-s{seed}",
        "env_options": {"backend_options": {"map": BLOCKS, "start_seed": 0, "num_scenarios": maps}},
    }  # fmt: skip


def train_arguments(maps: int, seed: int, steps: int) -> list[str]:
    """The ``drivelab train`` arguments of a run of ``steps`` steps evaluated at its end, paths from
    the repository root (``benchmarks/maps-N.yaml`` holds the maps' ``env_options``): the config
    ``run_values`` makes."""
    name, root = f"ppo-maps{maps}-s{seed}", Path(__file__).resolve().parents[1]
    return [
        "train", "--algo", "ppo", "--env", "blocks", "--obs", OBS, "--action", "continuous",
        "--reward", "metadrive", "--n-envs", str(N_ENVS), "--steps", str(steps), "--seed", str(seed),
        "--eval-maps", TEST_MAPS, "--eval-every", str(steps), "--eval-episodes", "1", "--name", name,
        "--runs-dir", str(RUNS.resolve().relative_to(root)),
        "--config", str((Path(__file__).resolve().parent / f"maps-{maps}.yaml").relative_to(root)),
    ]  # fmt: skip


def train_command(maps: int, seed: int, steps: int) -> str:
    """The ``drivelab train`` command(s) of a run, from the repository root: trained to its
    ``eval_every`` (the first budget), then continued to ``steps`` when that is larger."""
    run_dir = RUNS / f"ppo-maps{maps}-s{seed}"
    first = load_run_config(run_dir).eval_every
    command = "drivelab " + shlex.join(train_arguments(maps, seed, first))
    if steps > first:
        root = Path(__file__).resolve().parents[1]
        command += f" && drivelab train --resume {run_dir.resolve().relative_to(root)} --steps {steps}"
    return command


def ensure_trained(maps: int, seed: int, steps: int) -> Path:
    """The run directory with its model.zip at ``steps``: trained, resumed, continued or left as
    it is; its times kept in ``<run>.timing.json`` beside it.

    A complete run of fewer steps is continued to ``steps`` (``drivelab train --resume RUN --steps
    STEPS``: exactly the uninterrupted run), after its evaluations and times are moved into
    ``RUN/steps-<its steps>/``, where the report finds them as an earlier budget."""
    config = build_config(with_shipped_hyperparams(run_values(maps, seed, steps)))
    run_dir = RUNS / config.name
    timing = RUNS / f"{config.name}.timing.json"
    before = json.loads(timing.read_text()) if timing.is_file() else {}
    wall, cpu = time.perf_counter(), time.process_time()
    if (run_dir / "model.zip").is_file():
        existing = load_run_config(run_dir)
        same = build_config({**config.to_dict(), "eval_every": existing.eval_every})
        if existing.identity() != same.identity() or existing.steps > steps:
            sys.exit(f"error: {run_dir} was trained with another config; give another runs folder")
        if existing.steps == steps:
            return run_dir
        archive = run_dir / f"steps-{existing.steps}"
        archive.mkdir(exist_ok=True)
        for path in run_dir.glob("eval-maps-*.json"):
            os.replace(path, archive / path.name)
        if timing.is_file():
            shutil.copy(timing, archive / "timing.json")
        resume(run_dir, steps)
        resumed = f"continued from {existing.steps}"
    else:
        resumed = ""
        if (run_dir / "checkpoints" / "latest.json").is_file():
            try:
                resume(run_dir, steps)
                resumed = "resumed"
            except UsageError as exc:
                print(f"{run_dir}: cannot resume ({exc}); starting over", flush=True)
        if not resumed:
            shutil.rmtree(run_dir, ignore_errors=True)
            before = {}
            train(config, RUNS)
    record = {
        "train_wall_s": time.perf_counter() - wall + before.get("train_wall_s", 0.0),
        "train_cpu_s": time.process_time() - cpu + before.get("train_cpu_s", 0.0),
        "resumed": resumed,
        "load_average_1min": os.getloadavg()[0],
    }
    timing.write_text(json.dumps(record, indent=2))
    return run_dir


def ensure_evaluated(run_dir: Path, maps: str, episodes: int) -> dict:
    """The run's ``eval-maps-START-COUNT.json`` (``drivelab evaluate --maps``), played if missing."""
    path = run_dir / report_name(maps)
    if path.is_file():
        report = json.loads(path.read_text())
        if report["episodes"] == episodes:
            return report
    wall, cpu = time.perf_counter(), time.process_time()
    evaluate_run(run_dir, episodes=episodes, maps=maps)
    report = json.loads(path.read_text())
    report["eval_wall_s"], report["eval_cpu_s"] = time.perf_counter() - wall, time.process_time() - cpu
    path.write_text(json.dumps(report, indent=2))
    return report


# --- statistics ------------------------------------------------------------------------------
def wilson(successes: float, n: int, z: float = Z90) -> tuple[float, float]:
    """Wilson score interval of a proportion (90 % with the default z)."""
    if n == 0:
        return math.nan, math.nan
    p = successes / n
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    return max(0.0, centre - half), min(1.0, centre + half)


def gap_bootstrap(train: np.ndarray, test: np.ndarray, seed: int = 0) -> tuple[float, float]:
    """90 % percentile bootstrap of mean(train) − mean(test), each resampled with replacement."""
    rng = np.random.default_rng(seed)
    a = rng.choice(train, size=(RESAMPLES, len(train))).mean(axis=1)
    b = rng.choice(test, size=(RESAMPLES, len(test))).mean(axis=1)
    low, high = np.quantile(a - b, [0.05, 0.95])
    return float(low), float(high)


def outcomes(report: dict) -> dict[str, np.ndarray]:
    """Per-episode 0/1 arrays: success, out of road (an off-road event), crash (a collision)."""
    episodes = report["per_episode"]
    return {
        "success": np.array([e["success"] for e in episodes], dtype=float),
        "out_of_road": np.array([e["off_road_events"] > 0 for e in episodes], dtype=float),
        "crash": np.array([e["crashed"] for e in episodes], dtype=float),
        "route_completion": np.array([e["route_completion"] for e in episodes], dtype=float),
    }


def run_row(maps: int, seed: int, train_report: dict, test_report: dict) -> dict:
    row = {"maps": maps, "seed": seed}
    split_outcomes = {"train": outcomes(train_report), "test": outcomes(test_report)}
    for split, values in split_outcomes.items():
        n = len(values["success"])
        row[f"{split}_episodes"] = n
        for key, column in values.items():
            row[f"{split}_{key}"] = float(column.mean())
        row[f"{split}_success_ci90"] = wilson(values["success"].sum(), n)
    row["gap"] = row["train_success"] - row["test_success"]
    row["gap_ci90"] = gap_bootstrap(split_outcomes["train"]["success"], split_outcomes["test"]["success"])
    return row


def group_row(maps: int, rows: list[dict]) -> dict:
    """The mean over seeds of one number of maps, with 90 % bootstrap intervals over seeds."""
    group = {"maps": maps, "seeds": [r["seed"] for r in rows]}
    for key in ("train_success", "test_success", "gap", "train_out_of_road", "test_out_of_road",
                "train_crash", "test_crash", "train_route_completion", "test_route_completion"):  # fmt: skip
        values = [r[key] for r in rows]
        group[key] = float(np.mean(values))
        group[f"{key}_ci90_seeds"] = bootstrap_ci(values) if len(values) > 1 else (math.nan, math.nan)
    n_train = sum(r["train_episodes"] for r in rows)
    n_test = sum(r["test_episodes"] for r in rows)
    group["train_success_ci90_pooled"] = wilson(
        sum(r["train_success"] * r["train_episodes"] for r in rows), n_train
    )
    group["test_success_ci90_pooled"] = wilson(
        sum(r["test_success"] * r["test_episodes"] for r in rows), n_test
    )
    return group


# --- report ----------------------------------------------------------------------------------
def group_table(groups: list[dict], rows: list[dict]) -> list[str]:
    """Markdown lines: one row per number of maps (over seeds when there are several)."""
    multi = any(len(g["seeds"]) > 1 for g in groups)
    lines = [
        "| training maps | seeds | success on train | success on 100 unseen | gap (train − test) "
        "| out of road train / test | crash train / test | route completion train / test |",
        "|---|---|---|---|---|---|---|---|",
    ]
    row_of = {(r["maps"], r["seed"]): r for r in rows}
    for g in groups:
        if multi:
            train, test = (
                f"{g[f'{split}_success']:.2f} {interval(g[f'{split}_success_ci90_seeds'])} "
                f"({interval(g[f'{split}_success_ci90_pooled'])})"
                for split in ("train", "test")
            )
            gap = f"{g['gap']:+.2f} {interval(g['gap_ci90_seeds'])}"
        else:
            r = row_of[(g["maps"], g["seeds"][0])]
            train = f"{g['train_success']:.2f} {interval(r['train_success_ci90'])}"
            test = f"{g['test_success']:.2f} {interval(r['test_success_ci90'])}"
            gap = f"{g['gap']:+.2f} {interval(r['gap_ci90'])}"
        lines.append(
            f"| {g['maps']} | {len(g['seeds'])} | {train} | {test} | {gap} | "
            f"{g['train_out_of_road']:.2f} / {g['test_out_of_road']:.2f} | {g['train_crash']:.2f} / "
            f"{g['test_crash']:.2f} | {g['train_route_completion']:.2f} / {g['test_route_completion']:.2f} |"
        )
    return lines


def groups_of(rows: list[dict], maps: list[int]) -> list[dict]:
    return [
        group_row(m, [r for r in rows if r["maps"] == m]) for m in maps if any(r["maps"] == m for r in rows)
    ]


def interval(pair) -> str:
    low, high = pair
    return "n/a" if math.isnan(low) else f"[{low:.2f}, {high:.2f}]"


def plot(
    groups: list[dict], rows: list[dict], path: Path, steps: int, earlier: dict[int, list[dict]]
) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.5, 4.2))
    for budget, earlier_groups in sorted(earlier.items()):
        for split, colour in (("train", "tab:blue"), ("test", "tab:orange")):
            ax.plot(
                [g["maps"] for g in earlier_groups], [g[f"{split}_success"] for g in earlier_groups],
                color=colour, linestyle="--", marker="x", alpha=0.5,
                label=f"{'training' if split == 'train' else 'unseen'} maps, {budget:,} steps",
            )  # fmt: skip
    for split, colour in (("train", "tab:blue"), ("test", "tab:orange")):
        xs = [g["maps"] for g in groups]
        ys = [g[f"{split}_success"] for g in groups]
        bands = [
            g[f"{split}_success_ci90_seeds" if len(g["seeds"]) > 1 else f"{split}_success_ci90_pooled"]
            for g in groups
        ]
        low = [y - b[0] for y, b in zip(ys, bands, strict=True)]
        high = [b[1] - y for y, b in zip(ys, bands, strict=True)]
        label = f"{'training maps' if split == 'train' else '100 unseen maps'}, {steps:,} steps"
        ax.errorbar(xs, ys, yerr=[low, high], color=colour, marker="o", capsize=4, label=label)
        ax.scatter(
            [r["maps"] for r in rows], [r[f"{split}_success"] for r in rows], color=colour, alpha=0.35, s=14
        )
    ax.set_xscale("log")
    ax.set_xticks([g["maps"] for g in groups], [str(g["maps"]) for g in groups])
    ax.set_ylim(-0.02, 1.02)
    ax.set_xlabel("number of training maps")
    ax.set_ylabel("success rate")
    ax.set_title("PPO on procedural block maps: train vs unseen maps")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def write_report(
    args,
    rows: list[dict],
    times: dict,
    skipped: list[str],
    earlier: dict[int, list[dict]],
    earlier_cpu_s: float,
) -> None:
    """generalisation.md / .json / .png from the final ``rows`` and the ``earlier`` budgets' rows
    (steps → rows of the same runs evaluated before they were continued)."""
    groups = groups_of(rows, args.maps)
    earlier_groups = {budget: groups_of(budget_rows, args.maps) for budget, budget_rows in earlier.items()}
    if not groups:
        print("nothing to report yet", flush=True)
        return
    test_start, test_count = (int(v) for v in TEST_MAPS.split(":"))
    first = load_run_config(RUNS / f"ppo-maps{rows[0]['maps']}-s{rows[0]['seed']}")
    hyperparams = ", ".join(f"{k} {v}" for k, v in first.hyperparams.items())
    machine = f"{cpu_isa()}, {os.cpu_count()} cores, Python {platform.python_version()}"
    command = command_line()
    commands = {
        f"maps{r['maps']}-s{r['seed']}": train_command(r["maps"], r["seed"], args.steps) for r in rows
    }
    for budget, budget_rows in sorted(earlier.items()):
        for r in budget_rows:
            commands.setdefault(f"maps{r['maps']}-s{r['seed']}", train_command(r["maps"], r["seed"], budget))
    cpu_total = sum(t.get("train_cpu_s", 0) + t.get("eval_cpu_s", 0) for t in times.values()) + earlier_cpu_s
    result = {
        "command": command,
        "machine": machine,
        "date": time.strftime("%Y-%m-%d"),
        "steps_per_run": args.steps,
        "seeds": args.seeds,
        "maps": args.maps,
        "blocks_per_map": BLOCKS,
        "test_maps": TEST_MAPS,
        "episodes": {"test": args.test_episodes, "train": args.train_episodes},
        "obs": OBS,
        "n_envs": N_ENVS,
        "train_commands": commands,
        "cpu_s_total": cpu_total,
        "times": times,
        "not_run": skipped,
        "groups": groups,
        "runs": rows,
        "earlier_budgets": {
            str(budget): {"groups": earlier_groups[budget], "runs": budget_rows}
            for budget, budget_rows in sorted(earlier.items())
        },
    }
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / "generalisation.json").write_text(json.dumps(result, indent=2))
    plot(groups, rows, RESULTS / "generalisation.png", args.steps, earlier_groups)
    multi = any(len(g["seeds"]) > 1 for g in groups)
    lines = [
        "# Generalisation: PPO trained on 1, 10 and 100 procedural maps (MetaDrive's experiment)",
        "",
        f"Command: `{command}`  ",
        f"Machine: {machine}; shared with other jobs, niced, one thread; date {result['date']}.  ",
        f"Budget: {args.steps:,} environment steps per run ({N_ENVS} worlds), seeds "
        f"{', '.join(map(str, args.seeds))}; "
        f"CPU time of what this report holds: {cpu_total / 60:.1f} min"
        + (
            f" (with the evaluations at {', '.join(f'{b:,}' for b in sorted(earlier))} steps)."
            if earlier
            else "."
        ),
        "MetaDrive's generalisation runs train PPO for about 1M steps and more, so these runs have a small "
        "fraction of that budget: the rates below are those of briefly trained policies.",
        "",
        f"Each run: SB3 PPO with drivelab's shipped hyper-parameters ({hyperparams}), `--env blocks` "
        f"with map={BLOCKS} (random blocks, MetaDrive's default), MetaDrive's traffic density 0.1, "
        f"observation `{OBS}` (LiDAR 240 beams + speed/steering + 10 route waypoints, standing in for "
        "MetaDrive's 240 LiDAR + ego state + navigation), continuous steering/acceleration, reward "
        f"`metadrive`. Training maps: seeds 0 … N−1. Test: the 100 maps of seeds {test_start} … "
        f"{test_start + test_count - 1} (one episode each: `drivelab evaluate RUN --episodes "
        f"{args.test_episodes} --maps {TEST_MAPS}`); train: `--episodes {args.train_episodes} --maps 0:N` "
        "(each training map 100/N times, traffic drawn anew). Deterministic policy.",
        "",
        "Success = arrival at the route's end; out of road = an off-road event (off every lane or across a "
        "solid line); crash = a collision. Both end the episode.",
        "",
        "## Mean over seeds" if multi else "## Results",
        "",
        (
            "Intervals: 90 % percentile bootstrap over seeds (coarse with so few seeds); in brackets after "
            "it the 90 % Wilson interval of all seeds' episodes pooled."
        )
        if multi
        else "Intervals: 90 % Wilson over episodes (success); gap: 90 % bootstrap over episodes.",
        "",
    ]
    lines += group_table(groups, rows)
    off_road = ", ".join(
        f"{g['test_out_of_road'] - g['train_out_of_road']:+.2f} ({g['maps']})" for g in groups
    )
    crash = [g[f"{split}_crash"] for g in groups for split in ("train", "test")]
    lines += [
        "",
        f"Out of road, unseen minus training maps, by number of training maps: {off_road}. Crashes "
        f"end {min(crash):.2f}–{max(crash):.2f} of the episodes: drivelab's traffic drives from the "
        "start, where MetaDrive's waits for the ego ('trigger' mode).",
    ]
    lines += [
        "",
        "## Each run",
        "",
        "Success with its 90 % Wilson interval over the episodes; gap with a 90 % bootstrap over episodes.",
        "",
        "| training maps | seed | success train | success test | gap | out of road train / test "
        "| crash train / test | training CPU | evaluation CPU |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        t = times.get(f"maps{r['maps']}-s{r['seed']}", {})
        lines.append(
            f"| {r['maps']} | {r['seed']} | {r['train_success']:.2f} {interval(r['train_success_ci90'])} "
            f"| {r['test_success']:.2f} {interval(r['test_success_ci90'])} | {r['gap']:+.2f} "
            f"{interval(r['gap_ci90'])} | {r['train_out_of_road']:.2f} / {r['test_out_of_road']:.2f} "
            f"| {r['train_crash']:.2f} / {r['test_crash']:.2f} "
            f"| {t.get('train_cpu_s', math.nan) / 60:.1f} min "
            f"| {t.get('eval_cpu_s', math.nan) / 60:.1f} min |"
        )
    for budget, budget_groups in sorted(earlier_groups.items()):
        lines += [
            "",
            f"## The same runs at {budget:,} steps",
            "",
            f"The runs evaluated as above after {budget:,} steps; those in the table above were then "
            f"continued to {args.steps:,} (`drivelab train --resume RUN --steps {args.steps}`, which "
            "continues exactly).",
            "",
            *group_table(budget_groups, earlier[budget]),
        ]
    if skipped:
        lines += [
            "",
            f"Not at {args.steps:,} steps (not run or not continued in the time there was): "
            f"{', '.join(skipped)}; the ones listed above at fewer steps are reported there.",
        ]
    lines += [
        "",
        "Plot: `generalisation.png` (success against the number of training maps; points: single seeds).",
        "",
        "Training command of each run (the library call behind it is what this script makes):",
        "",
        *[f"    {c}" for c in result["train_commands"].values()],
        "",
    ]
    (RESULTS / "generalisation.md").write_text("\n".join(lines))
    print("\n".join(lines), flush=True)


def earlier_evaluations(run_dir: Path, maps: int, seed: int, steps: int) -> list[tuple[int, dict, float]]:
    """(budget, row, CPU seconds) of the run's evaluations below ``steps``: those kept in
    ``steps-<budget>/`` when it was continued, and its present ones when it is complete at fewer
    steps (not continued). The CPU seconds are those evaluations' (and the training's, for a run
    that stops there)."""
    names = [report_name(TEST_MAPS), report_name(f"0:{maps}")]
    found = []
    folders = [(int(a.name.removeprefix("steps-")), a, a / "timing.json") for a in run_dir.glob("steps-*")]
    if (run_dir / "model.zip").is_file() and load_run_config(run_dir).steps < steps:
        timing = RUNS / f"{run_dir.name}.timing.json"
        folders.append((load_run_config(run_dir).steps, run_dir, timing))
    for budget, folder, timing in sorted(folders):
        paths = [folder / name for name in names]
        if not all(path.is_file() for path in paths):
            continue
        test, train_report = (json.loads(path.read_text()) for path in paths)
        cpu_s = test.get("eval_cpu_s", 0.0) + train_report.get("eval_cpu_s", 0.0)
        if not (run_dir / "model.zip").is_file() or load_run_config(run_dir).steps <= budget:
            # the run stops at this budget (or its continuation is unfinished): its training counts too
            cpu_s += json.loads(timing.read_text()).get("train_cpu_s", 0.0) if timing.is_file() else 0.0
        found.append((budget, run_row(maps, seed, train_report, test), cpu_s))
    return found


def main() -> None:
    global RUNS
    parser = Parser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=whole(), default=50_000)
    parser.add_argument("--seeds", type=wholes(), default="0,1,2")
    parser.add_argument("--maps", type=wholes(1), default="1,10,100")
    parser.add_argument("--test-episodes", type=whole(), default=100)
    parser.add_argument("--train-episodes", type=whole(), default=100)
    parser.add_argument("--runs-dir", type=Path, default=RUNS)
    parser.add_argument("--report-only", action="store_true", help="write the report from what is there")
    args = parser.parse_args()
    RUNS = args.runs_dir
    rows, times, skipped, earlier, earlier_cpu_s = [], {}, [], {}, 0.0
    for seed in args.seeds:  # seed-major: an unfinished budget still leaves whole seeds
        for maps in args.maps:
            key = f"maps{maps}-s{seed}"
            run_dir = RUNS / f"ppo-maps{maps}-s{seed}"
            if args.report_only:
                if not (run_dir / "model.zip").is_file() or load_run_config(run_dir).steps != args.steps:
                    skipped.append(key)
                    for budget, row, cpu_s in earlier_evaluations(run_dir, maps, seed, args.steps):
                        earlier.setdefault(budget, []).append(row)
                        earlier_cpu_s += cpu_s
                    continue
            else:
                run_dir = ensure_trained(maps, seed, args.steps)
            test_path = run_dir / "eval-maps-{}-{}.json".format(*TEST_MAPS.split(":"))
            train_path = run_dir / f"eval-maps-0-{maps}.json"
            if args.report_only and not (test_path.is_file() and train_path.is_file()):
                skipped.append(key)
                continue
            test = ensure_evaluated(run_dir, TEST_MAPS, args.test_episodes)
            train_report = ensure_evaluated(run_dir, f"0:{maps}", args.train_episodes)
            timing_path = RUNS / f"ppo-maps{maps}-s{seed}.timing.json"
            timing = json.loads(timing_path.read_text()) if timing_path.is_file() else {}
            timing["eval_cpu_s"] = test.get("eval_cpu_s", math.nan) + train_report.get("eval_cpu_s", math.nan)
            times[key] = timing
            rows.append(run_row(maps, seed, train_report, test))
            for budget, row, cpu_s in earlier_evaluations(run_dir, maps, seed, args.steps):
                earlier.setdefault(budget, []).append(row)
                earlier_cpu_s += cpu_s
            print(key, {k: rows[-1][k] for k in ("train_success", "test_success", "gap")}, timing, flush=True)
    write_report(args, rows, times, skipped, earlier, earlier_cpu_s)


if __name__ == "__main__":
    main()
