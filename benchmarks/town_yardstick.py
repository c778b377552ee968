"""One yardstick in the town: the shipped town agents on the evaluation set and on NoCrash's rules.

    .venv/bin/python benchmarks/town_yardstick.py [--episodes 100]

For each shipped town agent (``drivelab/zoo/town-*``), greedy, over the same ``--episodes``
episodes per row:

- **evaluation set**: what ``drivelab evaluate`` plays. The training town, the run's traffic
  (dense), random routes, the episode ending on arrival, NoCrash's time limit (the route at
  10 km/h, plus 10 s);
- **evaluation set, cut at 60 s**: the same episodes, each also cut at the training episodes' 60 s.
  Until the time limit above was given to random routes, the evaluation set cut every episode at
  60 s, whatever its route;
- **NoCrash's fixed routes, training town**: ``fixed_routes`` on the training town, dense traffic,
  NoCrash's seeds;
- **NoCrash's fixed routes, test town**: what ``drivelab benchmark nocrash`` plays at the dense
  level.

The table also gives the share of the evaluation set's routes whose time limit is above 60 s.
"""

from __future__ import annotations

import json
import os
import sys
import time
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")

sys.path.insert(0, str(Path(__file__).resolve().parent))
from provenance import Parser, command_line, cpu_isa, whole  # noqa: E402

RESULTS = Path(__file__).parent / "results"
ROWS = {  # name: (episode seed, env keywords, backend options)
    "evaluation set": (None, {}, {}),
    "evaluation set, cut at 60 s": (None, {"duration_s": 60.0}, {}),
    "NoCrash's fixed routes, training town": ("nocrash", {}, {"fixed_routes": True}),
    "NoCrash's fixed routes, test town": ("nocrash", {}, {"fixed_routes": True, "layout": "test"}),
}


def measure(name: str, episodes: int) -> dict:
    from drivelab.envs.core import DriveEnv
    from drivelab.training.checkpoints import load_agent
    from drivelab.training.evaluate import aggregate, load_run_config, run_episodes
    from drivelab.training.nocrash import NOCRASH_SEED
    from drivelab.training.zoo import resolve

    run_dir, _ = resolve(name)
    config = load_run_config(run_dir)
    agent = load_agent(run_dir, config)
    policy = lambda obs: agent.predict(obs, deterministic=True)[0]  # noqa: E731
    rows = {}
    for row, (seed, keywords, options) in ROWS.items():
        kwargs = {**config.eval_env_kwargs(), **keywords}
        kwargs["backend_options"] = {**(kwargs.get("backend_options") or {}), **options}
        env = DriveEnv(**kwargs)
        limits = []
        if seed is None and not keywords:  # the route limits of the evaluation set's episodes
            from drivelab.training.seeds import evaluation_seeds

            for episode_seed in evaluation_seeds(episodes, 0):
                env.reset(options={"episode_seed": int(episode_seed)})
                limits.append(env.time_limit_s)
        start = time.perf_counter()
        results, _ = run_episodes(policy, env, episodes, None if seed is None else NOCRASH_SEED)
        summary = aggregate(results)
        timed_out = sum(1 for r in results if not r["success"] and not r["crashed"]) / episodes
        rows[row] = {**summary, "neither_success_nor_crash": timed_out, "wall_s": time.perf_counter() - start}
        if limits:
            rows[row]["routes_over_60_s"] = sum(limit > 60.0 for limit in limits) / episodes
        print(name, row, {k: round(v, 3) for k, v in rows[row].items() if isinstance(v, float)}, flush=True)
    return rows


def report(result: dict) -> str:
    lines = [
        "# One yardstick in the town: the evaluation set and NoCrash",
        "",
        f"Command: `{result['command']}`  ",
        f"Machine: {result['machine']}; date {result['date']}; "
        f"{result['episodes']} episodes per row, greedy.",
        "",
        "The shipped town agents (`drivelab zoo`), each row over the same episodes for every agent: "
        "the evaluation set (`drivelab evaluate`: the training town, the run's dense traffic, random "
        "routes with NoCrash's time limit, the route at 10 km/h plus 10 s); the same episodes each "
        "also cut at 60 s (the training episodes' length, the evaluation set's time limit before "
        "random routes got NoCrash's); NoCrash's fixed routes and seeds in the training town and in "
        'the test town (`drivelab benchmark nocrash`\'s dense level). "Neither": episodes that ended '
        "without success or collision (the time limit, a red light, off the route, blocked).",
        "",
        "| agent | protocol | success % | crash % | neither % | route completion % | mean speed m/s | "
        "routes whose limit is above 60 s % |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for agent, rows in result["agents"].items():
        for protocol, row in rows.items():
            over = row.get("routes_over_60_s")
            lines.append(
                f"| {agent} | {protocol} | {100 * row['success_rate']:.0f} | {100 * row['crash_rate']:.0f} | "
                f"{100 * row['neither_success_nor_crash']:.0f} | {100 * row['route_completion']:.0f} | "
                f"{row['mean_speed_mps']:.1f} | {'—' if over is None else f'{100 * over:.0f}'} |"
            )
    return "\n".join(lines) + "\n"


def main() -> None:
    parser = Parser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=whole(), default=100)
    parser.add_argument("--report-only", action="store_true", help="write the table again from the JSON")
    args = parser.parse_args()
    if args.report_only:
        result = json.loads((RESULTS / "town_yardstick.json").read_text())
    else:
        import platform

        import torch

        from drivelab.training.zoo import shipped_agents

        torch.set_num_threads(1)
        names = [agent.name for agent in shipped_agents() if agent.card["env"] == "town"]
        result = {
            "command": command_line(),
            "machine": f"{cpu_isa()}, {os.cpu_count()} cores, Python {platform.python_version()}, "
            f"torch {torch.__version__}",
            "date": time.strftime("%Y-%m-%d"),
            "episodes": args.episodes,
            "agents": {name: measure(name, args.episodes) for name in names},
        }
        RESULTS.mkdir(exist_ok=True)
        (RESULTS / "town_yardstick.json").write_text(json.dumps(result, indent=2))
    (RESULTS / "town_yardstick.md").write_text(report(result))
    print(report(result))


if __name__ == "__main__":
    main()
