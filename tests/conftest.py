import os
from pathlib import Path

import pytest

os.environ.setdefault("PYGAME_HIDE_SUPPORT_PROMPT", "1")
os.environ.setdefault("MPLBACKEND", "Agg")


def pytest_configure(config):
    """SB3 models trained without a run's logger (tests calling ``learn`` directly) log to a folder
    it makes under ``$SB3_LOGDIR``, else a new one in the temp directory per call: keep them in one
    folder of this session's."""
    if "SB3_LOGDIR" not in os.environ:
        import tempfile

        os.environ["SB3_LOGDIR"] = tempfile.mkdtemp(prefix="drivelab-tests-sb3-")
        config.drivelab_sb3_logdir = os.environ["SB3_LOGDIR"]


def pytest_unconfigure(config):
    """The session's SB3 folder goes with the session (the process that made it removes it)."""
    folder = getattr(config, "drivelab_sb3_logdir", None)
    if folder is not None:
        import shutil

        shutil.rmtree(folder, ignore_errors=True)
        del os.environ["SB3_LOGDIR"]


@pytest.fixture
def work(tmp_path, monkeypatch) -> Path:
    """An empty working folder that is the current directory (``-o .`` and relative paths)."""
    folder = tmp_path / "work"
    folder.mkdir()
    monkeypatch.chdir(folder)
    return folder


@pytest.fixture
def one_torch_thread():
    """Tiny networks on a shared 2-core machine: one torch thread avoids oversubscription stalls
    (and keeps one process's float sums in one order); restored after the test."""
    import torch

    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(threads)
