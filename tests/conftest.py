import os

os.environ.setdefault("PYGAME_HIDE_SUPPORT_PROMPT", "1")
os.environ.setdefault("MPLBACKEND", "Agg")


def pytest_configure(config):
    """SB3 models trained without a run's logger (tests calling ``learn`` directly) log to a folder
    it makes under ``$SB3_LOGDIR``, else a new one in the temp directory per call: keep them in one
    folder of this session's."""
    if "SB3_LOGDIR" not in os.environ:
        import tempfile

        os.environ["SB3_LOGDIR"] = tempfile.mkdtemp(prefix="drivelab-tests-sb3-")
