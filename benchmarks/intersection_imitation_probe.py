"""Can the intersection row's network, on its own observation, drive as the planner does? Behaviour
cloning and DAgger of the planner into the leaderboard's `ppo_own` network: evidence for issue 49's
"what limits a target", never a leaderboard row (it imitates; the rows learn by RL from scratch).

    nice -n 10 env OMP_NUM_THREADS=1 NUMBA_NUM_THREADS=1 \\
        .venv/bin/python benchmarks/intersection_imitation_probe.py [--episodes 1000] [--horizon 3]
        [--futures 0] [--dagger-rounds 3] [--dagger-episodes 1000] [--epochs 40] [--net-arch 64,64]
        [--features presence+x+y+vx+vy+cos_h+sin_h+cos_d+sin_d+accel]

The teacher is ``planner_probe.py``'s planner: before each decision it plays every sequence of the
next H meta-actions in the simulator and takes the first action of the best (``--futures 0``: the
exact model; M > 0: M sampled futures of the arrivals to come). The student is the network of the
leaderboard's intersection ``ppo_own`` row (ego-attention over the 15 nearest vehicles on the map's
axes with their intentions, the route's waypoints and the clock, observations normalised): a run of
the row's command for one rollout (8,192 steps) gives its shapes and config, and its weights are
replaced.

Round 0 clones the planner's own episodes (``--episodes`` training episodes, seeds 0, 1, …); each
DAgger round plays the next ``--dagger-episodes`` training episodes from seed 1,000 on (the same
episodes the planner drove where ``--episodes`` exceeds 1,000) with the current student (greedy,
as ``drivelab evaluate`` plays), has the planner label every state the student visited (the planner
replays the episode's seed and the student's actions, so it plans from that state), adds them to
the data and trains a fresh network on all of it. After each round the student plays the 100
evaluation episodes of the leaderboard (``drivelab evaluate RUN --episodes 100``).

What it tells: if the student reaches the planner's success, the row's observation and network can
hold a competent policy, and what holds the RL row back is how it learns; if not, the observation
or network is a limit too. ``--net-arch`` widens the student's attention embeddings (``-H
net_arch``; the row's: 64,64) and ``--features`` replaces the kinematics features the row reads.
Writes ``benchmarks/results/intersection_imitation_probe.{json,md}`` (a probe run again with the
same settings replaces its table) and the rounds' run directories under
``benchmarks/runs/intersection-imitation-probe/NET_ARCH[-FEATURES]/``.
"""

from __future__ import annotations

import json
import os
import platform
import re
import shlex
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import torch

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from intersection_probe import wilson_text  # noqa: E402
from leaderboard import INTERSECTION_PPO_OWN  # noqa: E402
from planner_probe import SCENARIOS, plan_action  # noqa: E402
from provenance import Parser, command_line, cpu_isa, positive, whole  # noqa: E402

RESULTS = ROOT / "benchmarks" / "results"
RUNS = ROOT / "benchmarks" / "runs" / "intersection-imitation-probe"
BASE_STEPS = 8192  # one rollout of the row (128 steps x 64 worlds): its network's shapes and config
DAGGER_SEED_START = 1_000  # the first DAgger round's first episode seed
VALIDATION_SHARE = 0.1  # of the episodes, held out for the accuracy


def widths(text: str) -> list[int]:
    """Comma-separated layer widths (each at least 1), e.g. 128,128."""
    return [whole(1)(part) for part in text.split(",")]


def base_command(run_dir: Path, net_arch: str, features: str | None = None) -> list[str]:
    """``drivelab train`` of the leaderboard row for one rollout, into ``run_dir``, its attention
    embeddings ``net_arch`` wide, reading the kinematics ``features`` (None: the row's)."""
    args = shlex.split(INTERSECTION_PPO_OWN) + ["-H", f"net_arch={net_arch}"]
    if features is not None:
        obs = args.index("--obs") + 1
        args[obs], count = re.subn(r"features=[a-z_+]+", f"features={features}", args[obs])
        assert count == 1, args[obs]
    values = {"--steps": str(BASE_STEPS), "--eval-every": str(BASE_STEPS), "--eval-episodes": "1"}
    for i, arg in enumerate(args[:-1]):
        if arg in values:
            args[i + 1] = values[arg]
    return [sys.executable, "-m", "drivelab", "train", *args, "--seed", "0",
            "--runs-dir", str(run_dir.parent.relative_to(ROOT)), "--name", run_dir.name]  # fmt: skip


