"""One numba cache folder per version of drivelab's sources.

numba's ``cache=True`` keys a kernel's cache on its own file only, so an edit to a jitted function
it calls from another module leaves stale code in the cache. The cache therefore lives in a folder
named after a hash of every source file of the package, set through ``NUMBA_CACHE_DIR`` (which child
processes inherit)."""

from __future__ import annotations

import contextlib
import hashlib
import os
import shutil
import sys
import time
from pathlib import Path

PACKAGE = Path(__file__).resolve().parent
PREFIX = "drivelab-numba-"
STALE_S = 7 * 86_400  # another version's folder not imported for this long is removed


def source_digest(root: Path = PACKAGE) -> str:
    """A hash of every ``.py`` file under ``root``: their paths and contents."""
    digest = hashlib.sha256()
    for path in sorted(root.rglob("*.py")):
        relative = path.relative_to(root)
        if any(part.startswith(".") for part in relative.parts) or not path.is_file():
            continue  # an editor's lock link (.#cli.py) or a broken link is no source
        try:
            digest.update(relative.as_posix().encode() + b"\0" + path.read_bytes() + b"\0")
        except OSError:
            continue
    return digest.hexdigest()[:16]


def cache_folder(digest: str, environ: dict[str, str] | None = None) -> Path:
    """Where this version's kernels are cached: under ``NUMBA_CACHE_DIR`` when set, else beside the
    sources, else in the user's own cache folder."""
    environ = os.environ if environ is None else environ
    given = environ.get("NUMBA_CACHE_DIR")
    if given:
        base = Path(given)
        if base.name.startswith(PREFIX):  # set by drivelab in a parent process
            base = base.parent
    elif os.access(PACKAGE / "__pycache__", os.W_OK) or os.access(PACKAGE, os.W_OK):
        base = PACKAGE / "__pycache__"
    else:
        base = Path(environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "drivelab"
    return base / f"{PREFIX}{digest}"


def _remove_stale(folder: Path) -> None:
    """Remove other versions' folders beside ``folder`` unused for ``STALE_S``."""
    with contextlib.suppress(OSError):
        siblings = [p for p in folder.parent.glob(f"{PREFIX}*") if p != folder and p.is_dir()]
        for old in siblings:
            if time.time() - old.stat().st_mtime > STALE_S:
                shutil.rmtree(old, ignore_errors=True)


def configure() -> Path:
    """Point numba's cache at this version's folder (before any drivelab kernel is decorated)."""
    folder = cache_folder(source_digest())
    with contextlib.suppress(OSError):  # numba says so itself if it cannot write there
        folder.mkdir(parents=True, exist_ok=True)
        os.utime(folder)  # in use: another version's configure leaves it alone
    os.environ["NUMBA_CACHE_DIR"] = str(folder)
    numba = sys.modules.get("numba")
    if numba is not None:  # imported before drivelab: its config has read the environment already
        numba.config.CACHE_DIR = str(folder)
    _remove_stale(folder)
    return folder


_noticed = False  # the first-compile line is said once per process


def compile_notice(folder: Path | None = None, stream=None) -> bool:
    """Say, once per process and on a terminal, that the simulator is being compiled when this
    version's cache folder holds no compiled kernel yet; whether it said so."""
    global _noticed
    stream = sys.stderr if stream is None else stream
    if _noticed or not getattr(stream, "isatty", lambda: False)():
        return False
    if folder is None:
        if not os.environ.get("NUMBA_CACHE_DIR"):
            return False  # numba's own cache beside each module: nothing to look at
        folder = Path(os.environ["NUMBA_CACHE_DIR"])
    try:
        compiled = next(folder.rglob("*.nbi"), None) is not None
    except OSError:
        return False
    if compiled:
        return False
    _noticed = True
    print(
        "drivelab: compiling the simulator for this machine (first run after an install or an update, "
        "about a minute; cached after)",
        file=stream,
        flush=True,
    )
    return True
