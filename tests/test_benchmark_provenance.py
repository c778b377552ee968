"""benchmarks/provenance.py: the command line a benchmark records is the one that ran."""

import importlib.util
from pathlib import Path

SCRIPT = Path(__file__).parents[1] / "benchmarks" / "provenance.py"


def _provenance():
    spec = importlib.util.spec_from_file_location("provenance", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_the_thread_settings_are_the_environments_and_the_arguments_are_quoted(monkeypatch):
    provenance = _provenance()
    argv = ["benchmarks/rlad_ablation.py", "--hyperparams", '{"batch_size": 32}']
    monkeypatch.delenv("OMP_NUM_THREADS", raising=False)
    monkeypatch.delenv("NUMBA_NUM_THREADS", raising=False)
    assert (
        provenance.command_line(argv)
        == "python benchmarks/rlad_ablation.py --hyperparams '{\"batch_size\": 32}'"
    )
    monkeypatch.setenv("OMP_NUM_THREADS", "1")
    monkeypatch.setenv("NUMBA_NUM_THREADS", "2")
    assert provenance.command_line(argv[:1]) == (
        "OMP_NUM_THREADS=1 NUMBA_NUM_THREADS=2 python benchmarks/rlad_ablation.py"
    )