class Data:
    """The labelled states: each observation part stacked, the planner's actions, each state's episode."""

    def __init__(self) -> None:
        self.obs: dict[str, list[np.ndarray]] = {}
        self.actions: list[int] = []
        self.episodes: list[int] = []

    def add(self, obs: dict, action: int, episode: int) -> None:
        for key, value in obs.items():
            self.obs.setdefault(key, []).append(np.asarray(value))
        self.actions.append(action)
        self.episodes.append(episode)

    def tensors(self, rows: np.ndarray) -> tuple[dict[str, torch.Tensor], torch.Tensor]:
        obs = {key: torch.from_numpy(np.stack(values)[rows]) for key, values in self.obs.items()}
        return obs, torch.as_tensor(np.asarray(self.actions)[rows], dtype=torch.long)

    def __len__(self) -> int:
        return len(self.actions)


def labelled_episode(planner_env, student_env, seed: int, args, data: Data, agent=None) -> dict:
    """Training episode ``seed`` played by the planner (``agent`` None) or by the student ``agent``
    (greedy); every state's observation (the row's) joins ``data`` with the planner's action for it
    (the planner replays the episode's seed and the actions taken, so it plans from that state).
    The episode's metrics, from the row's own environment."""
    taken: list[int] = []
    obs, _ = student_env.reset(options={"episode_seed": seed})
    while True:
        label = plan_action(planner_env, "intersection", seed, taken, args.horizon, futures=args.futures)
        assert label is not None, "the planner's model ended the episode before the row's environment"
        data.add(obs, label, seed)
        action = label if agent is None else int(agent.predict(obs, deterministic=True)[0])
        taken.append(action)
        obs, _, terminated, truncated, info = student_env.step(action)
        if terminated or truncated:
            return info["episode_metrics"]


def train_student(agent, initial: dict, data: Data, args, seed: int) -> dict:
    """A fresh network (the base run's weights) trained by cross-entropy on the planner's actions,
    the observation statistics computed from the data; the held-out episodes' accuracy."""
    torch.manual_seed(seed)
    policy = agent.policy
    policy.load_state_dict(initial)
    episodes = np.unique(data.episodes)
    held = np.random.default_rng(seed).permutation(episodes)[: max(1, int(len(episodes) * VALIDATION_SHARE))]
    validation = np.isin(np.asarray(data.episodes), held)
    train_rows, valid_rows = np.flatnonzero(~validation), np.flatnonzero(validation)
    obs, actions = data.tensors(train_rows)
    valid_obs, valid_actions = data.tensors(valid_rows)
    policy.norm.count.zero_()
    policy.norm.update(obs)
    optimizer = torch.optim.Adam(policy.parameters(), lr=args.learning_rate)
    generator = torch.Generator().manual_seed(seed)
    best = (-1.0, None)
    for _ in range(args.epochs):
        policy.train()
        for rows in torch.randperm(len(actions), generator=generator).split(args.batch_size):
            logits, _ = policy({key: value[rows] for key, value in obs.items()})
            loss = torch.nn.functional.cross_entropy(logits, actions[rows])
            optimizer.zero_grad()
            loss.backward()
            torch.nn.utils.clip_grad_norm_(policy.parameters(), 1.0)
            optimizer.step()
        with torch.no_grad():
            accuracy = float((policy(valid_obs)[0].argmax(-1) == valid_actions).float().mean())
        if accuracy > best[0]:  # the epoch with the best held-out accuracy is kept
            best = (accuracy, {k: v.clone() for k, v in policy.state_dict().items()})
    policy.load_state_dict(best[1])
    with torch.no_grad():
        train_accuracy = float((policy(obs)[0].argmax(-1) == actions).float().mean())
    return {"train_accuracy": train_accuracy, "validation_accuracy": best[0],
            "train_states": len(train_rows), "validation_states": len(valid_rows)}  # fmt: skip


