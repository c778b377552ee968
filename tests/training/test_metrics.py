"""The metrics registry: every table that shows metrics names registered ones, and the registry
names only what an evaluation report holds, with values of the kind it says."""

import math

import pytest

from drivelab.training import compare, compare_plots, evaluate, tune
from drivelab.training.evaluate import aggregate
from drivelab.training.metrics import METRICS

EPISODES = [
    {"return": 3.0, "distance_km": 0.5, "success": True, "crashed": False, "mean_speed_mps": 20.0,
     "length": 40, "collisions": 0, "pedestrian_collisions": 0, "off_road_events": 1, "red_lights": 0,
     "blocked": 0, "route_completion": 1.0},
    {"return": -1.0, "distance_km": 0.2, "success": False, "crashed": True, "mean_speed_mps": 12.0,
     "length": 15, "collisions": 1, "pedestrian_collisions": 0, "off_road_events": 0, "red_lights": 1,
     "blocked": 2, "route_completion": 0.4},
]  # fmt: skip


@pytest.mark.parametrize(
    "table", [compare.METRICS, tune.METRICS, evaluate.METRIC_LABELS, compare_plots.BAR_METRICS]
)
def test_every_table_shows_registered_metrics(table):
    assert set(table) <= set(METRICS)


def test_labels_and_directions_come_from_the_registry():
    assert compare.METRICS["off_road_per_km"] == compare_plots.BAR_METRICS.get(
        "off_road_per_km", METRICS["off_road_per_km"].label
    ) == METRICS["off_road_per_km"].label  # fmt: skip
    assert tune.METRICS["crash_rate"] == "minimize" and tune.METRICS["mean_speed_mps"] == "maximize"


def test_the_registry_names_what_an_evaluation_reports_with_values_of_its_kind():
    report = aggregate(EPISODES)
    for name, metric in METRICS.items():
        value = report[name]
        assert isinstance(value, float) and math.isfinite(value), name
        assert metric.better in ("maximize", "minimize")
        if metric.values == "rate":
            assert 0.0 <= value <= 1.0, name
        elif metric.values == "count":
            assert value >= 0.0, name


def test_a_scenario_without_a_goal_says_what_its_success_rate_measures():
    """On the highway (no goal) success is reaching the time limit without a crash or leaving the
    road: a slow, safe policy's 100 % is labelled as that; with a goal (merge) it is the plain rate."""
    from drivelab.training.evaluate import NO_GOAL_SUCCESS, metrics_rows

    report = {"mean_return": 1.0, "std_return": 0.0, "success_rate": 1.0, "crash_rate": 0.0,
              "mean_distance_km": 0.6, "mean_speed_mps": 20.0, "collisions_per_km": 0.0,
              "off_road_per_km": 0.0, "red_lights_per_km": 0.0, "blocked_per_km": 0.0,
              "route_completion": None}  # fmt: skip
    highway = dict(metrics_rows(report, "highway"))
    assert highway[NO_GOAL_SUCCESS] == "1.000" and "success rate" not in highway
    assert dict(metrics_rows(report, "merge"))["success rate"] == "1.000"
    assert dict(metrics_rows(report))["success rate"] == "1.000"  # no scenario named: the plain label
