"""Where a town run's NoCrash collisions happen: each collision of the NoCrash routes of one traffic
level, with what the ego and the body it touched were doing.

    nice -n 10 env OMP_NUM_THREADS=1 NUMBA_NUM_THREADS=1 \\
        .venv/bin/python benchmarks/town_collisions.py RUN [RUN ...] [--level dense] [--episodes 100]
        [--beta-actions mode,mean]

Each run drives the test town's fixed routes of ``drivelab benchmark nocrash`` (the same episodes,
its deterministic actions; a Beta policy once for each of ``--beta-actions``, read at its mode or
its mean). At every collision: its kind (vehicle or pedestrian), the ego's speed
then and a second earlier, where the nearest other body is in the ego frame (ahead within 45°,
behind, or beside) with its speed and heading relative to the ego's, whether the ego is in a
junction and the state of a light ahead within 30 m. The collisions are grouped as: creeping into
a stopped vehicle ahead (the ego under 1 m/s, the other under 0.5 m/s), a vehicle ahead otherwise,
a vehicle beside or behind, a pedestrian. Writes ``benchmarks/results/town_collisions.json`` (every
collision) and ``.md`` (the groups per run).
"""

from __future__ import annotations

import json
import platform
import shlex
import sys
from collections import Counter
from datetime import date
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from drivelab.agents.actor_critic import BETA_ACTIONS  # noqa: E402
from drivelab.envs.core import DriveEnv  # noqa: E402
from drivelab.training.checkpoints import load_agent  # noqa: E402
from drivelab.training.evaluate import load_run_config  # noqa: E402
from drivelab.training.nocrash import LEVELS, NOCRASH_SEED  # noqa: E402

sys.path.insert(0, str(ROOT / "benchmarks"))
from provenance import Parser, stop, whole  # noqa: E402

RESULTS = ROOT / "benchmarks" / "results"
GROUPS = (
    "creeping into a stopped vehicle ahead",
    "a vehicle ahead, otherwise",
    "a vehicle beside or behind",
    "a pedestrian",
)
LIGHTS = {None: "none", 0: "green", 1: "yellow", 2: "red"}


def collision_row(world, speeds: list[float]) -> dict:
    """What the ego and the nearest other body do at a collision (``speeds``: the ego's so far)."""
    bodies = world.road_users()
    delta = bodies[:, :2] - world.ego.position
    cos_h, sin_h = np.cos(world.ego.heading), np.sin(world.ego.heading)
    x, y = delta[:, 0] * cos_h + delta[:, 1] * sin_h, -delta[:, 0] * sin_h + delta[:, 1] * cos_h
    nearest = int(np.argmin(np.hypot(x, y)))
    bearing = float(np.degrees(np.arctan2(y[nearest], x[nearest])))
    relative = float(np.degrees((bodies[nearest, 2] - world.ego.heading + np.pi) % (2 * np.pi) - np.pi))
    light = world.light_ahead(30.0)
    return {
        "kind": world.events.collision_with,
        "ego_speed_mps": round(speeds[-1], 2),
        "ego_speed_1s_before_mps": round(speeds[max(len(speeds) - 1 - round(1 / world.dt_s), 0)], 2),
        "where": "ahead" if abs(bearing) < 45 else "behind" if abs(bearing) > 135 else "beside",
        "bearing_deg": round(bearing),
        "other_heading_deg": round(relative),
        "other_speed_mps": round(float(bodies[nearest, 3]), 2),
        "in_junction": bool(world.ego.in_intersection),
        "light_ahead": LIGHTS[None if light is None else light[0]],
        "time_s": round(world.time_s, 1),
    }


def group(row: dict) -> str:
    if row["kind"] == "pedestrian":
        return GROUPS[3]
    if row["where"] != "ahead":
        return GROUPS[2]
    if row["ego_speed_mps"] < 1.0 and row["other_speed_mps"] < 0.5:
        return GROUPS[0]
    return GROUPS[1]


