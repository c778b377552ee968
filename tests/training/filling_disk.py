"""A disk that fills up, for tests of what drivelab does when a write fails with ENOSPC.

Files opened for writing under a folder (through ``open``/``io.open``: Python's file objects,
zipfile, numpy, pandas, matplotlib, SB3's and TensorBoard's logs) get a real descriptor. When
``fill`` is called, those still open and every one opened later are pointed at ``/dev/full``
(``os.dup2``), where the kernel fails each write with ENOSPC, as on a full disk: buffered data
fails when flushed, files already open fail too, and new files are created empty. Writing never
fails while the disk is not full.
"""

from __future__ import annotations

import builtins
import io
import os
from pathlib import Path


class FillingDisk:
    """The writes under ``root`` fail with ENOSPC once ``fill`` was called (until ``uninstall``)."""

    def __init__(self, root: Path) -> None:
        self.root = str(Path(root).resolve())
        self.full = False
        self.opened: list[tuple[int, int, int]] = []  # (descriptor, device, inode) of files written
        self.real_open = io.open

    def install(self) -> FillingDisk:
        builtins.open = io.open = self._open
        return self

    def uninstall(self) -> None:
        builtins.open = io.open = self.real_open

    def fill(self) -> None:
        """From now on every write under ``root`` fails with ENOSPC, to files open or opened later."""
        self.full = True
        for descriptor, device, inode in self.opened:
            try:
                status = os.fstat(descriptor)
            except OSError:
                continue  # closed
            if (status.st_dev, status.st_ino) == (device, inode):  # not another file's number now
                self._point_at_full(descriptor)

    def _point_at_full(self, descriptor: int) -> None:
        full = os.open("/dev/full", os.O_WRONLY)
        try:
            os.dup2(full, descriptor)
        finally:
            os.close(full)

    def _open(self, file, mode="r", buffering=-1, encoding=None, errors=None, newline=None, closefd=True,
              opener=None):  # fmt: skip
        writes = any(flag in mode for flag in "wax+")
        if writes and isinstance(file, (str, os.PathLike)) and self._under_root(file):
            opener = self._opener(opener)
        return self.real_open(file, mode, buffering, encoding, errors, newline, closefd, opener)

    def _under_root(self, file) -> bool:
        path = os.path.abspath(os.fsdecode(file))
        return path == self.root or path.startswith(self.root + os.sep)

    def _opener(self, inner):
        def opener(path, flags):
            descriptor = inner(path, flags) if inner is not None else os.open(path, flags, 0o666)
            if self.full:
                self._point_at_full(descriptor)
            else:
                status = os.fstat(descriptor)
                self.opened.append((descriptor, status.st_dev, status.st_ino))
            return descriptor

        return opener
