"""``drivelab convert-run``: rewrite a trusted run directory of the old pickle format.

Loading the pickles of earlier drivelab versions can execute code, so drivelab refuses them
everywhere else; this module, the one place that unpickles, loads each old file the old way and
writes it again in the safe format (``agents/storage.py``), for a directory the user trusts."""

from __future__ import annotations

import io
import json
import os
import pickle
import zipfile
from pathlib import Path

import torch

from drivelab.agents.registry import get_algo
from drivelab.agents.storage import is_old_format, space_to_json
from drivelab.config import RunConfig
from drivelab.errors import UsageError


def _old_sb3(config: RunConfig, path: Path):
    """An SB3 model from SB3's pickle format, as drivelab's safe-saving class."""
    model = get_algo(config.algo).agent_class().load(path, device="cpu")
    model.drivelab_hyperparams = json.loads(json.dumps(dict(config.hyperparams)))
    return model


def _old_own(config: RunConfig, path: Path):
    """An own agent from the old zip (``spaces.pkl`` and a pickled ``state.pt``)."""
    cls = get_algo(config.algo).agent_class()
    with zipfile.ZipFile(path) as archive:
        meta = json.loads(archive.read("agent.json"))
        observation_space, action_space = pickle.loads(archive.read("spaces.pkl"))
        state = torch.load(io.BytesIO(archive.read("state.pt")), map_location="cpu", weights_only=False)
    agent = cls(observation_space, action_space, meta["seed"], meta["hyperparams"], None)
    agent.num_timesteps = int(meta["num_timesteps"])
    agent.rng.bit_generator.state = meta["rng"]
    agent.generator.set_state(state.pop("generator"))
    agent._set_state(state)
    space_to_json(observation_space)  # fails now, before anything is written, for an odd space
    return agent


def _old_replay(model, path: Path) -> None:
    """Put the pickled replay ``path`` into ``model``."""
    from stable_baselines3.common.off_policy_algorithm import OffPolicyAlgorithm

    if isinstance(model, OffPolicyAlgorithm):
        OffPolicyAlgorithm.load_replay_buffer(model, path)
    else:
        with open(path, "rb") as handle:
            model.replay_buffer = pickle.load(handle)


def _save(save, path: Path) -> None:
    """``save(tmp)`` then rename over ``path``."""
    tmp = path.with_name(path.stem + ".convert.tmp" + path.suffix)
    try:
        save(tmp)
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)


def _check_whole(run_dir: Path) -> None:
    """A UsageError, before anything is converted, when the model or the checkpoint is not a whole
    file of either format (truncated, corrupted), so that none is called "already safe"."""
    from drivelab.training.checkpoints import file_sha256

    folder = run_dir / "checkpoints"
    for path in (run_dir / "model.zip", folder / "latest.zip"):
        if path.exists() and not zipfile.is_zipfile(path):
            relative = path.relative_to(run_dir).as_posix()
            raise UsageError(
                f"cannot convert {str(run_dir)!r}: {relative} is not a model zip of either format "
                "(truncated or corrupted)"
            )
    if not (folder / "latest.zip").exists():
        return
    try:
        expected = json.loads((folder / "latest.json").read_text())["sha256"]
    except (OSError, ValueError, KeyError, TypeError):
        raise UsageError(
            f"cannot convert {str(run_dir)!r}: its checkpoint manifest checkpoints/latest.json "
            "is missing or corrupted"
        ) from None
    if file_sha256(folder / "latest.zip") != expected:
        raise UsageError(
            f"cannot convert {str(run_dir)!r}: checkpoints/latest.zip is truncated or corrupted "
            "(checksum mismatch with checkpoints/latest.json)"
        )


def convert_run(run_dir: str | Path) -> list[Path]:
    """Rewrite the old-format model, checkpoint and replay of ``run_dir``; the files rewritten."""
    from drivelab.training.checkpoints import file_sha256, load_agent
    from drivelab.training.evaluate import load_run_config

    run_dir = Path(run_dir)
    config = load_run_config(run_dir)
    family = get_algo(config.algo).family
    if family == "qlearning":
        return []  # Q-learning always saved JSON and numeric arrays
    load_old = _old_own if family == "own" else _old_sb3
    folder, written = run_dir / "checkpoints", []
    checkpoint, replay = folder / "latest.zip", folder / "replay.pkl"
    _check_whole(run_dir)
    try:
        if (run_dir / "model.zip").is_file() and is_old_format(run_dir / "model.zip"):
            _save(load_old(config, run_dir / "model.zip").save, run_dir / "model.zip")
            written.append(run_dir / "model.zip")
        if checkpoint.is_file() and (is_old_format(checkpoint) or replay.is_file()):
            manifest = json.loads((folder / "latest.json").read_text())
            if is_old_format(checkpoint):
                model = load_old(config, checkpoint)
            else:  # a safe checkpoint beside an old replay
                model = load_agent(run_dir, config, path=checkpoint)
            _save(model.save, checkpoint)
            manifest["sha256"] = file_sha256(checkpoint)
            if replay.is_file():
                _old_replay(model, replay)
                _save(model.save_replay_buffer, folder / "replay.npz")
                manifest["replay_sha256"] = file_sha256(folder / "replay.npz")
            (folder / "latest.tmp.json").write_text(json.dumps(manifest, indent=2))
            os.replace(folder / "latest.tmp.json", folder / "latest.json")
            replay.unlink(missing_ok=True)
            written += [checkpoint, folder / "latest.json"]
    except OSError as exc:
        raise UsageError(f"cannot convert {str(run_dir)!r}: {exc.strerror or exc}") from None
    except Exception as exc:  # not a drivelab run of the old format
        raise UsageError(f"cannot convert {str(run_dir)!r}: {type(exc).__name__}: {exc}") from None
    return written
