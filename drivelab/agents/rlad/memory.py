"""Device memory for replay frames shared by several processes on one GPU (``replay_frames=auto``).

A process puts its frames on the GPU when they take less than half of the device's free memory.
Processes started together would all read the same free memory before any allocates, so
``DeviceMemoryLedger`` keeps a JSON file, under an exclusive ``flock``, of each process's
reservation (pid, device, bytes, allocated yet); the free memory counted is the device's minus
the live processes' reservations not yet allocated. The ledger lives in the temporary directory
(``DRIVELAB_DEVICE_LEDGER`` names another file); devices are told apart by their UUID.
"""

from __future__ import annotations

import contextlib
import fcntl
import json
import os
import tempfile
import uuid
from collections.abc import Callable, Iterator
from pathlib import Path

import torch

LEDGER_ENV = "DRIVELAB_DEVICE_LEDGER"
SHARE = 0.5  # frames may take at most this share of the memory that is free and not reserved


def pid_alive(pid: int) -> bool:
    """Whether a process ``pid`` exists (signal 0 checks without sending anything)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # exists, owned by another user
        return True
    return True


def device_key(device: torch.device) -> str:
    """A name of a CUDA device that is the same in every process (its UUID where torch has it)."""
    index = device.index if device.index is not None else torch.cuda.current_device()
    properties = torch.cuda.get_device_properties(index)
    return f"cuda-{properties.uuid}" if getattr(properties, "uuid", None) else f"cuda:{index}"


def cuda_free_bytes(device: torch.device) -> int:
    return int(torch.cuda.mem_get_info(device)[0])


class DeviceMemoryLedger:
    """Reservations of device memory by the processes of one machine (see the module docstring).

    :param path: the JSON ledger (its lock is ``path`` + ``.lock``).
    :param pid: this process's id (a test passes others to act as several processes).
    :param alive: whether a pid is a live process.
    """

    def __init__(
        self, path: str | Path | None = None, pid: int | None = None, alive: Callable[[int], bool] = pid_alive
    ) -> None:
        if path is None:
            path = os.environ.get(LEDGER_ENV) or Path(tempfile.gettempdir()) / "drivelab-device-memory.json"
        self.path = Path(path)
        self.pid = os.getpid() if pid is None else int(pid)
        self.alive = alive

    @contextlib.contextmanager
    def _locked(self) -> Iterator[list[dict]]:
        """The live reservations, under the lock; what the block leaves in the list is written back."""
        self.path.parent.mkdir(parents=True, exist_ok=True)
        with open(f"{self.path}.lock", "a") as lock:
            fcntl.flock(lock, fcntl.LOCK_EX)
            try:
                try:
                    entries = json.loads(self.path.read_text())
                except (FileNotFoundError, json.JSONDecodeError):
                    entries = []
                entries = [e for e in entries if isinstance(e, dict) and self.alive(int(e.get("pid", -1)))]
                yield entries
                temporary = self.path.with_name(f"{self.path.name}.{self.pid}.tmp")
                temporary.write_text(json.dumps(entries, indent=1))
                os.replace(temporary, self.path)
            finally:
                fcntl.flock(lock, fcntl.LOCK_UN)

    def reserve(self, device: str, nbytes: int, free_bytes: Callable[[], int]) -> str | None:
        """Reserve ``nbytes`` on ``device`` when they fit in ``SHARE`` of the memory that is free
        (``free_bytes()``, read under the lock) and not reserved by a live process (this one's
        other agents included); the reservation's token, or None when they do not fit."""
        with self._locked() as entries:
            pending = sum(e["bytes"] for e in entries if e["device"] == device and not e["allocated"])
            if nbytes >= SHARE * (free_bytes() - pending):
                return None
            token = uuid.uuid4().hex
            entries.append({"token": token, "pid": self.pid, "device": device, "bytes": int(nbytes),
                            "allocated": False})  # fmt: skip
            return token

    def allocated(self, token: str) -> None:
        """The reserved bytes are allocated now (the device's free memory no longer holds them)."""
        with self._locked() as entries:
            for entry in entries:
                if entry["token"] == token:
                    entry["allocated"] = True

    def release(self, token: str) -> None:
        with self._locked() as entries:
            entries[:] = [e for e in entries if e["token"] != token]

    def entries(self) -> list[dict]:
        """The live reservations (a copy)."""
        with self._locked() as entries:
            return [dict(e) for e in entries]
