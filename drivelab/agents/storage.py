"""Safe files for agents and replays: tensors (``torch.load(weights_only=True)``), arrays
(``np.load(allow_pickle=False)``) and JSON, never pickles, since a run directory may come from
someone else. Files from drivelab before this format raise ``OldFormatError``; ``drivelab
convert-run`` rewrites a directory the user trusts.
"""

from __future__ import annotations

import io
import json
import pickle  # only for its exception type: nothing here unpickles
import warnings
import zipfile
from pathlib import Path
from typing import Any

import numpy as np
import torch
from gymnasium import spaces

from drivelab.errors import UsageError

PICKLED_MEMBERS = ("data", "spaces.pkl", "pytorch_variables.pth")  # SB3's and drivelab's old zips


class OldFormatError(ValueError):
    """A file in the pickle format of earlier drivelab versions (loading it would unpickle)."""

    def __init__(self, path: str | Path) -> None:
        super().__init__(f"{str(path)!r} is in the old pickle format")
        self.path = Path(path)


class NonFiniteParametersError(UsageError):
    """A model whose tensors hold nan or inf (training diverged): it is neither saved nor loaded,
    as every action or evaluation computed from it would be meaningless."""


# --- tensors -----------------------------------------------------------------------------------
def _tensors(state: Any, name: str = ""):
    """(dotted name, tensor) of every tensor in nested dicts/lists ``state``."""
    if isinstance(state, torch.Tensor):
        yield name or "tensor", state
    elif isinstance(state, (dict, list, tuple)):
        for key, value in state.items() if isinstance(state, dict) else enumerate(state):
            yield from _tensors(value, f"{name}.{key}".lstrip("."))


def _check_finite(state: Any, prefix: str = "") -> None:
    names = [
        name for name, tensor in _tensors(state)
        if (tensor.is_floating_point() or tensor.is_complex()) and not bool(torch.isfinite(tensor).all())
    ]  # fmt: skip
    if names:
        shown = ", ".join(names[:3]) + (f" and {len(names) - 3} more" if len(names) > 3 else "")
        raise NonFiniteParametersError(
            f"{prefix}the model's tensors hold nan or inf ({shown}): training diverged "
            f"(a learning rate too large?) and the model cannot act"
        )


def tensors_to_bytes(state: Any) -> bytes:
    """Nested dicts/lists of tensors and numbers (state dicts, optimizer states) as torch bytes;
    a tensor holding nan or inf is refused (``NonFiniteParametersError``)."""
    _check_finite(state, "not saved: ")
    buffer = io.BytesIO()
    torch.save(state, buffer)
    return buffer.getvalue()


def tensors_from_bytes(data: bytes) -> Any:
    """The inverse of ``tensors_to_bytes``; refuses anything but tensors and plain containers, and
    tensors holding nan or inf (``NonFiniteParametersError``)."""
    try:
        with warnings.catch_warnings():
            # torch warns about a foreign pickle protocol before it refuses or reads the file
            warnings.filterwarnings("ignore", message="Detected pickle protocol", category=UserWarning)
            state = torch.load(io.BytesIO(data), map_location="cpu", weights_only=True)
    except pickle.UnpicklingError:
        raise ValueError("the tensor file holds objects other than tensors (refused)") from None
    _check_finite(state)
    return state


# --- arrays ------------------------------------------------------------------------------------
def read_arrays(source: str | Path | bytes) -> dict[str, np.ndarray]:
    """Every array of an ``.npz`` file or its bytes; object arrays are refused (ValueError), and so
    are compressed members: drivelab writes its arrays uncompressed (``np.savez``), so that none
    reads larger than the file, where a compressed one could inflate to gigabytes."""
    handle = io.BytesIO(source) if isinstance(source, bytes) else source
    try:
        with zipfile.ZipFile(handle) as members:
            infos = members.infolist()
    except zipfile.BadZipFile:
        raise ValueError("not an .npz file of arrays (truncated or corrupted)") from None
    packed = next((info.filename for info in infos if info.compress_type != zipfile.ZIP_STORED), None)
    if packed is not None:
        raise ValueError(f"array {packed!r} is compressed: not an array file drivelab wrote")
    if isinstance(handle, io.BytesIO):
        handle.seek(0)
    with np.load(handle, allow_pickle=False) as archive:
        return {key: archive[key] for key in archive.files}


