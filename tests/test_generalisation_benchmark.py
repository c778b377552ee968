"""benchmarks/generalisation.py's statistics: the Wilson interval, the gap's bootstrap, and the
rows made from two evaluations (its training and evaluation go through tested library code)."""

import importlib.util
import math
from pathlib import Path

import numpy as np
import pytest
from scipy import stats

SCRIPT = Path(__file__).parents[1] / "benchmarks" / "generalisation.py"


@pytest.fixture(scope="module")
def bench():
    spec = importlib.util.spec_from_file_location("generalisation", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.mark.parametrize(("successes", "n"), [(0, 10), (50, 100), (7, 100), (100, 100), (3, 4)])
def test_wilson_matches_scipy(bench, successes, n):
    expected = stats.binomtest(successes, n).proportion_ci(confidence_level=0.9, method="wilson")
    low, high = bench.wilson(successes, n)
    assert low == pytest.approx(expected.low, abs=1e-12) and high == pytest.approx(expected.high, abs=1e-12)


def test_gap_bootstrap_brackets_the_difference(bench):
    train, test = np.r_[np.ones(60), np.zeros(40)], np.r_[np.ones(20), np.zeros(80)]
    low, high = bench.gap_bootstrap(train, test)
    assert low < 0.4 < high and 0.25 < low and high < 0.55  # ± about 1.645 × 0.064
    assert bench.gap_bootstrap(np.ones(10), np.ones(10)) == (0.0, 0.0)


def _report(successes, crashes, off_road, n):
    episodes = [
        {"success": float(k < successes), "crashed": float(successes <= k < successes + crashes),
         "off_road_events": int(successes + crashes <= k < successes + crashes + off_road),
         "route_completion": 1.0 if k < successes else 0.5}
        for k in range(n)
    ]  # fmt: skip
    return {"per_episode": episodes}


def test_rows_and_groups(bench):
    rows = [
        bench.run_row(10, 0, _report(8, 1, 1, 10), _report(3, 2, 5, 10)),
        bench.run_row(10, 1, _report(6, 2, 2, 10), _report(1, 4, 5, 10)),
    ]
    first = rows[0]
    assert (first["train_success"], first["test_success"], first["gap"]) == (0.8, 0.3, pytest.approx(0.5))
    test = (first["test_crash"], first["test_out_of_road"], first["test_route_completion"])
    assert test == (0.2, 0.5, pytest.approx(0.65))
    assert first["train_success_ci90"] == bench.wilson(8, 10)
    group = bench.group_row(10, rows)
    assert group["test_success"] == pytest.approx(0.2) and group["gap"] == pytest.approx(0.5)
    assert group["test_success_ci90_pooled"] == bench.wilson(4, 20)
    low, high = group["test_success_ci90_seeds"]
    assert 0.1 <= low <= 0.2 <= high <= 0.3  # the bootstrap over two seeds stays within their values
    single = bench.group_row(10, rows[:1])
    assert math.isnan(single["gap_ci90_seeds"][0])


def test_the_listed_command_trains_the_runs_config(bench, monkeypatch):
    """The command the report lists (with benchmarks/maps-N.yaml) makes the config the script
    trains from its own values: a reader who pastes it gets the same run."""
    from drivelab.cli import train_config
    from drivelab.config import build_config
    from drivelab.hyperparams import with_shipped_hyperparams

    monkeypatch.chdir(SCRIPT.parents[1])
    for maps in (1, 10, 100):
        arguments = bench.train_arguments(maps, 2, 4096)
        assert arguments[0] == "train"
        expected = build_config(with_shipped_hyperparams(bench.run_values(maps, 2, 4096)))
        assert train_config(arguments[1:]) == expected
