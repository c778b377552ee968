"""benchmarks/provenance.py: the command line a benchmark records is the one that ran."""

import importlib.util
import sys
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


def test_every_benchmark_parses_its_arguments_with_the_one_line_parser_and_checked_types():
    """No benchmark builds argparse's own parser (a usage block before its error line), and no
    option is a bare int or float (a count of 0 or -1 ran, and wrote results of nothing)."""
    import ast

    parsers = {}
    for script in sorted(BENCHMARKS.glob("*.py")):
        calls = [n for n in ast.walk(ast.parse(script.read_text())) if isinstance(n, ast.Call)]
        names = {ast.unparse(call.func) for call in calls}
        assert "argparse.ArgumentParser" not in names and "ArgumentParser" not in names, script.name
        parsers[script.name] = "Parser" in names
        parsed_late = [
            ast.unparse(c) for c in calls if ast.unparse(c).startswith(("json.loads(args.", "int(args."))
        ]
        assert not parsed_late, (script.name, parsed_late)  # a type= checks it before any work
        for call in (c for c in calls if ast.unparse(c.func).endswith("add_argument")):
            types = [ast.unparse(k.value) for k in call.keywords if k.arg == "type"]
            assert types not in (["int"], ["float"]), (script.name, ast.unparse(call))
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


def test_the_argument_types_refuse_what_makes_no_sense(tmp_path, capsys):
    provenance = _provenance()
    parser = provenance.Parser()
    parser.add_argument("--steps", type=provenance.whole(), default=3)
    parser.add_argument("--offset", type=provenance.whole(0), default=0)
    parser.add_argument("--seeds", type=provenance.wholes(), default="0,1,2")
    parser.add_argument("--agents", type=provenance.names(("ppo", "dqn")), default="ppo,dqn")
    parser.add_argument("--steps-of", type=provenance.step_overrides(("ppo", "dqn")), default="")
    parser.add_argument("--duration-s", type=provenance.positive)
    parser.add_argument("--hyperparams", type=provenance.mapping)
    parser.add_argument("--notes", type=provenance.readable)
    parser.add_argument("--device", type=provenance.device, default="cpu")
    (tmp_path / "notes.md").write_text("seen")
    args = parser.parse_args(
        ["--seeds", "4,0", "--steps-of", "dqn=5", "--duration-s", "2.5", "--hyperparams", '{"a": 1}',
         "--notes", str(tmp_path / "notes.md")]
    )  # fmt: skip
    assert (args.steps, args.offset, args.seeds, args.agents) == (3, 0, [4, 0], ["ppo", "dqn"])
    assert (args.steps_of, args.duration_s, args.hyperparams, args.notes) == (
        {"dqn": 5},
        2.5,
        {"a": 1},
        "seen",
    )
    for argv, message in (
        (["--steps", "0"], "argument --steps: 0 is below 1"),
        (["--steps", "2.5"], "argument --steps: '2.5' is not a whole number"),
        (["--offset", "-1"], "argument --offset: -1 is below 0"),
        (["--seeds", "0,abc"], "argument --seeds: 'abc' is not a whole number"),
        (["--seeds", "1,1"], "argument --seeds: '1,1' names a value twice"),
        (["--agents", "ppo,sac"], "argument --agents: unknown 'sac' (known: ppo, dqn)"),
        (["--steps-of", "sac=5"], "argument --steps-of: 'sac=5' is not NAME=STEPS, NAME one of ppo, dqn"),
        (["--steps-of", "ppo=0"], "argument --steps-of: 0 is below 1"),
        (["--duration-s", "nan"], "argument --duration-s: 'nan' is not a finite number above 0"),
        (["--duration-s", "0"], "argument --duration-s: '0' is not a finite number above 0"),
        (["--hyperparams", "{bad"], "argument --hyperparams: not JSON (Expecting property name enclosed in "
         "double quotes at character 1)"),
        (["--hyperparams", "[1]"], "argument --hyperparams: '[1]' is not a JSON object"),
        (["--notes", str(tmp_path / "none.md")], f"argument --notes: cannot read '{tmp_path / 'none.md'}' "
         "(No such file or directory)"),
        (["--device", "gpu"], "argument --device: 'gpu' is not cpu or cuda[:N]"),
    ):  # fmt: skip
        with pytest.raises(SystemExit) as stopped:
            parser.parse_args(argv)
        assert stopped.value.code == 2 and capsys.readouterr().err == f"error: {message}\n", argv


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


def test_a_nonsensical_count_stops_a_benchmark_before_it_writes(tmp_path):
    """pg_maps.py --seeds 0 once overwrote its committed results with a mean of nothing."""
    import subprocess
    import sys

    results = BENCHMARKS / "results" / "pg_maps.json"
    before = results.read_bytes()
    done = subprocess.run(
        [sys.executable, str(BENCHMARKS / "pg_maps.py"), "--seeds", "0"], capture_output=True, text=True
    )
    assert (done.returncode, done.stdout, done.stderr) == (2, "", "error: argument --seeds: 0 is below 1\n")
    assert results.read_bytes() == before


def test_a_benchmark_continues_a_run_a_kill_left_unfinished(tmp_path):
    provenance = _provenance()
    run_dir, train = tmp_path / "runs" / "r", ["train", "--algo", "ppo", "--name", "r"]
    assert provenance.training_command(run_dir, train, tmp_path) == (train, False)
    run_dir.mkdir(parents=True)
    (run_dir / "config.yaml").write_text("algo: ppo\n")  # started: drivelab train --resume continues it
    assert provenance.training_command(run_dir, train, tmp_path) == (["train", "--resume", "runs/r"], True)


def _benchmark(name):
    folder = str(SCRIPT.parent)
    sys.path.insert(0, folder)
    try:
        spec = importlib.util.spec_from_file_location(name, SCRIPT.parent / f"{name}.py")
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
    finally:
        sys.path.remove(folder)
    return module


def _option(arguments: list[str], name: str) -> int:
    return int(arguments[arguments.index(name) + 1])


@pytest.mark.parametrize("steps", [500, 5_000, 1_000_000])
def test_the_benchmarks_train_commands_evaluate_within_their_budget(steps):
    """``drivelab train`` refuses an ``--eval-every`` above ``--steps``: the town benchmarks' and
    the GPU training's commands stay within it at any budget (nocrash_town asked for at least
    10 000 steps between evaluations, rlad_gpu_training for ten budgets)."""
    commands = [
        *_benchmark("nocrash_town").agents(steps, 8).values(),
        *_benchmark("imitation_town").agents(steps, 8).values(),
        _benchmark("rlad_gpu_training").train_command("rlad", 0, steps, Path("runs")),
    ]
    for arguments in commands:
        if "--eval-every" not in arguments:  # the expert's run: the default schedule
            continue
        assert 0 <= _option(arguments, "--eval-every") <= _option(arguments, "--steps")
