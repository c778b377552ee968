"""Writing in a run directory: never through a link, each file whole or not at all, one command at a
time, and a failed write (a full disk) as one line; a run directory may come from someone else, and
nothing drivelab writes may land outside it (docs/trust.md). ``locked_run`` holds the run,
``check_run_members`` refuses links and folders in the way, ``replacing`` / ``write_file`` write
through an exclusive temporary renamed over the name, ``remove_file`` deletes regular files only and
``write_failure`` makes the one-line error."""

from __future__ import annotations

import contextlib
import errno
import fcntl
import os
import shutil
import stat
from collections.abc import Iterator
from fnmatch import fnmatch
from pathlib import Path

from drivelab.errors import UsageError

IN_USE = ".in-use.pid"  # the pid of the command holding the run's lock, while it holds it
OWN_FOLDERS = ("checkpoints", "videos")  # folders of files drivelab writes, nothing else
# names drivelab writes as files at the top of a run directory (temporaries included): a folder there
# is in the way, and refused before anything is written
FILE_NAMES = (
    "config.yaml", "monitor.csv", "progress*.csv", "evaluations.csv", "events.out.tfevents.*",
    "eval.json*", "eval-maps-*.json*", "nocrash.json*", "nocrash.md*", "learning_curve*.png",
    "model*.zip", "q_table.*", "qlearning_curves.png", IN_USE + "*",
)  # fmt: skip
_CREATE = os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_NOFOLLOW | os.O_CLOEXEC
DISK_FULL = (errno.ENOSPC, errno.EDQUOT)
NEARLY_FULL_BYTES = 1 << 20  # free space below which a write that failed without an errno was a full disk


# --- failures --------------------------------------------------------------------------------
AGAIN = "run the command again"


class WriteError(UsageError):
    """A write that failed, as one line: ``what``, ``reason``, and when ``disk_full``, what to do
    once space is freed (``then``)."""

    def __init__(self, what: str, reason: str, disk_full: bool, then: str = AGAIN) -> None:
        self.what, self.reason, self.disk_full = what, reason, disk_full
        advice = f"; free some space, then {then}" if disk_full else ""
        super().__init__(f"cannot write {what}: {reason}{advice}")

    def advising(self, then: str) -> WriteError:
        """The same failure with another ``then``."""
        return WriteError(self.what, self.reason, self.disk_full, then)


def write_failure(exc: BaseException, path: Path, then: str = AGAIN, what: str | None = None) -> WriteError:
    """The ``WriteError`` of a write to ``path`` (or ``what``) that failed with ``exc``."""
    if isinstance(exc, WriteError):
        return exc.advising(then)
    what = repr(str(path)) if what is None else what
    if _disk_full(exc, path):
        return WriteError(what, "no space left on device (the disk is full)", True, then)
    if isinstance(exc, OSError) and exc.strerror:
        reason = exc.strerror
    else:
        reason = (str(exc).strip().splitlines() or [type(exc).__name__])[0]
    return WriteError(what, reason, False, then)


def _disk_full(exc: BaseException, path: Path) -> bool:
    """Whether ``exc`` says the disk is full; a writer that fails without an errno (ffmpeg) is
    judged by the free space left where it wrote."""
    if isinstance(exc, OSError) and exc.errno is not None:
        return exc.errno in DISK_FULL
    folder = next((p for p in (path, *path.parents) if p.is_dir()), None)
    try:
        return folder is not None and shutil.disk_usage(folder).free < NEARLY_FULL_BYTES
    except OSError:
        return False


# --- members ---------------------------------------------------------------------------------
def _kind(path: Path) -> str | None:
    """What ``path`` is, its link not followed: "a symbolic link", "a folder", "a file" or "a
    special file"; None when nothing is there."""
    try:
        mode = os.lstat(path).st_mode
    except FileNotFoundError:
        return None
    if stat.S_ISLNK(mode):
        return "a symbolic link"
    if stat.S_ISDIR(mode):
        return "a folder"
    return "a file" if stat.S_ISREG(mode) else "a special file"


