"""Tiny runs for the run-directory tests: a PPO config on an empty road that trains in seconds,
a fingerprint of a folder tree, a zip member rewritten, and the check of a refusal's one
``error:`` line."""

import hashlib
import os
import zipfile
from pathlib import Path

from drivelab.config import RunConfig, build_config

TINY = {"n_steps": 64, "batch_size": 32, "n_epochs": 1, "policy_kwargs": {"net_arch": [16]}}


def tiny_config(**overrides) -> RunConfig:
    """PPO on an empty road: 128 steps, checkpoints every 64, one evaluation episode at 128."""
    values = {
        "algo": "ppo",
        "traffic": "empty",
        "steps": 128,
        "seed": 1,
        "name": "r",
        "eval_every": 128,
        "eval_episodes": 1,
        "checkpoint_every": 64,
        "hyperparams": TINY,
        "env_options": {"duration_s": 8},
    }
    return build_config({**values, **overrides})


def tree(root: Path) -> dict[str, str]:
    """Every file, folder and link under ``root``: relative path → sha256 of the file ("dir" for a
    folder, "link to TARGET" for a symbolic link, not followed)."""
    found = {}
    for path in sorted(root.rglob("*")):
        if path.is_symlink():
            found[str(path.relative_to(root))] = f"link to {os.readlink(path)}"
        elif path.is_dir():
            found[str(path.relative_to(root))] = "dir"
        else:
            found[str(path.relative_to(root))] = hashlib.sha256(path.read_bytes()).hexdigest()
    return found


def error_line(output: str, *fragments: str) -> str:
    """The one line of ``output``, an ``error:`` line holding every fragment (AssertionError else)."""
    lines = output.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), output
    assert "Traceback" not in output
    for fragment in fragments:
        assert fragment in lines[0], lines[0]
    return lines[0]


def rewrite_member(path: Path, member: str, data: bytes) -> None:
    """Replace (or add) ``member`` of the zip file ``path`` with ``data``."""
    with zipfile.ZipFile(path) as archive:
        members = {name: archive.read(name) for name in archive.namelist()}
    members[member] = data
    with zipfile.ZipFile(path, "w") as archive:
        for name, value in members.items():
            archive.writestr(name, value)


def met_observations(env, count: int) -> list:
    """``count`` observations of ``env`` met along random actions (seeded; episodes restarted as
    they end)."""
    env.action_space.seed(0)
    obs, _ = env.reset(seed=0)
    found = [obs]
    while len(found) < count:
        obs, _, terminated, truncated, _ = env.step(env.action_space.sample())
        if terminated or truncated:
            obs, _ = env.reset()
        found.append(obs)
    return found


def train_then_kill_back_to(
    monkeypatch, tmp_path: Path, config: RunConfig, steps: int, then=None
) -> tuple[Path, Path]:
    """(run directory, reference): ``config`` trained to the end in ``tmp_path/runs`` (``then``
    called with the run directory, if given), copied whole as the reference, then put back as a run
    killed after its checkpoint of ``steps`` that had logged past it: that checkpoint in place of
    the final one, no model.zip, the logs as written."""
    import shutil

    from drivelab.training import run as run_module

    kept, checkpoint = tmp_path / "kept", run_module.RunCallback.checkpoint

    def keep(self, snapshot):
        checkpoint(self, snapshot)
        if snapshot.steps == steps:
            shutil.copytree(self.run_dir / "checkpoints", kept)

    monkeypatch.setattr(run_module.RunCallback, "checkpoint", keep)
    run_dir = run_module.train(config, tmp_path / "runs")
    monkeypatch.undo()
    if then is not None:
        then(run_dir)
    reference = tmp_path / "reference"
    shutil.copytree(run_dir, reference)
    shutil.rmtree(run_dir / "checkpoints")
    shutil.copytree(kept, run_dir / "checkpoints")
    (run_dir / "model.zip").unlink()  # killed before the end
    return run_dir, reference