def write_arrays(path: str | Path, arrays: dict[str, np.ndarray], meta: dict | None = None) -> None:
    """An ``.npz`` file of ``arrays`` plus ``meta`` (JSON, stored as a string array ``__meta__``)."""
    extra = {} if meta is None else {"__meta__": np.asarray(json.dumps(meta))}
    with open(path, "wb") as handle:
        np.savez(handle, **arrays, **extra)


def split_meta(arrays: dict[str, np.ndarray]) -> tuple[dict[str, np.ndarray], dict]:
    """(arrays, meta) of a ``write_arrays`` file read back with ``read_arrays``."""
    arrays = dict(arrays)
    meta = arrays.pop("__meta__", None)
    return arrays, ({} if meta is None else json.loads(str(meta)))


def assign_arrays(target: Any, arrays: dict[str, np.ndarray], names: tuple[str, ...]) -> None:
    """Copy ``arrays[name]`` into ``target.name`` for each name, after checking that each has the
    shape and dtype of the attribute it replaces (a replay saved by another configuration fails)."""
    for name in names:
        if name not in arrays:
            raise ValueError(f"the replay has no {name!r} array")
        current = getattr(target, name)
        if isinstance(current, torch.Tensor):
            current = current.cpu().numpy()
        value = arrays[name]
        if value.shape != np.shape(current) or value.dtype != np.asarray(current).dtype:
            raise ValueError(
                f"replay array {name!r} is {value.dtype}{value.shape}, this agent's is "
                f"{np.asarray(current).dtype}{np.shape(current)}"
            )
    for name in names:
        value = arrays[name]
        setattr(target, name, value.item() if value.ndim == 0 else value.copy())


# --- spaces ------------------------------------------------------------------------------------
def _bound(values: np.ndarray) -> Any:
    """A Box bound as JSON: one number when all are equal, else nested lists."""
    flat = values.ravel()
    if flat.size and np.all(flat == flat[0]):
        return flat[0].item()
    return values.tolist()


def space_to_json(space: spaces.Space) -> dict:
    """A gymnasium space (Box, Discrete, MultiDiscrete, MultiBinary, Dict, Tuple) as JSON."""
    if isinstance(space, spaces.Box):
        return {"type": "Box", "shape": list(space.shape), "dtype": space.dtype.str,
                "low": _bound(space.low), "high": _bound(space.high)}  # fmt: skip
    if isinstance(space, spaces.Discrete):
        return {"type": "Discrete", "n": int(space.n), "start": int(space.start)}
    if isinstance(space, spaces.MultiDiscrete):
        return {"type": "MultiDiscrete", "nvec": space.nvec.tolist()}
    if isinstance(space, spaces.MultiBinary):
        return {"type": "MultiBinary", "n": np.asarray(space.n).tolist()}
    if isinstance(space, spaces.Dict):
        return {"type": "Dict", "spaces": [[key, space_to_json(sub)] for key, sub in space.spaces.items()]}
    if isinstance(space, spaces.Tuple):
        return {"type": "Tuple", "spaces": [space_to_json(sub) for sub in space.spaces]}
    raise ValueError(f"cannot describe a {type(space).__name__} space")