def _refuse(path: Path, kind: str, want: str) -> UsageError:
    """The one line refusing ``path``, which is ``kind`` (``_kind``) where drivelab ``want``s."""
    if kind == "a symbolic link":
        return UsageError(
            f"{str(path)!r} is a symbolic link: drivelab neither writes nor deletes through links (a run "
            "directory is data); put what it points to in its place, or move it away (nothing was changed)"
        )
    if want == "writes a file":
        where = f"{path.name} in {str(path.parent)!r}"
        return UsageError(f"cannot write {where}: it is {kind}; move it away (nothing was changed)")
    return UsageError(f"{str(path)!r} is {kind}, where drivelab {want}; move it away (nothing was changed)")


def check_run_members(run_dir: Path) -> None:
    """A UsageError naming the first member of ``run_dir`` that drivelab could write or delete
    through, or that is in the way of a file it writes: a symbolic link, an ``OWN_FOLDERS`` entry
    that is not a folder of files, a folder of a name in ``FILE_NAMES``."""
    for path in sorted(run_dir.iterdir()):
        kind = _kind(path)
        if kind == "a symbolic link":
            raise _refuse(path, kind, "keeps its own files")
        if path.name in OWN_FOLDERS:
            check_folder(path)
            for inner in sorted(path.iterdir()):
                if _kind(inner) != "a file":
                    raise _refuse(inner, _kind(inner), "keeps its own files")
        elif kind != "a file" and any(fnmatch(path.name, pattern) for pattern in FILE_NAMES):
            raise _refuse(path, kind, "writes a file")


def check_replaceable(path: Path, temporary: Path | None = None) -> None:
    """A UsageError when ``replacing(path, temporary)`` could not write: ``path`` is a folder, or
    its temporary's name holds anything but a file."""
    temporary = temporary_of(path) if temporary is None else temporary
    if _kind(path) == "a folder":
        raise _refuse(path, "a folder", "writes a file")
    if _kind(temporary) not in (None, "a file"):
        raise _refuse(temporary, _kind(temporary), "writes a file")


# --- writing -------------------------------------------------------------------------------------
def temporary_of(path: Path) -> Path:
    """The temporary that ``path`` is written into: ``NAME.tmp`` beside it."""
    return path.with_name(path.name + ".tmp")


def _create(temporary: Path) -> int:
    """A descriptor of ``temporary``, created now (a file a killed command left there is replaced)."""
    try:
        return os.open(temporary, _CREATE, 0o666)
    except FileExistsError:
        pass
    except OSError as exc:
        raise write_failure(exc, temporary) from None
    kind = _kind(temporary)
    if kind not in (None, "a file"):
        raise _refuse(temporary, kind, "writes a file")
    try:
        temporary.unlink(missing_ok=True)
        return os.open(temporary, _CREATE, 0o666)
    except OSError as exc:
        raise write_failure(exc, temporary) from None


def _still(descriptor: int, temporary: Path) -> bool:
    """Whether ``temporary`` is still the file ``descriptor`` created (not replaced meanwhile)."""
    try:
        return os.path.samestat(os.fstat(descriptor), os.lstat(temporary))
    except OSError:
        return False


@contextlib.contextmanager
def temporary_file(temporary: Path, final: Path | None = None) -> Iterator[Path]:
    """Yield ``temporary``, a file created now (``_create``), for the caller to write by its path
    and later rename to ``final``. When the block fails it is removed (an OSError becomes
    ``write_failure``'s line); when it ends, it must still be the file created."""
    descriptor = _create(temporary)
    try:
        yield temporary
        if not _still(descriptor, temporary):
            raise UsageError(f"{str(temporary)!r} was replaced while drivelab wrote it; nothing was written")
    except BaseException as exc:
        if _still(descriptor, temporary):
            with contextlib.suppress(OSError):
                temporary.unlink()
        if isinstance(exc, OSError):
            raise write_failure(exc, temporary if final is None else final) from None
        raise
    finally:
        os.close(descriptor)


@contextlib.contextmanager
def replacing(path: Path, temporary: Path | None = None) -> Iterator[Path]:
    """Yield a new empty file, ``temporary`` (default ``temporary_of(path)``), for the caller to
    write by its path; when the block ends, rename it over ``path`` (never following a link there).
    On a failure the temporary is removed; an OSError becomes ``write_failure``'s one line."""
    temporary = temporary_of(path) if temporary is None else temporary
    with temporary_file(temporary, path):
        yield temporary
    try:
        os.replace(temporary, path)
    except BaseException as exc:
        with contextlib.suppress(OSError):
            temporary.unlink()
        if isinstance(exc, OSError):
            raise write_failure(exc, path) from None
        raise