def outcome_counts(metrics: list[dict]) -> dict:
    return {"episodes": len(metrics), "success": sum(m["success"] > 0 for m in metrics),
            "crash": sum(m["collisions"] > 0 for m in metrics)}  # fmt: skip


def main() -> None:
    parser = Parser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=whole(), default=1000, help="the planner's own episodes (round 0)")
    parser.add_argument("--horizon", type=whole(), default=3, help="the planner's horizon H (decisions)")
    parser.add_argument("--futures", type=whole(0), default=0, help="sampled futures (0: the exact model)")
    parser.add_argument("--dagger-rounds", type=whole(0), default=3)
    parser.add_argument("--dagger-episodes", type=whole(), default=1000, help="episodes per DAgger round")
    parser.add_argument("--epochs", type=whole(), default=40)
    parser.add_argument("--batch-size", type=whole(), default=256)
    parser.add_argument("--learning-rate", type=positive, default=1e-3)
    parser.add_argument("--eval-episodes", type=whole(), default=100)
    parser.add_argument("--net-arch", type=widths, default=[64, 64], help="attention embeddings' widths")
    parser.add_argument(
        "--features", default=None, help="the kinematics features, '+'-joined (default: the row's)"
    )
    args = parser.parse_args()
    net_arch = ",".join(map(str, args.net_arch))
    if args.learning_rate > 1:
        parser.error("--learning-rate must be at most 1")
    if 3**args.horizon * max(args.futures, 1) > 3**7:
        parser.error("--horizon, --futures: more than 3**7 worlds per decision")

    from drivelab.envs.core import DriveEnv
    from drivelab.envs.vector import VectorDriveEnv
    from drivelab.training.checkpoints import load_agent
    from drivelab.training.evaluate import evaluate_run, load_run_config

    torch.set_num_threads(1)
    if args.features is not None:
        from drivelab.perception.kinematics import feature_names

        try:
            feature_names(args.features)
        except ValueError as exc:
            parser.error(str(exc))
    runs = RUNS / (net_arch.replace(",", "x") + ("" if args.features is None else f"-{args.features}"))
    if runs.exists():
        shutil.rmtree(runs)
    base = runs / "base"
    subprocess.run(
        base_command(base, net_arch, args.features), check=True, cwd=ROOT, stdout=subprocess.DEVNULL
    )
    config = load_run_config(base)
    student_env = DriveEnv(**config.eval_env_kwargs())
    planner_env = VectorDriveEnv(3**args.horizon * max(args.futures, 1), "intersection",
                                 **SCENARIOS["intersection"])  # fmt: skip
    agent = load_agent(base, config)
    initial = {k: v.clone() for k, v in agent.policy.state_dict().items()}
    data, rounds = Data(), []
    for round_ in range(args.dagger_rounds + 1):
        start = time.perf_counter()
        if round_ == 0:
            seeds, player, who = range(args.episodes), None, "planner"
        else:
            first = DAGGER_SEED_START + (round_ - 1) * args.dagger_episodes
            seeds, player = range(first, first + args.dagger_episodes), agent
            who = "student (greedy), planner-labelled"
        played = [labelled_episode(planner_env, student_env, seed, args, data, player) for seed in seeds]
        collected_s = time.perf_counter() - start
        fit = train_student(agent, initial, data, args, round_)
        run = runs / f"round-{round_}"
        shutil.copytree(base, run, ignore=shutil.ignore_patterns("eval*.json", "videos"))
        agent.save(run / "model.zip")
        report = evaluate_run(run, episodes=args.eval_episodes)
        rounds.append({
            "round": round_, "played_by": who, "played": outcome_counts(played), "states": len(data),
            **fit, "collect_s": round(collected_s, 1), "wall_s": round(time.perf_counter() - start, 1),
            "evaluation": {"episodes": report["episodes"], "success_rate": report["success_rate"],
                           "crash_rate": report["crash_rate"], "mean_speed_mps": report["mean_speed_mps"]},
        })  # fmt: skip
        print(json.dumps(rounds[-1]), flush=True)
    probe = {
        "command": command_line(),
        "machine": f"{cpu_isa()}, {os.cpu_count()} cores, Python {platform.python_version()}",
        "date": time.strftime("%Y-%m-%d"),
        "settings": {**vars(args), "net_arch": net_arch},
        "base_run": " ".join(shlex.quote(a) for a in base_command(base, net_arch, args.features)[3:]),
        "rounds": rounds,
    }
    path = RESULTS / "intersection_imitation_probe.json"
    result = json.loads(path.read_text()) if path.exists() else {"probes": []}
    settings = probe["settings"]  # a probe run again with the same settings is replaced
    result["probes"] = [p for p in result["probes"] if p["settings"] != settings] + [probe]
    RESULTS.mkdir(exist_ok=True)
    path.write_text(json.dumps(result, indent=1))
    (RESULTS / "intersection_imitation_probe.md").write_text(markdown(result))
    print(markdown(result))


