"""Train, pack and measure the shipped agents (``drivelab/zoo/``) from their recorded commands.

    .venv/bin/python benchmarks/zoo_build.py [NAME ...] [--retrain] [--measure-only | --check-only]
    .venv/bin/python benchmarks/zoo_build.py [NAME ...] --verify

For each agent of ``AGENTS`` (all by default): ``drivelab train`` with its recorded arguments into
``benchmarks/runs/zoo/<name>`` (skipped when that run already has its final model, unless
``--retrain``), ``drivelab.training.zoo.pack`` into ``drivelab/zoo/<name>`` (config, model without
the optimizer's moments, card), then every recorded measurement on the packed agent
(``drivelab evaluate NAME``, ``drivelab benchmark nocrash NAME``), whose reports go to
``benchmarks/runs/zoo-eval/<name>`` and whose numbers, episode counts, commands, machine and CPU
time go into the card; finally ``drivelab enjoy NAME --episodes 3``, played in a fresh process
under ``drivelab.isa.PINNED_ISA`` (AVX2 code paths, one thread), gives the card's ``check``, the
numbers ``tests/training/test_zoo.py`` reproduces on any x86-64 CPU (for the camera agents, its
episodes cut at ``CAMERA_CHECK_DURATION_S``, as the card records). Every command runs with one thread
(``OMP_NUM_THREADS=1``). ``--measure-only`` re-measures the agents already in the zoo,
``--check-only`` records only their check. Writes ``benchmarks/results/zoo.md`` from the cards.

``--verify`` checks that the shipped agents are what their commands train today: each recipe is
trained afresh into ``benchmarks/runs/zoo-verify/<name>`` and packed into a scratch zoo, and its
model is compared with the shipped one, value for value (``zoo.model_differences``); the zoo is
left as it is. Writes ``benchmarks/results/zoo_verify.md`` (and ``.json``; an agent verified again
replaces its row).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import shlex
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
RUNS = Path("benchmarks/runs/zoo")
REPORTS = Path("benchmarks/runs/zoo-eval")
VERIFY_RUNS = Path("benchmarks/runs/zoo-verify")
VERIFY_RESULTS = ROOT / "benchmarks" / "results" / "zoo_verify"
DRIVELAB = [sys.executable, "-m", "drivelab.cli"]
CHECK_EPISODES = 3
# The camera-perception agents (follow-line/lane, ~25 ms a step) play their 3 check episodes cut
# at 20 s of the 60 s (100 steps each) so that tests/training/test_zoo.py stays fast; the card
# records the cap, and the 100-episode evaluation is uncut.
CAMERA_CHECK_DURATION_S = 20
PINNED_ISA_TEXT = "drivelab.isa.PINNED_ISA (AVX2 code paths, one thread)"

sys.path.insert(0, str(Path(__file__).parent))
from leaderboard import (  # noqa: E402
    BLOCKS_DAGGER,
    BLOCKS_FINETUNE,
    BLOCKS_PPO_OWN,
    HIGHWAY_DQN,
    HIGHWAY_PPO_OWN_ATTENTION,
    INTERSECTION_PPO_OWN_SIL,
    RACETRACK_DAGGER,
    RACETRACK_PPO_OWN,
    TOWN_PPO_OWN,
    TOWN_PPO_OWN_IMAGE,
    UNSEEN_MAPS,
    UNTUNED_PPO,
)
from provenance import Parser, agent_defaults, check_reuse, command_line, cpu_isa, stop, training_command  # noqa: E402
from town_competence import recipe as town_recipe  # noqa: E402

# highway-env's documented PPO values, pinned in the PPO recipes below: their agents were trained
# before drivelab/hyperparams/ppo.yaml's scenario entries held drivelab's tuned values (the shipped
# values then, as each card's hyperparams record; the cards' commands carry the pins since
# 2026-11-27, so that they still train the same model)
UNTUNED = shlex.split(UNTUNED_PPO)


# the town agents' measurements: the evaluation set and NoCrash on the test town, 100 episodes each
TOWN_MEASURE = [
    ("evaluation set", ["evaluate", "{name}", "--episodes", "100"]),
    ("nocrash", ["benchmark", "nocrash", "{name}", "--town", "test", "--episodes", "100"]),
]


EVALUATION_SET = [("evaluation set", ["evaluate", "{name}", "--episodes", "100"])]


def seed_0(recipe: str) -> list[str]:
    """A recipe's ``drivelab train`` arguments for seed 0, the seed every shipped recipe agent is."""
    return [*shlex.split(recipe), "--seed", "0"]