def write_file(path: Path, data: str | bytes, temporary: Path | None = None) -> None:
    """Write ``data`` (text is UTF-8) as the whole of ``path`` (``replacing``)."""
    with replacing(path, temporary) as tmp, open(tmp, "wb") as handle:
        handle.write(data.encode() if isinstance(data, str) else data)


def remove_file(path: Path) -> None:
    """Delete ``path`` when it is a file; a link or a folder there is a UsageError."""
    kind = _kind(path)
    if kind is None:
        return
    if kind != "a file":
        raise _refuse(path, kind, "deletes a file of its own")
    path.unlink(missing_ok=True)


def remove_empty_folders(folders: list[Path]) -> None:
    """Remove the empty ones of ``folders`` (innermost first: those a failed command created)."""
    for folder in folders:
        with contextlib.suppress(OSError):
            folder.rmdir()


def check_folder(path: Path) -> None:
    """A UsageError unless ``path``, a folder of drivelab's own, is a folder or missing."""
    kind = _kind(path)
    if kind not in (None, "a folder"):
        raise _refuse(path, kind, "keeps a folder of its own files")


def make_folder(path: Path) -> Path:
    """``path`` as a folder of drivelab's own (``check_folder``), made if missing."""
    check_folder(path)
    try:
        path.mkdir(exist_ok=True)
    except OSError as exc:
        raise write_failure(exc, path) from None
    check_folder(path)  # not made a link meanwhile
    return path


# --- one command at a time -------------------------------------------------------------------------
def _holder(run_dir: Path) -> str:
    """`` (pid N)`` from ``IN_USE`` when it holds a pid, else ""."""
    try:
        descriptor = os.open(run_dir / IN_USE, os.O_RDONLY | os.O_NOFOLLOW | os.O_CLOEXEC)
    except OSError:
        return ""
    try:
        text = os.read(descriptor, 32).decode("ascii", "replace").strip()
    except OSError:
        return ""
    finally:
        os.close(descriptor)
    return f" (pid {text})" if text.isdigit() else ""


def check_run_dir(run_dir: Path) -> None:
    """A UsageError unless ``run_dir`` is an existing folder."""
    if run_dir.exists() and not run_dir.is_dir():
        raise UsageError(f"{str(run_dir)!r} is a file, not a run directory")
    if not run_dir.is_dir():
        raise UsageError(f"run directory {str(run_dir)!r} does not exist")


@contextlib.contextmanager
def locked_run(run_dir: Path, writes: bool = True) -> Iterator[None]:
    """Hold ``run_dir`` for this command: exclusively when it ``writes`` there (then its members are
    checked and ``IN_USE`` holds this pid), shared when it only reads it. Another command holding it
    is a UsageError naming its pid. On a file system without locks nothing is held."""
    check_run_dir(run_dir)
    try:
        descriptor = os.open(run_dir, os.O_RDONLY | os.O_DIRECTORY | os.O_CLOEXEC)
    except OSError as exc:
        raise UsageError(f"cannot open run directory {str(run_dir)!r}: {exc.strerror or exc}") from None
    try:
        try:
            fcntl.flock(descriptor, (fcntl.LOCK_EX if writes else fcntl.LOCK_SH) | fcntl.LOCK_NB)
        except BlockingIOError:
            raise UsageError(
                f"run {str(run_dir)!r} is in use by another drivelab process{_holder(run_dir)} "
                "(training, resuming or evaluating it); wait for it to end"
            ) from None
        except OSError:
            pass  # no locks on this file system: whether another command uses it cannot be told
        if not writes:
            yield
            return
        check_run_members(run_dir)
        with contextlib.suppress(UsageError):  # a read-only or full disk: the pid is only a courtesy
            write_file(run_dir / IN_USE, f"{os.getpid()}\n")
        try:
            yield
        finally:
            with contextlib.suppress(UsageError, OSError):
                remove_file(run_dir / IN_USE)
    finally:
        os.close(descriptor)