def space_from_json(data: dict) -> spaces.Space:
    """The space ``space_to_json`` described."""
    kind = data["type"]
    if kind == "Box":
        dtype, shape = np.dtype(data["dtype"]), tuple(data["shape"])
        low = np.broadcast_to(np.asarray(data["low"], dtype=dtype), shape)
        high = np.broadcast_to(np.asarray(data["high"], dtype=dtype), shape)
        return spaces.Box(low, high, shape, dtype)
    if kind == "Discrete":
        return spaces.Discrete(int(data["n"]), start=int(data["start"]))
    if kind == "MultiDiscrete":
        return spaces.MultiDiscrete(np.asarray(data["nvec"], dtype=np.int64))
    if kind == "MultiBinary":
        return spaces.MultiBinary(data["n"])
    if kind == "Dict":
        return spaces.Dict({key: space_from_json(sub) for key, sub in data["spaces"]})
    if kind == "Tuple":
        return spaces.Tuple([space_from_json(sub) for sub in data["spaces"]])
    raise ValueError(f"unknown space type {kind!r}")


def check_spaces(saved: dict, observation_space: spaces.Space, action_space: spaces.Space) -> None:
    """Fail when an environment's spaces differ from those a model was saved with."""
    saved_obs = space_from_json(saved["observation_space"])
    saved_action = space_from_json(saved["action_space"])
    if (saved_obs, saved_action) != (observation_space, action_space):
        raise ValueError(
            f"the model reads observations {saved_obs} and takes actions {saved_action}, but its environment "
            f"gives {observation_space} and {action_space} (was config.yaml edited after training?)"
        )


# --- zips --------------------------------------------------------------------------------------
# A model zip's members are read whole, so each is bounded before it is inflated: the JSON metadata
# to kilobytes' worth, a tensor file to the weights plus at most three copies of them (optimizer
# moments) plus a MiB of structure, generator states and counters.
MAX_META_BYTES = 16 << 20
STATE_COPIES = 4
STATE_OVERHEAD_BYTES = 1 << 20


def state_limit(weights: Any) -> int:
    """The most bytes a saved state of a model with these fresh tensors (``weights``: its state
    dicts, optimizers without moments yet) can take, trained to any step."""
    weight_bytes = sum(tensor.numel() * tensor.element_size() for _, tensor in _tensors(weights))
    return STATE_COPIES * weight_bytes + STATE_OVERHEAD_BYTES


def read_member(archive: zipfile.ZipFile, name: str, limit: int) -> bytes:
    """The bytes of member ``name``, at most ``limit``: a ValueError when its header declares more
    or, the header lying, it inflates to more (read no further than ``limit`` + 1 bytes)."""
    try:
        info = archive.getinfo(name)
    except KeyError:
        raise ValueError(f"the model zip has no {name}") from None
    if info.file_size > limit:
        raise ValueError(
            f"{name} declares {info.file_size} bytes, more than a model of this config takes ({limit})"
        )
    with archive.open(info) as handle:
        data = handle.read(limit + 1)
    if len(data) > limit:
        raise ValueError(f"{name} inflates to more bytes than a model of this config takes ({limit})")
    return data


def read_zip(path: str | Path, meta_name: str) -> tuple[dict, zipfile.ZipFile]:
    """(JSON metadata ``meta_name``, open archive) of a model zip; an old pickled zip raises
    ``OldFormatError`` before anything inside it is read, metadata over ``MAX_META_BYTES`` a
    ValueError."""
    archive = zipfile.ZipFile(path)
    try:
        names = set(archive.namelist())
        if names & set(PICKLED_MEMBERS):
            raise OldFormatError(path)
        if meta_name not in names:
            raise ValueError(f"{str(path)!r} has no {meta_name}")
        meta = json.loads(read_member(archive, meta_name, MAX_META_BYTES))
        if not isinstance(meta, dict):
            raise ValueError(f"{meta_name} is not a mapping")
    except BaseException:
        archive.close()
        raise
    return meta, archive


def is_old_format(path: str | Path) -> bool:
    """Whether ``path`` is a model zip in the old pickle format (read without unpickling)."""
    if not zipfile.is_zipfile(path):
        return False
    with zipfile.ZipFile(path) as archive:
        return bool(set(archive.namelist()) & set(PICKLED_MEMBERS))