AGENTS: dict[str, dict] = {
    "town-dagger": {
        "description": (
            "DAgger imitation of the town's rule-based expert on a non-privileged observation (top-down "
            "image with the lights, route waypoints, measurements); seed 0 of "
            "benchmarks/results/town_competence.md"
        ),
        "train": seed_0(town_recipe("image")),
        "measure": TOWN_MEASURE,
    },
    "town-dagger-privileged": {
        "description": (
            "DAgger imitation of the town's rule-based expert on the privileged observation the expert "
            "itself reads (route waypoints, measurements, affordances: the light, the leader, pedestrians); "
            "seed 0 of benchmarks/results/town_competence.md"
        ),
        "train": seed_0(town_recipe("privileged")),
        "measure": TOWN_MEASURE,
    },
    "town-ppo_own": {
        "description": (
            "drivelab's PPO (the fast on-policy trainer) in the town, learned by RL alone (no imitation): "
            "route waypoints, measurements and affordances (privileged: the light, the leader, "
            "pedestrians), Roach's reward with its terminal penalty x10, Beta actions, an entropy bonus, "
            "gamma 0.995, the learning rate annealed to 0 over 12 M steps on 64 worlds in dense traffic; "
            "the leaderboard's town ppo_own (privileged) recipe, seed 0 (it does not meet NoCrash's "
            "target of 90 / 75 / 60 %)"
        ),
        "train": seed_0(TOWN_PPO_OWN),
        "measure": TOWN_MEASURE,
    },
    "town-ppo_own-image": {
        "description": (
            "drivelab's PPO (the fast on-policy trainer) in the town, learned by RL alone (no imitation) "
            "from the bird's-eye view: the top-down image with the lights (48x48 pixels, 1 m each), route "
            "waypoints and measurements, seed 003's CNN; otherwise town-ppo_own's recipe (Roach's reward "
            "with its terminal penalty x10, Beta actions, an entropy bonus, gamma 0.995, the learning "
            "rate annealed to 0) over 3 M steps on 64 worlds in dense traffic; the leaderboard's town "
            "ppo_own (image) recipe, seed 0"
        ),
        "train": seed_0(TOWN_PPO_OWN_IMAGE),
        "measure": TOWN_MEASURE,
    },
    "highway-ppo": {
        "description": (
            "stable-baselines3 PPO on highway (kinematics, meta actions, regular traffic), 16 worlds, "
            "500 k steps on the highway_fast training reward (speed pays from 20 m/s, collision -10) "
            "with gamma 0.95: seed 0 of benchmarks/results/highway_competence.md"
        ),
        "train": [
            "--algo", "ppo", "--env", "highway", "--obs", "kinematics", "--action", "meta",
            "--reward", "highway_fast", "--traffic", "regular", "--n-envs", "16", "--steps", "500000",
            "-H", "gamma=0.95", "--eval-every", "250000", "--eval-episodes", "10", "--seed", "0", *UNTUNED,
        ],
        "measure": EVALUATION_SET,
    },
    "highway-ppo_own": {
        "description": (
            "drivelab's PPO (the fast on-policy trainer) on highway, learned by RL alone: the 10 nearest "
            "vehicles read by ego-attention (observations and rewards normalised), meta actions, the "
            "highway_fast training reward with its speed term doubled, gamma 0.99, entropy 0.01, the "
            "learning rate annealed; 12 M steps on 64 worlds; the leaderboard's highway ppo_own "
            "(attention) recipe, seed 0 (it does not meet the target of at most 3 % crashes at 24 m/s "
            "or more)"
        ),
        "train": seed_0(HIGHWAY_PPO_OWN_ATTENTION),
        "measure": EVALUATION_SET,
    },
    **{
        f"{scenario}-ppo": {
            "description": (
                f"stable-baselines3 PPO on {scenario} (kinematics, meta actions, the scenario's default "
                "reward: highway's, regular traffic), 16 worlds; highway-env's documented PPO values"
            ),
            "train": [
                "--algo", "ppo", "--env", scenario, "--obs", "kinematics", "--action", "meta",
                "--reward", "highway", "--traffic", "regular", "--n-envs", "16", "--steps", "100000",
                "--eval-every", "50000", "--eval-episodes", "10", "--seed", "0", *UNTUNED, "-H", "gamma=0.8",
            ],
            "measure": EVALUATION_SET,
        }
        for scenario in ("merge", "roundabout", "intersection")
    },
    "merge-dqn": {
        "description": (
            "stable-baselines3 DQN on merge (kinematics, meta actions, highway's reward, regular traffic), "
            "4 worlds, 100 k steps, highway-env's documented DQN values: seed 0 of the leaderboard's merge "
            "dqn entry, the one that meets the merge target over 3 seeds"
        ),
        "train": [*shlex.split(HIGHWAY_DQN.format(env="merge", reward="highway", steps=100_000)),
                  "--seed", "0"],
        "measure": EVALUATION_SET,
    },
    "intersection-ppo-arrival": {
        "description": (
            "stable-baselines3 PPO on intersection as intersection-ppo, but with the weights of "
            "highway-env's IntersectionEnv reward (collision -5, high speed 1, arrival 1; there the "
            "arrival replaces the step's reward and the speed range is 7-9 m/s, here it adds and the "
            "range is 2/3 to 1 of the limit, unnormalised): the highway reward pays nothing for "
            "arriving, and intersection-ppo learns to stop short of the junction"
        ),
        "train": [
            "--algo", "ppo", "--env", "intersection", "--obs", "kinematics", "--action", "meta",
            "--reward", "collision=-5,high_speed=1,arrival=1", "--traffic", "regular", "--n-envs", "16",
            "--steps", "100000", "--eval-every", "50000", "--eval-episodes", "10", "--seed", "0", *UNTUNED,
            "-H", "gamma=0.8",
        ],
        "measure": EVALUATION_SET,
    },
    "racetrack-ppo": {
        "description": (
            "stable-baselines3 PPO on racetrack with continuous [steering, acceleration] (highway-env's "
            "racetrack agent steers only), 16 worlds, regular traffic (one other car); observation: "
            "LiDAR (beams stop at the road edges and at vehicles: what highway-env's occupancy grid of "
            "presence and on-road cells tells) and the 10-number ego state (lane offset, heading, "
            "curvature, speed, front gap); highway-env's racetrack PPO values (gamma 0.9)"
        ),
        "train": [
            "--algo", "ppo", "--env", "racetrack", "--obs", "lidar,ego_state:features=10",
            "--action", "continuous", "--reward", "highway", "--traffic", "regular", "--n-envs", "16",
            "--steps", "100000", "--eval-every", "50000", "--eval-episodes", "5", "--seed", "0", *UNTUNED,
            "-H", "gamma=0.9",
        ],
        "measure": EVALUATION_SET,
    },
    "intersection-ppo_own": {
        "description": (
            "drivelab's PPO (the fast on-policy trainer) on intersection, learned by RL alone: the 15 "
            "nearest vehicles on the map's axes and where each is headed, read as a set by ego-attention, "
            "the route's waypoints and the clock, "
            "highway-env's three longitudinal actions, reward arrival +10, collision -10 and 0.2 per metre "
            "of route progress, self-imitation of its own best actions after each update, the learning "
            "rate annealed; 4 M steps on 64 worlds; the leaderboard's intersection 'ppo_own "
            "(self-imitation)' recipe, seed 0 (it does not meet the target of 80 % success with at most "
            "10 % crashes)"
        ),
        "train": seed_0(INTERSECTION_PPO_OWN_SIL),
        "measure": EVALUATION_SET,
    },
    "racetrack-ppo_own": {
        "description": (
            "drivelab's PPO (the fast on-policy trainer) on racetrack, learned by RL alone: LiDAR, the "
            "10-number ego state and the route's waypoints (normalised), target speeds up to 12 m/s and "
            "steering, reward collision -10, off road -10 and 0.1 per metre of centred progress, an "
            "entropy bonus; 1 M steps on 64 worlds; the leaderboard's racetrack ppo_own recipe, seed 0"
        ),
        "train": seed_0(RACETRACK_PPO_OWN),
        "measure": EVALUATION_SET,
    },
    "racetrack-dagger": {
        "description": (
            "DAgger imitation of the rule-based expert on racetrack (its racetrack rules: cruise 15 m/s, "
            "bends at 6 m/s², a gap to the other car along its route, from privileged waypoints and "
            "affordances) onto LiDAR and the 10-number ego state; target-speed actions up to 20 m/s; "
            "regular traffic (one other car); the leaderboard's racetrack dagger recipe, seed 0"
        ),
        "train": seed_0(RACETRACK_DAGGER),
        "measure": EVALUATION_SET,
    },
    **{
        f"follow-{kind}-qlearning": {
            "description": (
                f"seed 004's tabular Q-learning on follow-{kind}: the camera's {state}, the seed's "
                f"5-action table and reward, 20 000 steps (benchmarks/results/qlearning_follow-{kind}.md)"
            ),
            "train": [
                "--algo", "qlearning", "--env", f"follow-{kind}", "--obs", kind, "--action", f"seed_{kind}",
                "--reward", f"{kind}_follow", "--steps", "20000", "--eval-every", "20000", "--eval-episodes",
                "2", "--seed", "0",
            ],
            "measure": EVALUATION_SET,
            "check_duration_s": CAMERA_CHECK_DURATION_S,
        }
        for kind, state in (
            ("line", "yellow-line state (1296 states)"), ("lane", "lane-centre state (6 states)")
        )
    },
    "blocks-dagger": {
        "description": (
            "DAgger imitation of the rule-based expert on procedural block maps (cruise 15 m/s, pursuit "
            "in the velocity's frame, the vehicle ahead on its route, from privileged waypoints and "
            "affordances) onto LiDAR + measurements + waypoints; target-speed actions up to 20 m/s; "
            "1000 training maps, regular traffic; the leaderboard's blocks-unseen dagger recipe, seed 0"
        ),
        "train": seed_0(BLOCKS_DAGGER),
        # its evaluation set is its --eval-maps: the 100 unseen maps, one episode each
        "measure": [("100 unseen maps", ["evaluate", "{name}", "--maps", UNSEEN_MAPS, "--episodes", "100"])],
    },
    "blocks-dagger-ppo_own": {
        "description": (
            "PPO fine-tuning (drivelab's ppo_own) of the shipped blocks-dagger policy on the 1000 training "
            "maps: imitation, then RL; crashes and leaving the road at -300, gamma 0.995, the critic trained "
            "alone for 300 k steps, a KL term to the DAgger policy, 1 M steps on 64 worlds; the "
            "leaderboard's blocks-unseen dagger+ppo_own recipe, seed 0, started from blocks-dagger"
        ),
        "train": [*seed_0(BLOCKS_FINETUNE), "--init-from", "blocks-dagger"],
        "measure": [("100 unseen maps", ["evaluate", "{name}", "--maps", UNSEEN_MAPS, "--episodes", "100"])],
    },
    "blocks-ppo_own": {
        "description": (
            "drivelab's PPO (the fast on-policy trainer) on the 1000 training block maps, learned by RL "
            "alone (no imitation): LiDAR, measurements, waypoints and affordances (privileged: the leader's "
            "distance and speed), MetaDrive's reward with crashes and leaving the road at -300, Beta target "
            "speeds up to 15 m/s and steering, gamma 0.995, the learning rate annealed to 0 over 6 M steps "
            "on 64 worlds; "
            "the leaderboard's blocks-unseen ppo_own (privileged) recipe, seed 0"
        ),
        "train": seed_0(BLOCKS_PPO_OWN),
        "measure": [("100 unseen maps", ["evaluate", "{name}", "--maps", UNSEEN_MAPS, "--episodes", "100"])],
    },
    "blocks-ppo": {
        "description": (
            "drivelab's own PPO (CNN) on the 5x84x84 top-down image, continuous actions, on MetaDrive's "
            "map \"OSX\" (roundabout, straight, 4-way intersection), regular traffic: seed 003's image "
            "PPO, retrained with the arguments of benchmarks/seed003_osx.py (ppo_topdown, seed 1)"
        ),
        "train": [
            "--algo", "ppo_own", "--obs", "topdown", "--action", "continuous", "--reward", "metadrive",
            "--env", "blocks", "--traffic", "regular", "--backend", "fast", "-H", "gamma=0.99",
            "--config", "benchmarks/seed003_osx.yaml", "--steps", "5000", "--seed", "1",
            "--eval-every", "5000", "--eval-episodes", "1", "--checkpoint-every", "1666",
        ],
        "measure": EVALUATION_SET,
    },
}  # fmt: skip


