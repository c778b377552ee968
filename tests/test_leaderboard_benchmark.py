"""benchmarks/leaderboard.py's own arithmetic: pooled rates, verdicts, the rows made from reports,
and its bad input (its training and evaluation run drivelab's tested commands)."""

import importlib.util
import subprocess
import sys
from pathlib import Path

import pytest

SCRIPT = Path(__file__).parents[1] / "benchmarks" / "leaderboard.py"


@pytest.fixture(scope="module")
def board():
    spec = importlib.util.spec_from_file_location("leaderboard", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    sys.modules["leaderboard"] = module  # its dataclass looks its module up
    spec.loader.exec_module(module)
    return module


def _evaluation(success, crash, off_road, speed, n=10):
    """An ``evaluate`` report of n episodes: the first ``success`` succeed, the next ``crash`` crash,
    the next ``off_road`` leave the road."""
    episodes = [{"off_road_events": int(success + crash <= k < success + crash + off_road)} for k in range(n)]
    return {"episodes": n, "success_rate": success / n, "crash_rate": crash / n, "mean_speed_mps": speed,
            "mean_return": 1.0, "per_episode": episodes}  # fmt: skip


def _time(wall, cpu):
    return {"wall_s": wall, "cpu_s": cpu}


def test_rates_pool_every_seeds_episodes(board):
    pooled = board._wilson([0.2, 0.4], [10, 30])
    assert pooled["rate"] == pytest.approx(14 / 40) and pooled["episodes"] == 40
    assert pooled["low"] < 14 / 40 < pooled["high"]
    assert board._wilson([None], [10]) is None


def test_verdict_needs_the_whole_interval(board):
    assert board._verdict({"rate": 0.9, "low": 0.81, "high": 0.95}, 0.80) == "met"
    assert board._verdict({"rate": 0.8, "low": 0.70, "high": 0.88}, 0.80) == "undecided"
    assert board._verdict({"rate": 0.5, "low": 0.40, "high": 0.60}, 0.80) == "not met"


def test_summary_of_evaluations(board):
    record = {
        "judge": "evaluate",
        "seeds": {
            0: {"steps": 1000, "training": _time(60.0, 30.0), "report": _evaluation(5, 2, 1, 20.0)},
            1: {"steps": 1000, "training": _time(120.0, 90.0), "report": _evaluation(7, 1, 0, 22.0)},
        },
    }
    summary = board.summarise(record)
    assert summary["success_rate"]["rate"] == pytest.approx(12 / 20)
    assert summary["crash_rate"]["rate"] == pytest.approx(3 / 20)
    assert summary["off_road_rate"]["rate"] == pytest.approx(1 / 20)
    assert summary["mean_speed_mps"]["mean"] == pytest.approx(21.0)
    assert summary["train_cpu_s"]["mean"] == pytest.approx(60.0) and summary["steps"] == [1000]
    record.update(scenario="highway", name="ppo", what="w", command="c", trained_by="t", missing=[2])
    record["summary"] = summary
    text = board.markdown({"command": "x", "machine": "m", "date": "d", "entries": [record]})
    assert "| ppo | 0,1 | 20 | 60 [" in text and "highway / ppo: seeds [2]" in text


def test_racetrack_counts_clean_episodes_of_a_lap(board):
    """The racetrack's target is >= 1 lap clean: a clean episode shorter than a lap does not count."""
    episodes = [
        {"success": 1.0, "distance_km": 0.5, "off_road_events": 0},
        {"success": 1.0, "distance_km": 0.3, "off_road_events": 0},  # clean, but short of a lap
        {"success": 0.0, "distance_km": 0.9, "off_road_events": 0},
        {"success": 1.0, "distance_km": board.LAP_M / 1000, "off_road_events": 0},
    ]
    report = {"env": "racetrack", "episodes": 4, "success_rate": 0.75, "crash_rate": 0.25,
              "mean_speed_mps": 10.0, "mean_return": 1.0, "per_episode": episodes}  # fmt: skip
    record = {"judge": "evaluate", "seeds": {0: {"steps": 10, "training": None, "report": report}}}
    summary = board.summarise(record)
    assert summary["lap_rate"]["rate"] == pytest.approx(2 / 4)
    assert summary["success_rate"]["rate"] == pytest.approx(3 / 4)
    assert board._target_verdict(summary, board.TARGETS["racetrack"]) == "not met"
    record.update(scenario="racetrack", name="sac", what="w", command="c", trained_by="t", missing=[])
    record["summary"] = summary
    text = board.markdown({"command": "x", "machine": "m", "date": "d", "entries": [record]})
    assert "| sac | 0 | 4 | 75 [" in text and "≥ 1 lap clean %" in text
    assert text.count("| not met |") == 1
    expert = {**record, "name": "expert", "judged": False}  # the teacher: shown, never judged
    text = board.markdown({"command": "x", "machine": "m", "date": "d", "entries": [record, expert]})
    assert text.count("| not met |") == 1 and "| expert | 0 | 4 |" in text
    assert board._metrics({**report, "env": "highway"})["lap_rate"] is None


def test_nocrash_summary_per_level(board):
    level = {"episodes": 4, "success_rate": 0.75, "crash_rate": 0.25, "mean_speed_mps": 5.0}
    report = {"levels": {name: level for name in ("empty", "regular", "dense")}}
    record = {"judge": "nocrash", "seeds": {0: {"steps": 10, "training": None, "report": report}}}
    summary = board.summarise(record)
    assert summary["levels"]["dense"]["success"]["rate"] == pytest.approx(0.75)
    assert summary["train_wall_s"] is None


def test_every_entry_names_a_command_with_its_seed(board):
    for entry in board.ENTRIES:
        command = entry.command(7)
        assert command[0] == "train" and "--seed" in command and command[command.index("--seed") + 1] == "7"
        assert entry.judge in ("evaluate", "nocrash", "maps")


@pytest.mark.parametrize(
    "arguments",
    [["--scenarios", "nowhere"], ["--episodes", "0"], ["--scenarios", "racetrack", "--entries", "dqn"]],
)
def test_bad_input_is_one_error_line(arguments):
    results = SCRIPT.parent / "results" / "leaderboard.json"
    before = results.stat().st_mtime_ns if results.exists() else None
    done = subprocess.run([sys.executable, str(SCRIPT), *arguments], capture_output=True, text=True)
    assert done.returncode == 2 and done.stderr.startswith("error:") and len(done.stderr.splitlines()) == 1
    assert (results.stat().st_mtime_ns if results.exists() else None) == before  # nothing written


def test_target_verdict_reads_each_metrics_side(board):
    met = {"crash_rate": {"low": 0.01, "high": 0.04}, "success_rate": {"low": 0.96, "high": 0.99}}
    assert board._target_verdict(met, board.JUNCTION_TARGETS) == "met"
    straddling = {**met, "crash_rate": {"low": 0.04, "high": 0.09}}
    assert board._target_verdict(straddling, board.JUNCTION_TARGETS) == "undecided"
    missed = {**straddling, "success_rate": {"low": 0.40, "high": 0.60}}
    assert board._target_verdict(missed, board.JUNCTION_TARGETS) == "not met"
    fast = {"crash_rate": met["crash_rate"], "mean_speed_mps": {"mean": 23.0, "low": 22.0, "high": 23.5}}
    assert board._target_verdict(fast, board.TARGETS["highway"]) == "not met"
    assert board._target_verdict(met, {}) == "–"


def test_rows_without_runs_here_keep_their_committed_record_of_the_same_command(board):
    fresh = {"scenario": "merge", "name": "dqn", "command": "drivelab train --algo dqn --seed S", "seeds": {},
             "missing": [0, 1, 2], "measured": "2026-12-01"}  # fmt: skip
    old = {**fresh, "seeds": {"0": {"steps": 10}}, "missing": [], "summary": {"seeds": ["0"]},
           "measured": "2026-11-24"}  # fmt: skip
    assert board.carry_over(fresh, old) is old
    assert board.carry_over(fresh, None) is fresh
    assert (
        board.carry_over(fresh, {**old, "command": "drivelab train --algo dqn --steps 9 --seed S"}) is fresh
    )
    assert board.carry_over(fresh, {**old, "seeds": {}}) is fresh  # never measured: stays missing
    result = {"date": "2026-12-01", "entries": [old, {**old, "measured": "2026-12-01"}, fresh]}
    note, rule = board._carried_note(result)  # measured on 2026-11-24, before the success rule
    assert note.count("merge / dqn (2026-11-24)") == 1 and "2026-12-01" not in note.split(": ", 1)[1]
    assert rule.endswith("merge / dqn.  ") and "before 2026-11-27" in rule
    assert board._carried_note({**result, "entries": [fresh]}) == []
    (note,) = board._carried_note({**result, "entries": [{**old, "measured": "2026-11-30"}]})
    assert "(2026-11-30)" in note
    (note,) = board._carried_note({**result, "entries": [{**old, "scenario": "highway"}]})  # no arrival
    assert "highway / dqn (2026-11-24)" in note


def _options(arguments) -> dict[str, list[str]]:
    """A command's options: flag → its values, sorted (``-H`` is given many times)."""
    assert arguments[0] == "train" and len(arguments) % 2 == 1
    options: dict[str, list[str]] = {}
    for flag, value in zip(arguments[1::2], arguments[2::2], strict=True):
        assert flag.startswith("-") and not value.startswith("--"), (flag, value)
        options.setdefault(flag, []).append(value)
    return {flag: sorted(values) for flag, values in options.items()}


def test_rows_of_runs_another_benchmark_trains_show_that_benchmarks_command(board):
    """A row whose run another script trains names exactly the command that trained it (the town
    PPO row once showed a command without its reward, traffic and minibatch size, and the OSX
    Dueling DDQN row 5000 steps where its runs have 2500)."""
    import generalisation
    import highway_competence
    import nocrash_town
    import seed003_osx
    import town_competence

    checked = set()
    for entry in (e for e in board.ENTRIES if e.reuse):
        run = entry.run_dir(0).name
        if entry.reused_by == "benchmarks/nocrash_town.py":
            trainer = ["train", *nocrash_town.agents()[run], *nocrash_town.COMMON, "--name", run]
        elif entry.reused_by == "benchmarks/seed003_osx.py":
            trainer = seed003_osx.train_command(entry.name, 0, seed003_osx.DEFAULT_STEPS[entry.name])
        elif entry.reused_by == "benchmarks/highway_competence.py":
            recipe = run.removeprefix(f"competence-{entry.scenario}-").rsplit("-s", 1)[0]
            steps = highway_competence.RECIPES[recipe]["steps"]
            trainer = highway_competence.train_arguments(entry.scenario, recipe, steps, 0, run)
        elif entry.reused_by == "benchmarks/town_competence.py":
            trainer = town_competence.train_arguments(entry.name.split("(")[1].rstrip(")"), 0, run)
        else:
            assert entry.reused_by == "benchmarks/generalisation.py"
            maps = int(entry.name.removeprefix("ppo (").removesuffix(" maps)"))
            steps = int(_options(entry.command(0))["--steps"][0])
            trainer = generalisation.train_arguments(maps, 0, steps)
        assert _options(entry.command(0)) == _options(trainer), (entry.scenario, entry.name)
        checked.add(entry.reused_by)
    assert len(checked) == 5


def test_a_report_of_an_older_model_is_not_reused(board, tmp_path):
    """A row's evaluation is made again when its run was trained again: the report records the
    model's SHA-256 (older reports: written after the model)."""
    import hashlib
    import os

    model, path = tmp_path / "model.zip", tmp_path / "eval.json"
    model.write_bytes(b"weights")
    path.write_text("{}")
    digest = hashlib.sha256(b"weights").hexdigest()
    assert board._of_this_model({"model_sha256": digest}, path, model)
    model.write_bytes(b"weights trained again")
    assert not board._of_this_model({"model_sha256": digest}, path, model)
    os.utime(path, (1_000, 1_000))  # an old report without a digest: older than the model
    assert not board._of_this_model({}, path, model)
    os.utime(model, (500, 500))
    assert board._of_this_model({}, path, model)
