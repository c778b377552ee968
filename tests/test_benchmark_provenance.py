"""benchmarks/provenance.py: the command line a benchmark records is the one that ran."""

import importlib.util
from pathlib import Path

import pytest
import yaml

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


def _run_of(root, env: str, option: str):
    """``drivelab train`` arguments of a small PPO run on ``env`` and its run folder under ``root``,
    holding the config those arguments make (as a finished run's)."""
    from drivelab.cli import train_config

    arguments = ["train", "--algo", "ppo", "--env", env, "--obs", "kinematics", "--steps", "2048",
                 "-H", option, "--seed", "1", "--runs-dir", "runs", "--name", "r"]  # fmt: skip
    run = root / "runs" / "r"
    run.mkdir(parents=True)
    (run / "config.yaml").write_text(yaml.safe_dump(train_config(arguments[1:]).to_dict()))
    return arguments, run


def test_a_run_is_reused_only_when_the_command_trains_its_config(tmp_path, capsys):
    """A benchmark that finds a finished run lists its command beside the run's numbers: a run of
    another config (here fewer steps, or other shipped hyper-parameters) stops it in one line."""
    provenance = _provenance()
    arguments, run = _run_of(tmp_path, "merge", "gamma=0.9")
    provenance.check_reuse(run, arguments, tmp_path)  # the same run: reused
    for changed in (["--steps", "4096"], ["-H", "n_steps=64"]):
        with pytest.raises(SystemExit) as stop:
            provenance.check_reuse(run, [*arguments, *changed], tmp_path)
        error = capsys.readouterr().err
        assert stop.value.code == 2 and error.startswith("error: ") and len(error.splitlines()) == 1
        assert ("steps differ" in error) if changed[0] == "--steps" else ("hyperparams differ" in error)


def test_pinning_an_agents_own_defaults_trains_the_same_run(tmp_path, capsys):
    """A recipe that pins SB3's defaults (clip_range 0.2, as the zoo's PPO cards do) names the run
    trained without them; a broken run config is one error line."""
    provenance = _provenance()
    arguments, run = _run_of(tmp_path, "highway", "n_steps=256")
    assert "clip_range" not in yaml.safe_load((run / "config.yaml").read_text())["hyperparams"]
    provenance.check_reuse(run, [*arguments, "-H", "clip_range=0.2", "-H", "ent_coef=0.0"], tmp_path)
    with pytest.raises(SystemExit):
        provenance.check_reuse(run, [*arguments, "-H", "clip_range=0.3"], tmp_path)
    capsys.readouterr()
    (run / "config.yaml").write_text("algo: ppo\nold_field: 1\n")
    with pytest.raises(SystemExit) as stop:
        provenance.check_reuse(run, arguments, tmp_path)
    error = capsys.readouterr().err
    assert stop.value.code == 2 and error.startswith("error: ") and len(error.splitlines()) == 1


BENCHMARKS = SCRIPT.parent


def test_every_benchmark_parses_its_arguments_with_the_one_line_parser():
    """No benchmark builds argparse's own parser (a usage block before its error line)."""
    import ast

    parsers = {}
    for script in sorted(BENCHMARKS.glob("*.py")):
        calls = [n for n in ast.walk(ast.parse(script.read_text())) if isinstance(n, ast.Call)]
        names = {ast.unparse(call.func) for call in calls}
        assert "argparse.ArgumentParser" not in names and "ArgumentParser" not in names, script.name
        parsers[script.name] = "Parser" in names
    assert sum(parsers.values()) >= 30  # the scripts that take arguments


def test_a_bad_argument_is_one_error_line_and_exit_2(capsys):
    parser = _provenance().Parser(description="a benchmark")
    parser.add_argument("--steps", type=int, default=3)
    for argv, message in (
        (["--steps", "many"], "error: argument --steps: invalid int value: 'many'"),
        (["--bogus"], "error: unrecognized arguments: --bogus"),
    ):
        with pytest.raises(SystemExit) as stopped:
            parser.parse_args(argv)
        assert stopped.value.code == 2
        assert capsys.readouterr().err == message + "\n"
    assert parser.parse_args(["--steps", "5"]).steps == 5


@pytest.mark.parametrize("script", ["zoo_build.py", "pg_maps.py"])
def test_a_benchmark_script_refuses_bad_input_in_one_line(script, tmp_path):
    import subprocess
    import sys

    done = subprocess.run(
        [sys.executable, str(BENCHMARKS / script), "--no-such-option"],
        capture_output=True,
        text=True,
        cwd=tmp_path,
    )
    assert done.returncode == 2 and done.stdout == ""
    assert done.stderr == "error: unrecognized arguments: --no-such-option\n"
    assert list(tmp_path.iterdir()) == []
