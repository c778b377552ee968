"""A run directory's checkpoints and final model: written, verified and loaded (nothing unpickled)."""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import time
import zipfile
from pathlib import Path

from drivelab.agents.counters import is_count
from drivelab.agents.registry import get_algo
from drivelab.agents.storage import NonFiniteParametersError, OldFormatError, is_old_format
from drivelab.config import RunConfig
from drivelab.errors import UsageError
from drivelab.training.safe_files import WriteError, make_folder, temporary_file, write_failure

REPLAY_LIMIT_BYTES = 512 * 2**20  # larger replay buffers are not checkpointed (resume refills)


def file_sha256(path: Path) -> str:
    """Hex SHA-256 of a file's bytes."""
    with path.open("rb") as handle:
        return hashlib.file_digest(handle, "sha256").hexdigest()


def save_checkpoint(model, run_dir: Path, config: RunConfig, save_replay: bool) -> Path:
    """Write checkpoints/latest.zip (and replay.npz) with a manifest that lets resume verify them.

    Every file is written into a temporary and renamed only when all are written, the manifest last:
    a failed write keeps the previous checkpoint and is a one-line UsageError. A kill between the
    renames is finished by ``verify_checkpoint`` (``_finish_renames``)."""
    folder = run_dir / "checkpoints"
    what = f"checkpoint in {str(folder)!r}"
    renames = {folder / "latest.tmp.zip": folder / "latest.zip"}
    try:
        make_folder(folder)
        with contextlib.ExitStack() as written:  # every temporary removed if one fails
            model_tmp = written.enter_context(temporary_file(folder / "latest.tmp.zip"))
            model.save(model_tmp)
            manifest = {
                "steps": int(model.num_timesteps),
                "sha256": file_sha256(model_tmp),
                "config_identity": config.identity(),
                "replay_buffer": False,
                "saved_at": time.strftime("%Y-%m-%dT%H:%M:%S"),
            }
            if save_replay and _replay_fits(model):
                replay_tmp = written.enter_context(temporary_file(folder / "replay.tmp.npz"))
                renames[replay_tmp] = folder / "replay.npz"
                model.save_replay_buffer(replay_tmp)
                manifest.update(replay_buffer=True, replay_sha256=file_sha256(replay_tmp))
            manifest_tmp = written.enter_context(temporary_file(folder / "latest.tmp.json"))
            renames[manifest_tmp] = folder / "latest.json"  # renamed last: the commit
            manifest_tmp.write_text(json.dumps(manifest, indent=2))
    except NonFiniteParametersError as exc:  # nan weights: the previous checkpoint stands
        raise UsageError(f"checkpoint in {str(folder)!r} {exc}") from None
    except WriteError as exc:
        raise WriteError(what, exc.reason, exc.disk_full) from None
    renamed = 0
    try:
        for tmp, final in renames.items():
            os.replace(tmp, final)
            renamed += 1
    except OSError as exc:  # after the first rename the rest is left to ``_finish_renames``
        if renamed == 0:
            for tmp in renames:
                with contextlib.suppress(OSError):
                    tmp.unlink(missing_ok=True)
        raise write_failure(exc, folder, what=what) from None
    return folder / "latest.zip"


def _finish_renames(folder: Path) -> None:
    """Finish a checkpoint whose renames a kill cut short: when ``latest.tmp.json`` is the manifest
    of the model already renamed, rename the replay and the manifest too; otherwise the previous
    checkpoint stands."""
    pending, model = folder / "latest.tmp.json", folder / "latest.zip"
    if not pending.is_file() or not model.is_file():
        return
    try:
        manifest = json.loads(pending.read_text())
        if manifest["sha256"] != file_sha256(model):
            return
        replay = folder / "replay.tmp.npz"
        if manifest.get("replay_buffer") and replay.is_file():
            if file_sha256(replay) != manifest.get("replay_sha256"):
                return
            os.replace(replay, folder / "replay.npz")
        os.replace(pending, folder / "latest.json")
    except (OSError, json.JSONDecodeError, KeyError, TypeError):
        return  # verify_checkpoint then judges what is there


def _replay_fits(model) -> bool:
    """Whether the model's replay buffer is small enough to checkpoint (``REPLAY_LIMIT_BYTES``)."""
    if getattr(model, "replay_buffer", None) is None:
        return False
    observations = model.replay_buffer.observations  # a dict of arrays for Dict observations
    arrays = observations.values() if isinstance(observations, dict) else [observations]
    limit = getattr(model, "replay_checkpoint_limit_bytes", REPLAY_LIMIT_BYTES)
    return sum(array.nbytes for array in arrays) * 2 < limit


