"""Comparisons: grouping over seeds, the numbers in the report, and refusing bad input."""

import csv
import json

import numpy as np
import pandas as pd
import pytest

from drivelab.config import build_config, save_yaml
from drivelab.errors import UsageError
from drivelab.training import compare as compare_module
from drivelab.training.compare import compare, find_runs, group_runs, load_run

METRIC_ROW = {
    "episodes": 2, "std_return": 0.0, "success_rate": 1.0, "crash_rate": 0.0, "mean_distance_km": 0.5,
    "mean_speed_mps": 20.0, "mean_length": 30.0, "collisions_per_km": 0.0, "off_road_per_km": 0.0,
    "route_completion": None,
}  # fmt: skip


def fake_run(
    root,
    name,
    algo="ppo",
    seed=0,
    reward="highway",
    final_return=None,
    curve=((10, 0.0), (20, 1.0)),
    hyperparams=None,
    **fields,
):
    """A run directory as drivelab train writes it, with chosen evaluation returns (``fields``: other
    config fields)."""
    run_dir = root / name
    run_dir.mkdir(parents=True)
    values = {"algo": algo, "seed": seed, "reward": reward, "steps": 20, "name": name, **fields}
    config = build_config({**values, "hyperparams": hyperparams or {}})
    save_yaml(config, run_dir / "config.yaml")
    with (run_dir / "evaluations.csv").open("w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=["step", "mean_return", *METRIC_ROW])
        writer.writeheader()
        for step, value in curve:
            writer.writerow({"step": step, "mean_return": value, **METRIC_ROW, "route_completion": ""})
    if final_return is not None:
        (run_dir / "eval.json").write_text(json.dumps({**METRIC_ROW, "mean_return": final_return}))
    return run_dir


@pytest.fixture
def runs(tmp_path):
    root = tmp_path / "runs"
    fake_run(root, "ppo-s0", seed=0, final_return=0.0)
    fake_run(root, "ppo-s1", seed=1, final_return=0.0)
    fake_run(root, "ppo-s2", seed=2, final_return=1.0)
    fake_run(root, "dqn-s0", algo="dqn", seed=0, curve=((10, 2.0), (20, 4.0)))  # no eval.json
    fake_run(root, "dqn-s1", algo="dqn", seed=1, curve=((10, 2.0), (20, 6.0)))
    fake_run(root, "ppo-nocrash-s0", seed=0, reward="highway,collision=0", final_return=7.0)
    return root


def test_grouping_over_seeds(runs):
    records = [load_run(p) for p in find_runs([str(runs / "*")])]
    groups = group_runs(records)
    assert {key: [r.config.seed for r in rs] for key, rs in groups.items()} == {
        ("dqn", "highway", "kinematics", "highway", "meta"): [0, 1],
        ("ppo", "highway", "kinematics", "highway,collision=0", "meta"): [0],
        ("ppo", "highway", "kinematics", "highway", "meta"): [0, 1, 2],
    }
    sources = {r.run_dir.name: r.source for r in records}
    assert sources["dqn-s0"] == "evaluations.csv" and sources["ppo-s0"] == "eval.json"


def test_runs_of_different_traffic_or_options_are_different_groups_labelled_by_them(tmp_path):
    """They used to share a group, their values pooled as if seeds of one config (with no word
    when the seeds differed). Conditions all runs share stay out of the labels."""
    root = tmp_path / "runs"
    fake_run(root, "empty-s0", seed=0, traffic="empty")
    fake_run(root, "empty-s1", seed=1, traffic="empty", backend="fast")  # what "auto" picks on highway
    fake_run(root, "dense-s2", seed=2, traffic="dense")
    fake_run(root, "dense-short-s3", seed=3, traffic="dense", env_options={"duration_s": 10})
    groups = group_runs([load_run(p) for p in find_runs([str(root / "*")])])
    assert {key[1]: [r.run_dir.name for r in rs] for key, rs in groups.items()} == {
        "highway (traffic=dense, duration_s=default)": ["dense-s2"],
        "highway (traffic=dense, duration_s=10)": ["dense-short-s3"],
        "highway (traffic=empty, duration_s=default)": ["empty-s0", "empty-s1"],
    }
    same = group_runs([load_run(p) for p in find_runs([str(root / "empty-*")])])
    assert list(same) == [("ppo", "highway", "kinematics", "highway", "meta")]


def test_a_report_of_several_scenarios_says_each_is_evaluated_on_its_own(tmp_path):
    root = tmp_path / "runs"
    fake_run(root, "highway-s0", final_return=1.0)
    fake_run(root, "merge-s0", final_return=2.0, env="merge")
    text = (compare([str(root / "*")], tmp_path / "both") / "report.md").read_text()
    assert "The groups drive different scenarios (highway, merge), each evaluated on its own" in text
    text = (compare([str(root / "highway-*")], tmp_path / "one") / "report.md").read_text()
    assert "different scenarios" not in text


def test_a_report_says_what_success_is_where_a_scenario_has_no_goal(tmp_path):
    root = tmp_path / "runs"
    fake_run(root, "highway-s0", final_return=1.0)
    fake_run(root, "merge-s0", final_return=2.0, env="merge")
    text = (compare([str(root / "*")], tmp_path / "both") / "report.md").read_text()
    assert "\nhighway has no goal to reach: there, success is the time limit reached" in text  # merge has one
    text = (compare([str(root / "merge-*")], tmp_path / "merge") / "report.md").read_text()
    assert "no goal to reach" not in text  # the merge's goal is its end: success is reaching it


def test_report_numbers_and_files(runs, tmp_path):
    out = compare([str(runs / "*")], tmp_path / "report", command="drivelab compare --runs 'runs/*'")
    for name in ("report.md", "summary.csv", "runs.csv", "learning_curves.png", "metrics.png"):
        assert (out / name).is_file() and (out / name).stat().st_size > 0, name
    with (out / "summary.csv").open() as handle:
        rows = {(r["algo"], r["reward"], r["metric"]): r for r in csv.DictReader(handle)}
    ppo = rows[("ppo", "highway", "mean_return")]
    # final returns 0, 0, 1: mean 1/3, 90 % percentile bootstrap (0, 2/3) (see test_stats), IQM = mean
    assert int(ppo["n"]) == 3
    assert float(ppo["mean"]) == pytest.approx(1 / 3)
    assert float(ppo["ci_low"]) == 0.0 and float(ppo["ci_high"]) == pytest.approx(2 / 3)
    assert float(ppo["iqm"]) == pytest.approx(1 / 3)
    dqn = rows[("dqn", "highway", "mean_return")]  # last evaluations.csv rows: 4 and 6
    assert float(dqn["mean"]) == pytest.approx(5.0)
    assert (float(dqn["ci_low"]), float(dqn["ci_high"])) == (4.0, 6.0)
    single = rows[("ppo", "highway,collision=0", "mean_return")]
    assert float(single["mean"]) == 7.0 and single["ci_low"] == "nan"
    assert int(rows[("ppo", "highway", "route_completion")]["n"]) == 0  # None everywhere
    text = (out / "report.md").read_text()
    assert "drivelab compare --runs 'runs/*'" in text
    assert "The groups differ in reward" in text
    assert "| ppo · highway · kinematics · highway · meta | 3 | 0.333 | [0.000, 0.667] | 0.333 |" in text
    with (out / "runs.csv").open() as handle:
        assert len(list(csv.DictReader(handle))) == 6


def test_rewrite_replaces_previous_report(runs, tmp_path):
    """A new report replaces the previous one's files; a file drivelab did not write stays."""
    out = compare([str(runs / "ppo-s*")], tmp_path / "report")
    (out / "notes.txt").write_text("the user's")
    compare([str(runs / "dqn-s0"), str(runs / "dqn-s1")], out)
    assert (out / "notes.txt").read_text() == "the user's"
    assert "dqn" in (out / "summary.csv").read_text() and "ppo" not in (out / "summary.csv").read_text()
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []
    assert [p.name for p in out.iterdir() if p.name.startswith(".")] == []


@pytest.mark.parametrize(
    "args, message",
    [
        (["nowhere"], "does not exist"),
        (["empty/*"], "no run directory matches"),
        ([], "no run directories given"),
    ],
)
def test_bad_input_is_one_line_and_writes_nothing(runs, tmp_path, args, message):
    with pytest.raises(UsageError, match=message):
        compare([str(tmp_path / a) if a else a for a in args], tmp_path / "report")
    assert not (tmp_path / "report").exists()


def test_failure_midway_leaves_nothing(runs, tmp_path, monkeypatch):
    def broken(*args, **kwargs):
        raise RuntimeError("disk full")

    monkeypatch.setattr("drivelab.training.compare_plots.plot_metric_bars", broken)
    with pytest.raises(RuntimeError):
        compare([str(runs / "*")], tmp_path / "report")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["runs"]


def test_a_report_killed_while_written_does_not_block_the_next(runs, tmp_path):
    """A report killed while it was written (SIGKILL of ``drivelab sweep --report`` or ``ablate``)
    leaves its temporary folder: the next report into that folder is written, not refused as a
    folder of the user's, and removes it; the folder of a report being written now stays."""
    import fcntl
    import os

    out = tmp_path / "report"
    stale = out / ".report.tmp-killed"
    stale.mkdir(parents=True)
    (stale / "report.md").write_text("half a report")
    live = out / ".report.tmp-live"
    live.mkdir()
    lock = os.open(live, os.O_RDONLY | os.O_DIRECTORY)
    fcntl.flock(lock, fcntl.LOCK_EX)  # as publish_dir holds its own
    try:
        compare([str(runs / "ppo-s*")], out)
    finally:
        os.close(lock)
    assert (out / "report.md").is_file() and "ppo" in (out / "summary.csv").read_text()
    assert not stale.exists() and live.is_dir()
    compare([str(runs / "dqn-s*")], out)  # a report again: the live one is left over now
    assert [p.name for p in out.iterdir() if p.name.startswith(".")] == []


def test_a_report_on_a_file_system_without_locks_is_written(runs, tmp_path, monkeypatch):
    """On NFS an exclusive flock needs a descriptor open for writing, which a folder's cannot be
    (flock(2), "NFS details"), and some file systems have no locks: the report folder's lock failed
    with a traceback, leaving its temporary folder. Now the report is written unlocked, and a
    leftover folder whose use cannot be told stays (it blocks no report)."""
    import errno
    import fcntl

    def no_locks(fd, operation):
        raise OSError(errno.EBADF, "Bad file descriptor")

    out = tmp_path / "report"
    stale = out / ".report.tmp-killed"
    stale.mkdir(parents=True)
    monkeypatch.setattr(fcntl, "flock", no_locks)
    compare([str(runs / "ppo-s*")], out)
    assert (out / "report.md").is_file() and "ppo" in (out / "summary.csv").read_text()
    assert [p.name for p in out.iterdir() if p.name.startswith(".")] == [stale.name]


def test_a_report_folder_removed_before_it_was_locked_is_made_again(runs, tmp_path, monkeypatch):
    """Another report into the same folder, ending between this one's mkdtemp and its lock, took the
    new folder for one left by a killed report and removed it: FileNotFoundError, a traceback."""
    import tempfile

    out = tmp_path / "report"
    made = []

    def raced(*args, **kwargs):
        path = real(*args, **kwargs)
        if not made:  # the other report's cleanup runs now, before this one locks its folder
            compare_module._remove_stale_tmp_folders(out, keep=out / "theirs")
        made.append(path)
        return path

    real = tempfile.mkdtemp
    monkeypatch.setattr(tempfile, "mkdtemp", raced)
    compare([str(runs / "ppo-s*")], out)
    assert len(made) == 2 and (out / "report.md").is_file()
    assert [p.name for p in out.iterdir() if p.name.startswith(".")] == []


def test_foreign_output_folder_is_refused(runs, tmp_path):
    (tmp_path / "mine").mkdir()
    (tmp_path / "mine" / "notes.txt").write_text("keep")
    with pytest.raises(UsageError, match="is not empty and holds no drivelab report"):
        compare([str(runs / "*")], tmp_path / "mine")
    assert (tmp_path / "mine" / "notes.txt").read_text() == "keep"


def test_run_without_evaluation_is_named(tmp_path):
    run_dir = fake_run(tmp_path, "bare")
    (run_dir / "evaluations.csv").unlink()
    with pytest.raises(UsageError, match="has no evaluation yet"):
        compare_module.load_run(run_dir)


def test_cli_compare(runs, tmp_path):
    from typer.testing import CliRunner

    from drivelab.cli import app

    runner = CliRunner()
    result = runner.invoke(
        app, ["compare", str(runs / "ppo-s0"), "--runs", str(runs / "dqn-*"), "-o", str(tmp_path / "r")]
    )
    assert result.exit_code == 0, result.output
    assert (tmp_path / "r" / "report.md").is_file()
    result = runner.invoke(app, ["compare", "--runs", str(tmp_path / "none-*"), "-o", str(tmp_path / "r2")])
    assert result.exit_code == 2
    assert result.output.strip() == f"error: no run directory matches {str(tmp_path / 'none-*')!r}"
    assert not (tmp_path / "r2").exists()


def test_runs_of_different_budgets_are_different_groups_and_the_report_says_so(runs, tmp_path):
    """They used to share a group (the budget only listed in its steps column), their final
    scores pooled as if seeds of one experiment."""
    fake_run(runs, "ppo-long-s0", seed=0, final_return=5.0, steps=40)
    fake_run(runs, "ppo-long-s1", seed=1, final_return=7.0, steps=40)
    groups = group_runs([load_run(p) for p in find_runs([str(runs / "ppo-s*"), str(runs / "ppo-long-*")])])
    assert {key[1]: [r.run_dir.name for r in rs] for key, rs in groups.items()} == {
        "highway (steps=20)": ["ppo-s0", "ppo-s1", "ppo-s2"],
        "highway (steps=40)": ["ppo-long-s0", "ppo-long-s1"],
    }
    out = compare([str(runs / "ppo-s*"), str(runs / "ppo-long-*")], tmp_path / "report")
    text = (out / "report.md").read_text()
    assert "trained for different budgets (20, 40 steps), and each budget is a group of its own" in text
    summary = pd.read_csv(out / "summary.csv")
    means = summary[summary["metric"] == "mean_return"].set_index("env")["mean"].to_dict()
    assert means == {"highway (steps=20)": pytest.approx(1 / 3), "highway (steps=40)": 6.0}
    text = (compare([str(runs / "ppo-s*")], tmp_path / "one") / "report.md").read_text()
    assert "different budgets" not in text and "steps=" not in text


def test_repeated_seed_is_flagged(runs, tmp_path):
    # the same seed and budget, other evaluation episodes (a copy of the same run is refused:
    # test_cli_input_more.py)
    again = fake_run(runs, "ppo-s0-again", seed=0, final_return=0.0)
    config = load_run(again).config
    save_yaml(build_config({**config.to_dict(), "eval_episodes": 3}), again / "config.yaml")
    text = (compare([str(runs / "ppo-s*")], tmp_path / "report") / "report.md").read_text()
    assert (
        "**Warning:** group ppo · highway · kinematics · highway · meta has several runs with the same seed"
        in text
    )
    text = (
        compare([str(runs / "ppo-s0"), str(runs / "ppo-s1")], tmp_path / "report") / "report.md"
    ).read_text()
    assert "Warning" not in text


def test_pandas_reads_every_csv_column_for_column(runs, tmp_path):
    """With a group that changed hyper-parameters (which once added an unnamed field to its rows),
    every row of both CSVs has the header's fields, pandas reads them under the right names, and
    each group's per-seed values come back as the (runs x tasks) score arrays rliable takes."""
    fake_run(runs, "ppo-lr-s0", seed=0, final_return=3.0, hyperparams={"learning_rate": 0.123, "gamma": 0.5})
    fake_run(runs, "ppo-lr-s1", seed=1, final_return=5.0, hyperparams={"learning_rate": 0.123, "gamma": 0.5})
    out = compare([str(runs / "*")], tmp_path / "report")
    group = ["algo", "env", "obs", "reward", "action", "hyperparams"]
    for name, columns in (
        ("runs.csv", ["run_dir", *group, "seed", "steps", "source", *compare_module.METRICS]),
        ("summary.csv", [*group, "metric", "n", "mean", "ci_low", "ci_high", "iqm"]),
    ):
        with (out / name).open(newline="") as handle:
            header, *rows = list(csv.reader(handle))
        assert header == columns and {len(row) for row in rows} == {len(columns)}, name
        assert list(pd.read_csv(out / name).columns) == columns
    runs_table = pd.read_csv(out / "runs.csv")
    assert runs_table.groupby("algo").size().to_dict() == {"dqn": 2, "ppo": 6}
    changed = "gamma=0.5,learning_rate=0.123"
    assert runs_table.groupby("hyperparams").size().to_dict() == {"shipped": 6, changed: 2}
    assert runs_table["route_completion"].isna().all() and (runs_table["steps"] == 20).all()
    scores = {
        label: table.sort_values("seed")["mean_return"].to_numpy()[:, None]  # rliable: (runs, tasks)
        for label, table in runs_table.groupby(["algo", "reward", "hyperparams"])
    }
    expected = {
        ("dqn", "highway", "shipped"): [4.0, 6.0],
        ("ppo", "highway", "shipped"): [0.0, 0.0, 1.0],
        ("ppo", "highway", changed): [3.0, 5.0],
        ("ppo", "highway,collision=0", "shipped"): [7.0],
    }
    assert scores.keys() == expected.keys()
    for label, values in expected.items():
        np.testing.assert_array_equal(scores[label], np.array(values)[:, None])
    summary = pd.read_csv(out / "summary.csv")
    changed = summary[(summary["hyperparams"] != "shipped") & (summary["metric"] == "mean_return")]
    assert changed[["algo", "n", "mean"]].values.tolist() == [["ppo", 2, 4.0]]
    assert summary.groupby("metric").size().nunique() == 1 and len(summary) == 4 * len(compare_module.METRICS)


def test_curves_are_aligned_where_every_run_has_been_evaluated():
    """A run first evaluated later than another is not extrapolated back to the earlier steps."""
    from drivelab.training.compare_plots import aligned_curves

    early = [(1000, 0.0), (2000, 10.0), (3000, 20.0)]
    late = [(2000, 100.0), (2500, 150.0), (3000, 200.0), (4000, 300.0)]
    steps, values = aligned_curves([early, late])
    assert steps.tolist() == [2000, 2500, 3000]
    assert values.tolist() == [[10.0, 15.0, 20.0], [100.0, 150.0, 200.0]]
    steps, values = aligned_curves([[(1, 0.0)], [(2, 1.0)]])  # no step both reached
    assert steps.size == 0 and values.shape == (2, 0)


def test_confidence_labels_are_not_rounded():
    from drivelab.training.stats import percent

    assert [percent(c) for c in (0.9, 0.95, 0.975, 0.995)] == ["90", "95", "97.5", "99.5"]
