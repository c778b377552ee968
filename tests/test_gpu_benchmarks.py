"""The GPU benchmarks' own logic, on the CPU: rlad_update.py reports a variant that fails and
measures the others; rlad_gpu_training.py reads a run's rate and nvidia-smi's samples, and refuses
to start without a GPU."""

import importlib.util
import json
import subprocess
import sys
from pathlib import Path

import pytest

BENCHMARKS = Path(__file__).parents[1] / "benchmarks"


def _script(name):
    sys.path.insert(0, str(BENCHMARKS))
    try:
        spec = importlib.util.spec_from_file_location(name, BENCHMARKS / f"{name}.py")
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
    finally:
        sys.path.remove(str(BENCHMARKS))
    return module


def test_rlad_update_reports_a_failing_variant_and_times_the_others(tmp_path, monkeypatch, capsys):
    """A GPU that runs out of memory (or a compiler that fails) for one variant used to end the whole
    run with a traceback and no results; now that variant is a row of the failures table."""
    update = _script("rlad_update")
    make_agent = update.make_agent

    def failing(size, batch, device, hyperparams, seed=0):
        if hyperparams.get("fast_update"):
            raise RuntimeError("CUDA out of memory. Tried to allocate 2.00 GiB\nmore detail")
        return make_agent(size, batch, device, hyperparams, seed)

    monkeypatch.setattr(update, "make_agent", failing)
    monkeypatch.setattr(update, "RESULTS", tmp_path)
    argv = "rlad_update.py --size 36 --batch-size 4 --variants plain fast --repeats 1 --out x"
    monkeypatch.setattr(sys, "argv", argv.split())
    update.main()
    result = json.loads((tmp_path / "x.json").read_text())
    assert [(r["variant"], r["speedup_vs_plain"]) for r in result["rows"]] == [("plain", 1.0)]
    assert result["rows"][0]["median_ms"] > 0
    assert result["failures"] == [
        {
            "size": 36,
            "variant": "fast",
            "error": "RuntimeError: CUDA out of memory. Tried to allocate 2.00 GiB",
        }
    ]
    assert "| 36x36 | fast | RuntimeError: CUDA out of memory." in (tmp_path / "x.md").read_text()
    assert "36 px fast: failed: RuntimeError" in capsys.readouterr().out


def test_rlad_update_writes_nothing_when_every_variant_fails(tmp_path, monkeypatch, capsys):
    """A GPU that fails every variant must not overwrite the committed results with a table of none."""
    update = _script("rlad_update")

    def failing(size, batch, device, hyperparams, seed=0):
        raise RuntimeError("CUDA error: no kernel image is available")

    monkeypatch.setattr(update, "make_agent", failing)
    monkeypatch.setattr(update, "RESULTS", tmp_path)
    monkeypatch.setattr(sys, "argv", "rlad_update.py --size 36 --variants plain fast --out x".split())
    with pytest.raises(SystemExit) as stopped:
        update.main()
    assert stopped.value.code == 1 and list(tmp_path.iterdir()) == []
    assert capsys.readouterr().err == "error: every variant failed (2); no results written\n"


def test_a_runs_rate_counts_only_the_steps_after_the_updates_begin(tmp_path):
    training = _script("rlad_gpu_training")
    run = tmp_path / "rlad-0"
    run.mkdir()
    # episodes of 400 steps: ends at 400, 800 (warm-up), 1200, 1600, 2000 at 10, 20, 40, 60, 80 s
    rows = "".join(f"0.5,400,{t}\n" for t in (10, 20, 40, 60, 80))
    (run / "monitor.csv").write_text('#{"t_start": 0, "env_id": "None"}\nr,l,t\n' + rows)
    assert training.run_rate(run / "monitor.csv") == {
        "run": "rlad-0",
        "episodes": 5,
        "steps": 2000,
        "seconds": 80.0,
        "steps_per_s_updating": 20.0,
    }  # fmt: skip (800 steps from 1200 at 40 s to 2000 at 80 s)
    (run / "monitor.csv").write_text('#{"t_start": 0}\nr,l,t\n0.5,400,10\n0.5,700,30\n')
    assert training.run_rate(run / "monitor.csv")["steps_per_s_updating"] is None  # one end after 1,000


def test_rlad_gpu_training_writes_nothing_when_no_run_reached_its_updates(tmp_path, monkeypatch, capsys):
    training = _script("rlad_gpu_training")
    monkeypatch.setattr(training, "RESULTS", tmp_path)
    run = {"run": "rlad-0", "episodes": 3, "steps": 600, "seconds": 40.0, "steps_per_s_updating": None}
    result = {"seconds": 160, "runs": [run], "gpu_utilisation_percent_once_updating": []}
    with pytest.raises(SystemExit) as stopped:
        training.write_results(result, "x")
    assert stopped.value.code == 1 and list(tmp_path.iterdir()) == []
    assert capsys.readouterr().err == "error: no run reached its updates in 160 s; no results written\n"
    rated = {**run, "steps_per_s_updating": 20.0}
    result = {
        **result,
        "command": "c",
        "machine": "m",
        "date": "d",
        "runs": [rated],
        "gpu_memory_used_mib_max": 1,
    }
    training.write_results(result, "x")
    assert json.loads((tmp_path / "x.json").read_text())["runs"] == [rated]
    assert "| rlad-0 | 3 | 600 | 40 | 20.0 |" in (tmp_path / "x.md").read_text()


def test_nvidia_smis_samples_are_read():
    training = _script("rlad_gpu_training")
    text = (
        "timestamp, utilization.gpu [%], memory.used [MiB]\n"
        "2026/11/27 18:11:56.927, 0 %, 0 MiB\n"
        "2026/11/27 18:12:01.932, 98 %, 22309 MiB\n"
    )
    assert training.gpu_samples(text) == [
        {"utilisation": 0, "memory_mib": 0},
        {"utilisation": 98, "memory_mib": 22309},
    ]


@pytest.mark.skipif(
    __import__("shutil").which("nvidia-smi") is not None, reason="this machine has an NVIDIA GPU"
)
def test_rlad_gpu_training_refuses_a_machine_without_a_gpu_in_one_line(tmp_path):
    results = BENCHMARKS / "results" / "rlad_gpu_training.json"
    before = results.read_bytes()
    done = subprocess.run(
        [sys.executable, str(BENCHMARKS / "rlad_gpu_training.py"), "--seconds", "5"],
        capture_output=True, text=True, cwd=tmp_path,
    )  # fmt: skip
    assert (done.returncode, done.stdout) == (2, "")
    assert done.stderr == "error: this benchmark needs an NVIDIA GPU: nvidia-smi was not found\n"
    assert results.read_bytes() == before and list(tmp_path.iterdir()) == []