def old_format_error(run_dir: Path) -> UsageError:
    """The one line for a run directory saved in the pickle format of earlier drivelab versions."""
    return UsageError(
        f"run {str(run_dir)!r} is in the old pickle format; if you trust it, convert it with "
        f"`drivelab convert-run {run_dir}`"
    )


def verify_checkpoint(run_dir: Path, config: RunConfig) -> dict:
    """The checkpoint manifest, once the file is checked whole and of ``config``."""
    folder = run_dir / "checkpoints"
    manifest_path, model_path = folder / "latest.json", folder / "latest.zip"
    _finish_renames(folder)
    if not manifest_path.is_file() or not model_path.is_file():
        raise UsageError(f"no checkpoint in {str(run_dir)!r} (nothing to resume)")
    try:
        manifest = json.loads(manifest_path.read_text())
        expected = manifest["sha256"]
        if not is_count(manifest["steps"]):  # a resume cuts the logs back to it
            raise TypeError("steps")
    except (json.JSONDecodeError, KeyError, TypeError, UnicodeDecodeError):
        raise UsageError(f"checkpoint manifest {str(manifest_path)!r} is corrupted") from None
    if file_sha256(model_path) != expected or not zipfile.is_zipfile(model_path):
        raise UsageError(f"checkpoint {str(model_path)!r} is truncated or corrupted (checksum mismatch)")
    if is_old_format(model_path) or (manifest.get("replay_buffer") and (folder / "replay.pkl").is_file()):
        raise old_format_error(run_dir)
    if manifest.get("config_identity") != config.identity():
        raise UsageError(f"checkpoint in {str(run_dir)!r} was made with a different config")
    return manifest


def check_trained_config(run_dir: Path, config: RunConfig) -> None:
    """A UsageError when ``config`` (the run's config.yaml) is not the config its checkpoint
    manifest recorded while it trained: config.yaml was edited after training. A run without a
    readable manifest (a shipped agent) is not checked."""
    try:
        recorded = json.loads((run_dir / "checkpoints" / "latest.json").read_text())["config_identity"]
    except (OSError, ValueError, KeyError, TypeError):
        return
    if recorded != config.identity():
        raise UsageError(
            f"config.yaml of {str(run_dir)!r} is not the config the run was trained with (its checkpoint "
            "records another): it was edited after training; put it back to evaluate the run"
        )


def model_path(run_dir: Path, config: RunConfig) -> Path:
    """The run's final model, else its latest verified checkpoint."""
    final = run_dir / "model.zip"
    if final.is_file():
        return final
    verify_checkpoint(run_dir, config)
    return run_dir / "checkpoints" / "latest.zip"


def load_agent(run_dir: Path, config: RunConfig, env=None, path: Path | None = None):
    """The agent of ``path`` (default ``model_path``) on ``env`` (default: the evaluation env)."""
    from drivelab.envs.core import DriveEnv

    spec = get_algo(config.algo)
    path = model_path(run_dir, config) if path is None else path
    try:
        env = DriveEnv(**config.eval_env_kwargs()) if env is None else env
        return spec.load(config.algo, path, env, dict(config.hyperparams), config.seed)
    except OldFormatError:
        raise old_format_error(run_dir) from None
    except NonFiniteParametersError as exc:  # a model that diverged: no evaluation of it means anything
        raise UsageError(f"cannot load model {str(path)!r}: {exc}") from None
    except UsageError:
        raise
    except Exception as exc:  # a broken zip, a model of another algorithm or config
        message = (str(exc).splitlines() or [""])[0]
        raise UsageError(f"cannot load model {str(path)!r}: {type(exc).__name__}: {message}") from None


def load_replay(model, run_dir: Path, manifest: dict) -> None:
    """Fill ``model``'s replay buffer from the checkpoint's replay.npz, after checking its sha256."""
    path = run_dir / "checkpoints" / "replay.npz"
    if not path.is_file() or file_sha256(path) != manifest.get("replay_sha256"):
        raise UsageError(f"checkpoint replay {str(path)!r} is missing, truncated or corrupted")
    try:
        model.load_replay_buffer(path)
    except Exception as exc:  # object arrays (a pickle) or a replay of another configuration
        message = (str(exc).splitlines() or [""])[0]
        raise UsageError(f"cannot load replay {str(path)!r}: {type(exc).__name__}: {message}") from None