def collisions(run: Path, level: str, episodes: int, beta_action: str | None = None) -> list[dict]:
    """Every collision of ``run`` on the NoCrash routes of ``level`` (test town); a Beta policy acts
    at ``beta_action`` (its mode or mean; None: as the run says)."""
    config = load_run_config(run)
    agent = load_agent(run, config)
    if beta_action is not None:
        agent.policy.beta_action = beta_action
    kwargs = {**config.eval_env_kwargs(), "traffic": level}
    options = kwargs.get("backend_options") or {}
    kwargs["backend_options"] = {**options, "layout": "test", "fixed_routes": True}
    env = DriveEnv(**kwargs)
    rows = []
    for episode in range(episodes):
        obs, _ = env.reset(seed=NOCRASH_SEED + episode)  # run_episodes' episode e
        speeds, done = [], False
        while not done:
            obs, _, terminated, truncated, _ = env.step(agent.predict(obs, deterministic=True)[0])
            speeds.append(float(env.world.ego.speed_mps))
            if env.world.events.collided:
                rows.append({"episode": episode, **collision_row(env.world, speeds)})
            done = terminated or truncated
    return rows


def main(argv: list[str] | None = None) -> None:
    parser = Parser(description=__doc__.splitlines()[0])
    parser.add_argument("runs", nargs="+", type=Path)
    parser.add_argument("--level", default="dense", choices=LEVELS)
    parser.add_argument("--episodes", type=whole(), default=100)
    parser.add_argument("--out", type=Path, default=RESULTS / "town_collisions")
    parser.add_argument(
        "--beta-actions", default="mode", type=lambda text: text.split(","),
        help="a Beta policy's deterministic actions to drive with, comma-separated: mode, mean",
    )  # fmt: skip
    args = parser.parse_args(argv)
    if not args.beta_actions or set(args.beta_actions) - set(BETA_ACTIONS):
        stop(f"--beta-actions takes {' and '.join(BETA_ACTIONS)}, got {','.join(args.beta_actions)!r}")
    for run in args.runs:  # every run checked before any is driven
        if not (run / "config.yaml").is_file():
            stop(f"{str(run)!r} is not a run directory (no config.yaml)")
        if load_run_config(run).env != "town":
            stop(f"{str(run)!r} was not trained in the town")
    report = {"level": args.level, "episodes": args.episodes, "runs": {}}
    lines = [
        "# Where the town's NoCrash collisions happen",
        "",
        f"Command: `python benchmarks/town_collisions.py {shlex.join(str(r) for r in args.runs)} --level "
        f"{args.level} --episodes {args.episodes} --beta-actions {','.join(args.beta_actions)}`  ",
        f"Machine: {platform.machine()}, Python {platform.python_version()}; {date.today().isoformat()}.",
        "",
        f"The {args.episodes} NoCrash routes of {args.level} traffic on the test town (the episodes of "
        "`drivelab benchmark nocrash`), each collision grouped by what the ego and the nearest other body "
        "were doing (see the script's docstring).",
        "",
        "| run | Beta read at | collisions | " + " | ".join(GROUPS) + " | in a junction |",
        "|---|---|---|" + "---|" * (len(GROUPS) + 1),
    ]
    for run in args.runs:
        beta = load_run_config(run).hyperparams.get("distribution") == "beta"  # ppo_own / a2c_own's Beta
        for readout in args.beta_actions if beta else [None]:
            rows = collisions(run, args.level, args.episodes, readout)
            report["runs"][str(run) if readout is None else f"{run} ({readout})"] = rows
            counts = Counter(group(row) for row in rows)
            junction = sum(row["in_junction"] for row in rows)
            cells = " | ".join(str(counts[name]) for name in GROUPS)
            label = run.resolve().relative_to(ROOT) if run.resolve().is_relative_to(ROOT) else run
            lines.append(f"| `{label}` | {readout or '—'} | {len(rows)} | {cells} | {junction} |")
            print(lines[-1], flush=True)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.with_suffix(".json").write_text(json.dumps(report, indent=1) + "\n")
    args.out.with_suffix(".md").write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