def machine() -> str:
    return f"{cpu_isa()}, {os.cpu_count()} cores (shared), Python {platform.python_version()}"


def drivelab(arguments: list[str]) -> tuple[float, float]:
    """Run ``drivelab ARGUMENTS`` with one thread from the repository root; (wall, CPU) seconds."""
    print("$ drivelab " + shlex.join(arguments), flush=True)
    single = {"OMP_NUM_THREADS": "1", "NUMBA_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}
    before, start = os.times(), time.perf_counter()
    subprocess.run(DRIVELAB + arguments, check=True, env={**os.environ, **single}, cwd=ROOT)
    after = os.times()
    cpu = (after.children_user - before.children_user) + (after.children_system - before.children_system)
    return time.perf_counter() - start, cpu


def train_and_pack(name: str, spec: dict, retrain: bool) -> None:
    from drivelab.training.zoo import pack

    run_dir = ROOT / RUNS / name
    arguments = ["train", *spec["train"], "--runs-dir", str(RUNS), "--name", name]
    timing = None
    if not retrain and (run_dir / "model.zip").is_file():
        check_reuse(run_dir, arguments, ROOT)  # the card names this command
    if retrain and run_dir.exists():
        stop(f"--retrain: {run_dir} exists; remove it first (a retrained agent starts from nothing)")
    if retrain or not (run_dir / "model.zip").is_file():
        command, resumed = training_command(run_dir, arguments, ROOT)
        wall, cpu = drivelab(command)
        if not resumed:  # a resumed run's time is its last part's only: the card records none
            timing = {"train_wall_s": round(wall, 1), "train_cpu_s": round(cpu, 1), "machine": machine()}
            (run_dir / "train_timing.json").write_text(json.dumps(timing))
    pack(run_dir, name, spec["description"], "drivelab " + shlex.join(arguments), timing)


def tree() -> str:
    """The commit of the tree these scripts run from, marked when tracked files have changed."""

    def git(*arguments: str) -> str:
        return subprocess.run(["git", "-C", str(ROOT), *arguments], capture_output=True, text=True).stdout

    changed = git("status", "--porcelain", "--untracked-files=no").strip()
    return git("rev-parse", "--short", "HEAD").strip() + (" with uncommitted changes" if changed else "")


def verify(name: str, spec: dict, zoo_dir: Path | None = None) -> dict:
    """Train ``name``'s recipe afresh (into ``VERIFY_RUNS/name``, replacing an earlier check's run),
    pack it into a scratch zoo as ``train_and_pack`` would, and compare its model with the one in
    ``zoo_dir`` (default: the package's zoo); the zoo is not touched. Returns the check's record."""
    from drivelab.training.zoo import ZOO_DIR, model_differences, pack

    shipped = (ZOO_DIR if zoo_dir is None else zoo_dir) / name
    run_dir = ROOT / VERIFY_RUNS / name
    if run_dir.exists():
        shutil.rmtree(run_dir)
    arguments = ["train", *spec["train"], "--runs-dir", str(VERIFY_RUNS), "--name", name]
    wall, cpu = drivelab(arguments)
    with tempfile.TemporaryDirectory() as scratch:
        packed = pack(
            run_dir, name, spec["description"], "drivelab " + shlex.join(arguments), zoo_dir=Path(scratch)
        )
        differences = model_differences(shipped / "model.zip", packed / "model.zip")
        pinned = pinned_defaults(shipped / "model.zip", packed / "model.zip", differences)
    card = json.loads((shipped / "card.json").read_text())
    return {
        "name": name,
        "identical": not differences or pinned is not None,
        "differences": differences,
        "pinned_defaults": pinned,
        "shipped_command": card["training"]["command"],
        "command": "drivelab " + shlex.join(arguments),
        "tree": tree(),
        "date": time.strftime("%Y-%m-%d"),
        "machine": machine(),
        "train_wall_s": round(wall, 1),
        "train_cpu_s": round(cpu, 1),
    }


def pinned_defaults(shipped: Path, packed: Path, differences: dict) -> dict | None:
    """When the two models differ only in the hyper-parameters their SB3 record lists, and those
    that one lists and the other does not are the agent's own defaults (a recipe pinning SB3's
    ``clip_range=0.2`` trains the model of one that leaves it out): those values; else None."""
    import zipfile

    if differences != {"sb3.json": "other values of hyperparams"}:
        return None
    records = [json.loads(zipfile.ZipFile(path).read("sb3.json")) for path in (shipped, packed)]
    one, two = (record["hyperparams"] for record in records)
    defaults = agent_defaults(records[0]["algo"])
    extra = {k: one.get(k, two.get(k)) for k in set(one) ^ set(two)}
    if any(one[k] != two[k] for k in set(one) & set(two)) or any(
        k not in defaults or defaults[k] != v for k, v in extra.items()
    ):
        return None
    return dict(sorted(extra.items()))


def write_verification(records: list[dict], invocation: str, path: Path = VERIFY_RESULTS) -> Path:
    """Merge ``records`` into ``path``.json (by agent; the others are kept) and write ``path``.md."""
    json_path, md_path = path.with_suffix(".json"), path.with_suffix(".md")
    known = json.loads(json_path.read_text())["agents"] if json_path.is_file() else {}
    known.update({record["name"]: {**record, "invocation": invocation} for record in records})
    json_path.write_text(json.dumps({"agents": dict(sorted(known.items()))}, indent=2) + "\n")
    lines = [
        "# Shipped agents against their commands",
        "",
        "Each agent's recorded command, run afresh, trains the model the zoo ships: written by "
        "`python benchmarks/zoo_build.py [NAME ...] --verify`, which trains each recipe into "
        "`benchmarks/runs/zoo-verify/<name>`, packs it (float16 weights, no optimizer moments) into a "
        "scratch zoo and compares every member of its `model.zip` with the shipped one, value for value. "
        "The runs differ from the cards' commands only in `--runs-dir`. A model counts as the same when "
        "every member holds the same values, less the wall-clock time of SB3's episode records, or when "
        "the only difference is that one SB3 record lists hyper-parameters at the algorithm's own "
        "defaults (the PPO cards' commands pin highway-env's values since 2026-11-27, the runs that "
        "trained the shipped models left SB3's defaults unnamed).",
        "",
        "| agent | same model | what differs | tree | date | train min wall / CPU |",
        "|---|---|---|---|---|---|",
    ]
    for name, record in sorted(known.items()):
        differs = "; ".join(f"{member}: {how}" for member, how in record["differences"].items()) or "nothing"
        if record.get("pinned_defaults"):
            values = ", ".join(f"{k} {v}" for k, v in record["pinned_defaults"].items())
            differs = (
                f"the SB3 record of one lists {values}, the algorithm's defaults, which the other leaves out"
            )
        lines.append(
            f"| {name} | {'yes' if record['identical'] else 'no'} | {differs} | {record['tree']} | "
            f"{record['date']} | {record['train_wall_s'] / 60:.1f} / {record['train_cpu_s'] / 60:.1f} |"
        )
    lines += ["", "Commands (each agent's row was measured by the first; `machine` per row):", ""]
    for name, record in sorted(known.items()):
        lines.append(
            f"- {name}: `{record['invocation']}` ({record['machine']}); trained `{record['command']}`"
        )
    md_path.write_text("\n".join(lines) + "\n")
    return md_path


def measure(name: str, spec: dict, check_only: bool = False) -> None:
    import torch

    from drivelab.training.evaluate import report_name
    from drivelab.training.zoo import ZOO_DIR, add_evaluation, pinned_check_metrics

    torch.set_num_threads(1)

    out = REPORTS / name
    for protocol, template in [] if check_only else spec["measure"]:
        arguments = [part.format(name=name) for part in template] + ["--out", str(out)]
        wall, cpu = drivelab(arguments)
        maps = arguments[arguments.index("--maps") + 1] if "--maps" in arguments else None
        written = "nocrash.json" if protocol == "nocrash" else report_name(maps)
        report = json.loads((ROOT / out / written).read_text())
        report.pop("run", None)
        per_episode = report.pop("per_episode", None)
        evaluation = {
            "protocol": protocol,
            "episodes": report.get("episodes", report.get("episodes_per_level")),
            "command": "drivelab " + shlex.join(arguments),
            "machine": machine(),
            "date": time.strftime("%Y-%m-%d"),
            "wall_s": round(wall, 1),
            "cpu_s": round(cpu, 1),
            "metrics": report,
        }
        if per_episode is not None:
            evaluation["successes"] = int(sum(bool(e["success"]) for e in per_episode))
            evaluation["crashes"] = int(sum(bool(e["crashed"]) for e in per_episode))
        add_evaluation(name, evaluation)
    duration_s = spec.get("check_duration_s")
    check = {"episodes": CHECK_EPISODES, "command": f"drivelab enjoy {name} --episodes {CHECK_EPISODES}"}
    if duration_s is not None:
        check["duration_s"] = duration_s
        check["command"] = (
            f"the first {CHECK_EPISODES} episodes of `drivelab enjoy {name}`, each cut at {duration_s} s "
            "(tests/training/test_zoo.py)"
        )
    check["isa"] = PINNED_ISA_TEXT
    path = ZOO_DIR / name / "card.json"
    card = json.loads(path.read_text())
    card["check"] = check  # what check_metrics plays
    path.write_text(json.dumps(card, indent=2) + "\n")
    card["check"]["metrics"] = pinned_check_metrics(name)
    path.write_text(json.dumps(card, indent=2) + "\n")


def _percent(value: float | None) -> str:
    return "n/a" if value is None else f"{100 * value:.0f}"


def _per_km(value: float | None) -> str:
    return "n/a" if value is None else f"{value:.2f}"


def write_results() -> Path:
    """``benchmarks/results/zoo.md``: every shipped agent's card as tables (no computation)."""
    from drivelab.training.zoo import shipped_agents

    lines = [
        "# Shipped agents (`drivelab zoo`)",
        "",
        "Written by `python benchmarks/zoo_build.py` from the cards in `drivelab/zoo/*/card.json`. Every "
        "number was measured on the shipped (float16) weights with the command shown, one training seed "
        "each; the issue-19 targets ask for 3 seeds and >= 100 episodes.",
        "",
        "| agent | algorithm | scenario | observation | training steps | train min wall/CPU | model KiB |",
        "|---|---|---|---|---|---|---|",
    ]
    agents = shipped_agents()
    for agent in agents:
        card, training = agent.card, agent.card["training"]
        wall, cpu = training.get("train_wall_s"), training.get("train_cpu_s")
        time_text = "n/a" if wall is None else f"{wall / 60:.1f} / {cpu / 60:.1f}"
        lines.append(
            f"| {agent.name} | {card['algo']} | {card['env']} ({card['traffic']}) | {', '.join(card['obs'])} "
            f"| {training['steps']} | {time_text} | {card['model']['bytes'] / 1024:.0f} |"
        )
    lines += [
        "",
        "Evaluation set (the scenario's fixed evaluation episodes, `drivelab evaluate`; a row naming "
        "another protocol: the 100 unseen block maps, `--maps 1000:100`):",
        "",
        "| agent | episodes | success % | crash % | off-road per km | mean speed m/s | mean distance km "
        "| route completion % | return |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for agent in agents:
        for evaluation in agent.card["evaluations"]:
            if evaluation["protocol"] != "nocrash":
                m = evaluation["metrics"]
                label = "" if evaluation["protocol"] == "evaluation set" else f" ({evaluation['protocol']})"
                lines.append(
                    f"| {agent.name}{label} | {m['episodes']} | {_percent(m['success_rate'])} | "
                    f"{_percent(m['crash_rate'])} | {_per_km(m['off_road_per_km'])} | "
                    f"{m['mean_speed_mps']:.1f} | {m['mean_distance_km']:.2f} | "
                    f"{_percent(m['route_completion'])} | {m['mean_return']:.1f} ± {m['std_return']:.1f} |"
                )
    nocrash = [(a, e) for a in agents for e in a.card["evaluations"] if e["protocol"] == "nocrash"]
    if nocrash:
        lines += [
            "",
            "NoCrash on the test town (`drivelab benchmark nocrash`), success % per traffic level:",
            "",
            "| agent | episodes per level | empty | regular | dense |",
            "|---|---|---|---|---|",
        ]
        for agent, evaluation in nocrash:
            levels = evaluation["metrics"]["levels"]
            cells = " | ".join(
                _percent(levels[level]["success_rate"]) for level in ("empty", "regular", "dense")
            )
            lines.append(f"| {agent.name} | {evaluation['episodes']} | {cells} |")
    lines += ["", "What each agent is, the command that trained it and those that measured it:", ""]
    for agent in agents:
        training = agent.card["training"]
        lines.append(f"- {agent.name}: {agent.card['description']}.")
        lines.append(f"  - `{training['command']}` ({training.get('machine', 'n/a')})")
        for evaluation in agent.card["evaluations"]:
            lines.append(f"  - `{evaluation['command']}` ({evaluation['machine']}, {evaluation['date']})")
    path = ROOT / "benchmarks" / "results" / "zoo.md"
    path.write_text("\n".join(lines) + "\n")
    return path


def main() -> None:
    formatter = argparse.RawDescriptionHelpFormatter
    parser = Parser(description=__doc__, formatter_class=formatter)
    parser.add_argument("names", nargs="*", help=f"agents to build (default: all of {', '.join(AGENTS)})")
    parser.add_argument("--retrain", action="store_true", help="train again even if the run has its model")
    parser.add_argument("--measure-only", action="store_true", help="only re-measure the packed agents")
    parser.add_argument("--check-only", action="store_true", help="only record the packed agents' check")
    parser.add_argument("--verify", action="store_true", help="retrain and compare with the shipped models")
    args = parser.parse_args()
    unknown = [name for name in args.names if name not in AGENTS]
    if unknown:
        parser.error(f"unknown agent {unknown[0]!r} (known: {', '.join(AGENTS)})")
    if args.verify and (args.retrain or args.measure_only or args.check_only):
        parser.error(
            "--verify leaves the zoo as it is: it takes no --retrain, --measure-only or --check-only"
        )
    sys.path.insert(0, str(ROOT))
    os.chdir(ROOT)
    if args.verify:
        invocation = command_line()
        for name in args.names or AGENTS:
            record = verify(name, AGENTS[name])
            print(
                f"{name}: {'the shipped model' if record['identical'] else record['differences']}", flush=True
            )
            path = write_verification([record], invocation)
        print(f"wrote {path}")
        return
    for name in args.names or AGENTS:
        if not (args.measure_only or args.check_only):
            train_and_pack(name, AGENTS[name], args.retrain)
        measure(name, AGENTS[name], check_only=args.check_only)
        print(f"packed drivelab/zoo/{name}", flush=True)
    print(f"wrote {write_results()}")


if __name__ == "__main__":
    main()
