"""``drivelab export``: a run's SB3 model in stable-baselines3's own format, for ``PPO.load``.

drivelab saves SB3 models without pickles, which SB3's ``load`` cannot read. The export writes what
SB3's own ``save`` writes, cloudpickled objects included, so the exported file is for the user's
own, trusted use; drivelab never reads it back, and it may not be written into a run directory."""

from __future__ import annotations

from pathlib import Path

from drivelab.errors import UsageError

SB3_CLASSES = {"dqn": "DQN", "ppo": "PPO", "a2c": "A2C", "sac": "SAC"}  # drivelab name → SB3 class


def export_sb3(target: str | Path, out: str | Path) -> tuple[Path, str]:
    """Write the SB3 model of ``target`` (a run directory or a shipped agent's name) to ``out``, a
    ``.zip`` in stable-baselines3's own format, whole or not at all; (the path written, the SB3
    class that reads it). A UsageError, before anything is written, for a non-SB3 run or an ``out``
    that is not a new ``.zip`` outside the run directory."""
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
