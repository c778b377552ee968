"""drivelab/_numba_cache.py: numba's cache folder follows the version of the sources."""

import io
import os
import time

import numba

import drivelab  # noqa: F401  (configures the cache folder)
from drivelab import _numba_cache


def _tree(root, text):
    (root / "sub").mkdir(parents=True, exist_ok=True)
    (root / "a.py").write_text("x = 1\n")
    (root / "sub" / "b.py").write_text(text)
    return root


def test_an_edit_in_any_module_gives_another_folder(tmp_path):
    """numba would keep a kernel's cache after an edit to a function it calls from another file;
    the folder's name changes with every file's content instead."""
    before = _numba_cache.source_digest(_tree(tmp_path, "def f():\n    return 1\n"))
    assert _numba_cache.source_digest(tmp_path) == before
    after = _numba_cache.source_digest(_tree(tmp_path, "def f():\n    return 2\n"))
    assert after != before
    assert _numba_cache.cache_folder(after, {}) != _numba_cache.cache_folder(before, {})


def test_the_folder_sits_under_the_users_cache_and_is_inherited_as_it_is(tmp_path):
    folder = _numba_cache.cache_folder("abc", {"NUMBA_CACHE_DIR": str(tmp_path)})
    assert folder == tmp_path / "drivelab-numba-abc"
    # a child process sees the parent's folder in NUMBA_CACHE_DIR and keeps it
    assert _numba_cache.cache_folder("abc", {"NUMBA_CACHE_DIR": str(folder)}) == folder
    assert _numba_cache.cache_folder("abc", {}).name == "drivelab-numba-abc"


def test_numba_caches_this_versions_kernels_in_its_folder():
    expected = _numba_cache.cache_folder(_numba_cache.source_digest())
    assert numba.config.CACHE_DIR == str(expected) == os.environ["NUMBA_CACHE_DIR"]


def test_other_versions_folders_unused_for_a_day_are_removed(tmp_path):
    current, recent, stale = (tmp_path / f"drivelab-numba-{n}" for n in ("now", "recent", "old"))
    for folder in (current, recent, stale):
        folder.mkdir()
    old = time.time() - 2 * _numba_cache.STALE_S
    os.utime(stale, (old, old))
    _numba_cache._remove_stale(current)
    assert current.is_dir() and recent.is_dir() and not stale.exists()


def test_editor_lock_links_and_broken_links_are_no_source(tmp_path):
    """Emacs leaves ``.#file.py`` links to nowhere while a file has unsaved edits: importing
    drivelab must not fail on them, and they do not change the folder."""
    clean = _numba_cache.source_digest(_tree(tmp_path, "def f():\n    return 1\n"))
    (tmp_path / ".#a.py").symlink_to("user@host.1234:1")
    (tmp_path / "sub" / "gone.py").symlink_to(tmp_path / "missing.py")
    assert _numba_cache.source_digest(tmp_path) == clean


def test_a_read_only_install_caches_in_the_users_own_folder(tmp_path, monkeypatch):
    monkeypatch.setattr(_numba_cache.os, "access", lambda path, mode: False)
    folder = _numba_cache.cache_folder("abc", {"XDG_CACHE_HOME": str(tmp_path)})
    assert folder == tmp_path / "drivelab" / "drivelab-numba-abc"


def test_configure_marks_its_folder_in_use(tmp_path, monkeypatch):
    before = numba.config.CACHE_DIR
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path))  # restored after the test
    old = time.time() - 2 * _numba_cache.STALE_S
    folder = _numba_cache.cache_folder(_numba_cache.source_digest(), dict(os.environ))
    folder.mkdir()
    os.utime(folder, (old, old))
    try:
        assert _numba_cache.configure() == folder
        assert time.time() - folder.stat().st_mtime < 60  # another version would keep it
    finally:
        numba.config.CACHE_DIR = before


class _Terminal(io.StringIO):
    def __init__(self, tty: bool) -> None:
        super().__init__()
        self.tty = tty

    def isatty(self) -> bool:
        return self.tty


def test_a_first_compile_is_announced_once_on_a_terminal(tmp_path, monkeypatch):
    monkeypatch.setattr(_numba_cache, "_noticed", False)
    quiet = _Terminal(tty=False)
    assert not _numba_cache.compile_notice(tmp_path, quiet) and quiet.getvalue() == ""  # a log, a pipe
    cached = tmp_path / "cached"
    (cached / "sub").mkdir(parents=True)
    (cached / "sub" / "traffic.act-12.py311.nbi").write_bytes(b"")
    terminal = _Terminal(tty=True)
    assert not _numba_cache.compile_notice(cached, terminal) and terminal.getvalue() == ""  # compiled before
    assert _numba_cache.compile_notice(tmp_path / "empty", terminal)
    assert terminal.getvalue().count("\n") == 1 and "compiling the simulator" in terminal.getvalue()
    assert not _numba_cache.compile_notice(tmp_path / "empty", terminal)  # once per process
    assert terminal.getvalue().count("\n") == 1
