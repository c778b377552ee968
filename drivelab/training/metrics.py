"""The evaluation metrics, written once: name, label, the better direction and the values they take
(read by ``evaluate``, ``compare`` and ``tune``)."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Metric:
    """One number of an evaluation report (``evaluate.aggregate``).

    :param name: its key in ``eval.json`` and ``evaluations.csv``.
    :param label: how tables and plots name it (with its unit).
    :param better: "maximize" or "minimize": the direction a study takes on it unless told.
    :param values: "rate" (in [0, 1]), "signed" (any finite number) or "count" (>= 0)."""

    name: str
    label: str
    better: str
    values: str


METRICS: dict[str, Metric] = {
    metric.name: metric
    for metric in (
        Metric("mean_return", "episode return", "maximize", "signed"),
        Metric("success_rate", "success rate", "maximize", "rate"),
        Metric("crash_rate", "crash rate", "minimize", "rate"),
        Metric("mean_distance_km", "distance per episode (km)", "maximize", "count"),
        Metric("mean_speed_mps", "mean speed (m/s)", "maximize", "signed"),
        Metric("mean_length", "episode length (steps)", "maximize", "count"),
        Metric("collisions_per_km", "collisions per km", "minimize", "count"),
        Metric("off_road_per_km", "off-road events per km", "minimize", "count"),
        Metric("red_lights_per_km", "red lights run per km", "minimize", "count"),
        Metric("blocked_per_km", "blocked per km", "minimize", "count"),
        Metric("route_completion", "route completion", "maximize", "rate"),
    )
}


def labels(names: tuple[str, ...]) -> dict[str, str]:
    """{name: label} of ``names``, in their order."""
    return {name: METRICS[name].label for name in names}
