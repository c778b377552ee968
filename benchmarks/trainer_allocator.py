"""Training with glibc's malloc thresholds left at their defaults, against drivelab's (freed memory
kept for reuse, ``drivelab/training/allocator.py``): wall, CPU, kernel time and page faults.

    OMP_NUM_THREADS=1 NUMBA_NUM_THREADS=1 .venv/bin/python benchmarks/trainer_allocator.py \
        [--repeats 3] [--scale 1.0]

Two recipes of the leaderboard, shortened: the town's bird's-eye PPO (a CNN on 48 x 48 images,
minibatches of 1,024) and highway's PPO (a 64 x 64 MLP). Each is trained by ``drivelab train`` in a
fresh process, once as shipped and once with ``keep_freed_memory`` made a no-op; repeats
interleave the two; medians. Each pair's trained weights are compared byte for byte: where the
memory lies must not change what is learnt. Writes ``benchmarks/results/trainer_allocator.{json,md}``.
"""

from __future__ import annotations

import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
import zipfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from leaderboard import ENTRIES  # noqa: E402
from provenance import Parser, command_line, positive, provenance, whole  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
RESULTS = ROOT / "benchmarks" / "results"


def _recipe(scenario: str, name: str) -> tuple[str, ...]:
    """The leaderboard entry's ``drivelab train`` arguments."""
    return next(e.train for e in ENTRIES if (e.scenario, e.name) == (scenario, name))


RECIPES = {  # name: (drivelab train arguments, steps at scale 1)
    "town, bird's-eye view (CNN)": (_recipe("town", "ppo_own (image)"), 131_072),
    "highway, kinematics (MLP)": (_recipe("highway", "ppo_own"), 131_072),
}
# ``drivelab train`` with the thresholds left as glibc sets them
DEFAULT_MALLOC = (
    "import sys; import drivelab.training.run as run; run.keep_freed_memory = lambda: False; "
    "from drivelab.cli import main; sys.argv[0] = 'drivelab'; main()"
)
KEPT_MALLOC = "import sys; from drivelab.cli import main; sys.argv[0] = 'drivelab'; main()"


def _arguments(recipe: tuple[str, ...], steps: int, runs: Path, name: str) -> list[str]:
    """The recipe's ``drivelab train`` arguments for ``steps`` steps, no evaluation, into ``runs``."""
    words = list(recipe)
    for option, value in (("--steps", str(steps)), ("--eval-every", "0")):
        words[words.index(option) + 1] = value
    return ["train", *words, "--seed", "0", "--name", name, "--runs-dir", str(runs)]


def measure(recipe: tuple[str, ...], steps: int, code: str, runs: Path, name: str) -> dict:
    """Train once in a fresh process (one thread); its times, faults and trained weights' bytes."""
    env = {**os.environ, "OMP_NUM_THREADS": "1", "NUMBA_NUM_THREADS": "1", "CI": "true"}
    before, start = resource.getrusage(resource.RUSAGE_CHILDREN), time.perf_counter()
    subprocess.run([sys.executable, "-c", code, *_arguments(recipe, steps, runs, name)], check=True,
                   env=env, cwd=ROOT, stdout=subprocess.DEVNULL)  # fmt: skip
    wall = time.perf_counter() - start
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    with zipfile.ZipFile(runs / name / "model.zip") as archive:
        weights = b"".join(archive.read(member) for member in sorted(archive.namelist()))
    return {
        "wall_s": wall,
        "user_s": after.ru_utime - before.ru_utime,
        "kernel_s": after.ru_stime - before.ru_stime,
        "page_faults": after.ru_minflt - before.ru_minflt,
        "weights": weights,
    }


def main() -> None:
    parser = Parser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=whole(), default=3)
    parser.add_argument("--scale", type=positive, default=1.0, help="steps = each recipe's x SCALE")
    args = parser.parse_args()
    rows = []
    with tempfile.TemporaryDirectory() as folder:
        for recipe_name, (recipe, steps) in RECIPES.items():
            steps = max(int(steps * args.scale), 1)
            runs: dict[str, list[dict]] = {"default": [], "kept": []}
            for repeat in range(args.repeats):
                for variant, code in (("default", DEFAULT_MALLOC), ("kept", KEPT_MALLOC)):
                    name = f"{len(rows)}-{variant}-{repeat}"
                    runs[variant].append(measure(recipe, steps, code, Path(folder), name))
                    shown = {k: round(v, 1) for k, v in runs[variant][-1].items() if k != "weights"}
                    print(recipe_name, variant, shown, flush=True)
            row = {"recipe": recipe_name, "steps": steps}
            for variant, measured in runs.items():
                for key in ("wall_s", "user_s", "kernel_s", "page_faults"):
                    row[f"{variant}_{key}"] = statistics.median(m[key] for m in measured)
                row[f"{variant}_steps_per_s"] = steps / row[f"{variant}_wall_s"]
            row["speedup"] = row["default_wall_s"] / row["kept_wall_s"]
            row["same_weights"] = all(
                d["weights"] == k["weights"] for d, k in zip(runs["default"], runs["kept"], strict=True)
            )
            rows.append(row)
    result = {**provenance(command_line()), "repeats": args.repeats, "rows": rows}
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / "trainer_allocator.json").write_text(json.dumps(result, indent=2) + "\n")
    lines = [
        "# Training with freed memory kept for reuse",
        "",
        f"Command: `{result['command']}`  ",
        f"Machine: {result['machine']}; date {result['date']}; {args.repeats} interleaved repeats "
        "(medians), one torch and one numba thread, each run a fresh `drivelab train` process.",
        "",
        "glibc's defaults serve every block above 32 MiB with an mmap of its own, returned on free,",
        "and trim the heap's top; drivelab raises both thresholds while training",
        "(`drivelab/training/allocator.py`). Kernel time and page faults are the training process's.",
        "",
        "| recipe | steps | glibc's defaults: steps/s | kept: steps/s | speed-up "
        "| kernel s (defaults / kept) | page faults (defaults / kept) | same weights |",
        "|---|---|---|---|---|---|---|---|",
        *[
            f"| {r['recipe']} | {r['steps']:,} | {r['default_steps_per_s']:,.0f} "
            f"| {r['kept_steps_per_s']:,.0f} | {r['speedup']:.2f}x "
            f"| {r['default_kernel_s']:.1f} / {r['kept_kernel_s']:.1f} "
            f"| {r['default_page_faults']:,.0f} / {r['kept_page_faults']:,.0f} "
            f"| {'yes' if r['same_weights'] else 'NO'} |"
            for r in rows
        ],
        "",
        "Steps/s include each process's start (imports, compiled kernels loaded, worlds built).",
        "",
    ]
    (RESULTS / "trainer_allocator.md").write_text("\n".join(lines))
    print("\n".join(lines))


if __name__ == "__main__":
    main()
