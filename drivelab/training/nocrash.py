"""NoCrash-style evaluation in the town: RLAD's Table III (success per traffic level) and Table IV
(infraction analysis of one level).

A run trained in the town drives a town layout (by default the smaller, unseen test town) at every
traffic level on the town's fixed routes, with the same seeds for every run. Success is reaching the
target without a collision; infractions are counted per kilometre driven."""

from __future__ import annotations

import json
from pathlib import Path

from tqdm import tqdm

from drivelab.errors import UsageError
from drivelab.training.evaluate import aggregate, load_run_config, run_episodes
from drivelab.training.safe_files import locked_run, write_file

LEVELS = ("empty", "regular", "dense")
NOCRASH_SEED = 20_000  # the same episodes for every run
INFRACTIONS = (  # Table IV's columns: (label, key of ``aggregate``)
    ("success %", "success_rate"),
    ("route completion %", "route_completion"),
    ("collisions with pedestrians / km", "pedestrian_collisions_per_km"),
    ("collisions with vehicles / km", "vehicle_collisions_per_km"),
    ("collisions with the layout (off road) / km", "off_road_per_km"),
    ("red lights run / km", "red_lights_per_km"),
    ("blocked / km", "blocked_per_km"),
)


def nocrash(
    run_dir: str | Path,
    town: str = "test",
    episodes: int = 25,
    infraction_level: str = "regular",
    out_dir: str | Path | None = None,
) -> dict:
    """Evaluate ``run_dir`` on the NoCrash protocol; write nocrash.json and nocrash.md into it (or
    into ``out_dir``, created if missing).

    :param town: the layout to drive in: "test" (unseen during training) or "train".
    :param episodes: episodes per traffic level.
    :param infraction_level: the traffic level of the infraction table."""
    from drivelab.envs.core import DriveEnv
    from drivelab.scenarios.town.road import LAYOUTS
    from drivelab.training.checkpoints import check_trained_config, file_sha256, load_agent, model_path
    from drivelab.training.evaluate import check_writable, make_out_dir

    run_dir = Path(run_dir)
    with locked_run(run_dir, writes=out_dir is None):  # no evaluation of a run that trains now
        config = load_run_config(run_dir)
        check_trained_config(run_dir, config)
        if config.env != "town":
            raise UsageError(f"NoCrash evaluates town runs; {str(run_dir)!r} was trained on {config.env!r}")
        if town not in LAYOUTS:
            raise UsageError(f"unknown town {town!r} (choose from {', '.join(LAYOUTS)})")
        if episodes < 1:
            raise UsageError("--episodes must be >= 1")
        if infraction_level not in LEVELS:
            raise UsageError(f"unknown traffic level {infraction_level!r} (choose from {', '.join(LEVELS)})")
        evaluated = model_path(run_dir, config)
        agent = load_agent(run_dir, config)
        out_dir = run_dir if out_dir is None else make_out_dir(Path(out_dir))
        check_writable(out_dir, "nocrash.json")
        policy = lambda obs: agent.predict(obs, deterministic=True)[0]  # noqa: E731
        levels = {}
        with tqdm(total=len(LEVELS) * episodes, desc=f"nocrash {config.algo}", unit="episode") as bar:
            for level in LEVELS:
                kwargs = {**config.eval_env_kwargs(), "traffic": level}
                options = {**(kwargs.get("backend_options") or {}), "layout": town, "fixed_routes": True}
                kwargs["backend_options"] = options
                bar.set_postfix_str(level)
                env = DriveEnv(**kwargs)
                results, _ = run_episodes(
                    policy, env, episodes, NOCRASH_SEED, on_episode=lambda _: bar.update()
                )
                levels[level] = aggregate(results)
        report = {
            "run": str(run_dir),
            "algo": config.algo,
            "town": town,
            "episodes_per_level": episodes,
            "seed": NOCRASH_SEED,
            "model": str(evaluated.relative_to(run_dir)),
            "model_sha256": file_sha256(evaluated),
            "levels": levels,
            "infraction_level": infraction_level,
        }
        write_file(out_dir / "nocrash.json", json.dumps(report, indent=2))
        write_file(out_dir / "nocrash.md", report_markdown(report))
        return report


def _percent(value: float | None) -> str:
    return "n/a" if value is None else f"{100 * value:.1f}"


def _number(value: float | None) -> str:
    return "n/a" if value is None else f"{value:.2f}"


def report_markdown(report: dict) -> str:
    """Both tables as Markdown."""
    levels = report["levels"]
    infractions = levels[report["infraction_level"]]
    cells = [(_percent if label.endswith("%") else _number)(infractions[key]) for label, key in INFRACTIONS]
    lines = [
        f"# NoCrash: {report['algo']} in the {report['town']} town",
        "",
        f"Run `{report['run']}`, {report['episodes_per_level']} episodes per traffic level on the town's "
        "fixed routes.",
        "",
        "| traffic | success % |",
        "|---|---|",
        *[f"| {level} | {_percent(levels[level]['success_rate'])} |" for level in LEVELS],
        "",
        f"Infractions, {report['infraction_level']} traffic:",
        "",
        "| " + " | ".join(label for label, _ in INFRACTIONS) + " |",
        "|" + "---|" * len(INFRACTIONS),
        "| " + " | ".join(cells) + " |",
        "",
    ]
    return "\n".join(lines)
