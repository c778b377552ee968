"""``drivelab export``: a run's SB3 model in stable-baselines3's own format, for ``PPO.load``.

drivelab saves SB3 models without pickles (``agents/sb3.py``), which SB3's ``load`` cannot read
("No data found in the saved file"). The export writes the file SB3's own ``save`` writes: a zip
whose ``data`` holds cloudpickled objects (spaces, schedules, the policy class) that SB3's
``load`` unpickles. So the exported file is for the user's own, trusted use: loading one runs what
it holds. drivelab never reads it (nor any other pickle) back: its runs stay in the safe format,
and the export may not be written into a run directory, where it would be taken for the run's own
model.

The model is loaded as every drivelab command loads it (nothing unpickled), then saved by SB3's
``BaseAlgorithm.save``; ``stable_baselines3.<ALGO>.load`` reads it and, given the same
observations, returns the same actions as ``drivelab.load``'s model.
"""

from __future__ import annotations

from pathlib import Path

from drivelab.errors import UsageError

SB3_CLASSES = {"dqn": "DQN", "ppo": "PPO", "a2c": "A2C", "sac": "SAC"}  # drivelab name → SB3 class


def export_sb3(target: str | Path, out: str | Path) -> tuple[Path, str]:
    """Write the SB3 model of ``target`` (a run directory or a shipped agent's name) to ``out``, a
    ``.zip`` in stable-baselines3's own format; (the path written, the SB3 class that reads it).

    Refused with a UsageError, before anything is written: a run of an algorithm other than SB3's,
    ``out`` not ending in ``.zip``, a folder, in a folder that does not exist, or inside the run
    directory. The file is written whole or not at all (a temporary renamed over ``out``)."""
    from drivelab.agents.sb3 import SafeSave
    from drivelab.training.evaluate import check_output_file, load_run_config
    from drivelab.training.safe_files import replacing
    from drivelab.training.zoo import load_trained, resolve

    run_dir, _ = resolve(target)
    out = Path(out)
    if out.suffix.lower() != ".zip":
        raise UsageError(
            f"{str(out)!r} must end in .zip (stable-baselines3's load adds .zip to a name without it)"
        )
    if out.is_dir():
        raise UsageError(f"{str(out)!r} is a directory; give the path of the .zip to write")
    if out.absolute().parent.resolve().is_relative_to(run_dir.resolve()):
        raise UsageError(
            f"{str(out)!r} is inside the run directory {str(run_dir)!r}: an exported model holds pickles, "
            "and a run directory holds only drivelab's safe files; write it elsewhere"
        )
    check_output_file(out, "the export")
    config = load_run_config(run_dir)
    if config.algo not in SB3_CLASSES:
        raise UsageError(
            f"{str(target)!r} holds a {config.algo!r} agent, drivelab's own: only runs of "
            f"stable-baselines3's algorithms ({', '.join(SB3_CLASSES)}) export to its format"
        )
    model = load_trained(run_dir).agent
    # SB3's own save (the class under drivelab's SafeSave); the attribute drivelab adds stays out
    with replacing(out, out.with_name(f".{out.stem}.tmp.zip")) as temporary, temporary.open("wb") as handle:
        super(SafeSave, model).save(handle, exclude=["drivelab_hyperparams"])
    return out, SB3_CLASSES[config.algo]