def markdown(result: dict) -> str:
    lines = [
        "# Can the intersection row's network drive as the planner does? Imitation as a probe",
        "",
        "Evidence for issue 49 (what limits the intersection's RL row), not a leaderboard row: the "
        "student imitates. The teacher is `planner_probe.py`'s planner. The student is the network "
        "and observation of the leaderboard's intersection `ppo_own` row (its command run for one "
        "rollout gives the shapes), trained by cross-entropy on the planner's actions, the epoch "
        "with the best accuracy on held-out episodes kept. Round 0 clones the planner's own "
        "episodes; each DAgger round adds the states the student visits (greedy) in training "
        "episodes, labelled by the planner, and trains a fresh network on all of it. "
        "Evaluation: the 100 evaluation episodes of the leaderboard (`drivelab evaluate RUN "
        "--episodes 100`), greedy; rates with their 90 % Wilson interval.",
    ]
    for probe in result["probes"]:
        lines += probe_table(probe)
    return "\n".join(lines) + "\n"


def probe_table(probe: dict) -> list[str]:
    s = probe["settings"]
    teacher = "the exact model" if not s["futures"] else f"{s['futures']} sampled futures of the arrivals"
    lines = [
        "",
        f"## Attention embeddings {s['net_arch']} wide, "
        + ("the row's features" if s.get("features") is None else f"features {s['features']}"),
        "",
        f"Command: `{probe['command']}`  ",
        f"Machine: {probe['machine']}; {probe['date']}.  ",
        f"Teacher: the planner with a horizon of {s['horizon']} decisions and {teacher}. Round 0: "
        f"the planner's episodes of training seeds 0 to {s['episodes'] - 1}; DAgger rounds of "
        f"{s['dagger_episodes']} episodes each, from seed {DAGGER_SEED_START:,} on; "
        f"{s['epochs']} epochs, minibatch {s['batch_size']}, Adam "
        f"{s['learning_rate']:g}. The student's run: `drivelab {probe['base_run']}`.",
        "",
        "| round | episodes played (by) | their success / crash | labelled states | "
        "accuracy train / held out | evaluation success % | crash % | mean speed m/s | wall s |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for r in probe["rounds"]:
        played, ev = r["played"], r["evaluation"]
        n = ev["episodes"]
        success, crash = round(ev["success_rate"] * n), round(ev["crash_rate"] * n)
        lines.append(
            f"| {r['round']} | {played['episodes']} ({r['played_by']}) | {played['success']} / "
            f"{played['crash']} | {r['states']:,} | "
            f"{r['train_accuracy']:.3f} / {r['validation_accuracy']:.3f} | "
            f"{wilson_text(success, n)} | {wilson_text(crash, n)} | "
            f"{ev['mean_speed_mps']:.1f} | {r['wall_s']:.0f} |"
        )
    return lines


if __name__ == "__main__":
    main()
