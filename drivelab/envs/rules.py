"""EpisodeRules: how K episodes end — the scenario's events and ``terminated`` / ``truncated`` (K,).

The simulators report what they see during a step (collisions, leaving the road, arrival, red
lights run: ``batch.events``). The rules that need an episode's history or a judgement live here,
once, for every world of a batch:

- blocked: the ego has stood still (below ``BLOCKED_SPEED_MPS``) for longer than the scenario's
  ``blocked_after_s`` — one stopped timer per world, cleared when it moves or its episode starts;
- off the route: the ego is farther than the scenario's ``route_deviation_m`` from its route's
  point at its progress;
- terminated: a collision, the goal reached, a red light run, blocked, off the route, or (with
  ``offroad_terminal``) off the road;
- truncated: not terminated, and the world's clock reached its episode's time limit.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from drivelab.world.batch import WorldBatch

BLOCKED_SPEED_MPS = 0.1  # below this the ego counts as standing still


def episode_time_limits_s(duration_s: float, duration_given: bool, route_limits_s) -> np.ndarray:
    """Each episode's time limit: the scenario's (or the given) duration, unless the episode's route
    brings its own limit (finite in ``route_limits_s``: the town's NoCrash protocol), which a given
    duration still caps."""
    route = np.asarray(route_limits_s, dtype=float)
    capped = np.minimum(route, duration_s) if duration_given else route
    return np.where(np.isfinite(route), capped, float(duration_s))


class EpisodeRules:
    """The episode rules of one scenario over K worlds, with each world's stopped timer and time limit.

    :param scenario: the scenario (its ``blocked_after_s`` and ``route_deviation_m``; None: no such rule).
    :param offroad_terminal: leaving the road ends the episode.
    """

    def __init__(self, scenario, offroad_terminal: bool = True) -> None:
        self.blocked_after_s: float | None = scenario.blocked_after_s
        self.route_deviation_m: float | None = scenario.route_deviation_m
        self.offroad_terminal = bool(offroad_terminal)
        self.stopped_s = np.zeros(0)  # (K,) seconds each ego has stood still
        self.time_limit_s = np.zeros(0)  # (K,) each episode's time limit
        self.truncate_at_s = np.zeros(0)  # (K,) the limit less 1e-9 s (set with it)

    def reset(self, mask: np.ndarray, time_limit_s: np.ndarray | float) -> None:
        """Start the episodes of the worlds where ``mask`` (K,): their stopped timers cleared, their
        time limits set from ``time_limit_s`` ((K,) or one for all). A new K starts every world."""
        mask = np.asarray(mask, dtype=bool)
        if len(mask) != len(self.stopped_s):
            self.stopped_s, self.time_limit_s = np.zeros(len(mask)), np.full(len(mask), np.inf)
            mask = np.ones(len(mask), dtype=bool)
        limits = np.broadcast_to(np.asarray(time_limit_s, dtype=float), mask.shape)
        self.stopped_s[mask] = 0.0
        self.time_limit_s[mask] = limits[mask]
        # a step's time reaching it truncates (written in place: the compiled circuit step holds it)
        if self.truncate_at_s.shape != self.time_limit_s.shape:
            self.truncate_at_s = np.empty_like(self.time_limit_s)
        np.subtract(self.time_limit_s, 1e-9, out=self.truncate_at_s)

    def apply(self, batch: WorldBatch) -> tuple[WorldBatch, np.ndarray, np.ndarray]:
        """``(batch with its blocked / off_route events, terminated (K,), truncated (K,))`` for the
        batch a step has just produced (each world's stopped timer advances by one step)."""
        if len(batch.time_s) != len(self.stopped_s):
            raise ValueError(
                f"reset the rules for {len(batch.time_s)} worlds (they hold {len(self.stopped_s)})"
            )
        if self.blocked_after_s is not None or self.route_deviation_m is not None:
            batch = self._judge(batch)
        events, count = batch.events, len(self.stopped_s)
        terminated, truncated = np.empty(count, dtype=bool), np.empty(count, dtype=bool)
        episode_ends(
            events.collided, events.arrived, events.red_light_crossed, events.blocked, events.off_route,
            events.off_road, self.offroad_terminal, batch.time_s, self.truncate_at_s, terminated, truncated,
        )  # fmt: skip
        return batch, terminated, truncated

    def _judge(self, batch: WorldBatch) -> WorldBatch:
        """The blocked and route-deviation events of ``batch``."""
        moving = batch.ego.speed_mps >= BLOCKED_SPEED_MPS
        self.stopped_s = np.where(moving, 0.0, self.stopped_s + batch.dt_s)
        blocked = np.zeros(len(moving), dtype=bool)
        if self.blocked_after_s is not None:
            blocked = self.stopped_s > self.blocked_after_s
        off_route = np.zeros(len(moving), dtype=bool)
        if self.route_deviation_m is not None:
            point, _ = batch.route.pose()
            off_route = np.linalg.norm(batch.ego.position - point, axis=1) > self.route_deviation_m
        # a world where neither rule fires keeps the events its simulator reported
        judged = blocked | off_route
        return batch.with_events(
            blocked=np.where(judged, blocked, batch.events.blocked),
            off_route=np.where(judged, off_route, batch.events.off_route),
        )


@njit(cache=True)
def episode_ends(
    collided, arrived, red_light_crossed, blocked, off_route, off_road, offroad_terminal, time_s,
    truncate_at_s, terminated, truncated
) -> None:  # fmt: skip
    """``terminated`` (K,): a collision, the goal, a red light run, blocked, off the route, or off
    the road where that ends an episode; ``truncated`` (K,): not terminated, and the clock at the
    time limit (one compiled pass: a handful of ufuncs cost more than the step's other rules)."""
    for k in range(terminated.size):
        ended = collided[k] or arrived[k] or red_light_crossed[k] or blocked[k] or off_route[k]
        terminated[k] = ended or (offroad_terminal and off_road[k])
        truncated[k] = not terminated[k] and time_s[k] >= truncate_at_s[k]
