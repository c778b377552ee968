"""The one-world EpisodeMetrics drivelab kept before the batch-first core: the oracle the (K,)
EpisodeMetrics is tested against."""

from __future__ import annotations

import numpy as np

from drivelab.world.state import WorldState


class OneWorldMetrics:
    """Accumulates one episode; ``summary`` gives the numbers put in ``info["episode_metrics"]``.

    Event counts are kept raw (not per km) so that evaluation can divide summed counts by summed
    distance over episodes instead of averaging noisy per-episode ratios.
    """

    def __init__(self, first: WorldState) -> None:
        self.episode_return = 0.0
        self.length = 0
        self.distance_m = 0.0
        self.speed_sum_mps = 0.0
        self.collisions = 0
        self.pedestrian_collisions = 0
        self.off_road_events = 0
        self.red_lights = 0
        self.blocked = 0
        self.arrived = False
        self.start_progress_m = first.route.progress_m
        self.last = first

    def update(self, world: WorldState, reward: float) -> None:
        """Add the step that led to ``world``."""
        self.episode_return += reward
        self.length += 1
        self.distance_m += float(np.linalg.norm(world.ego.position - self.last.ego.position))
        self.speed_sum_mps += world.ego.speed_mps
        new_collision = world.events.collided and not self.last.events.collided
        self.collisions += int(new_collision)
        self.pedestrian_collisions += int(new_collision and world.events.collision_with == "pedestrian")
        self.off_road_events += int(world.events.off_road and not self.last.events.off_road)
        self.red_lights += int(world.events.red_light_crossed)
        self.blocked += int(world.events.blocked)
        self.arrived |= world.events.arrived
        self.last = world

    def summary(self, has_goal: bool, timed_out: bool) -> dict[str, float | None]:
        """Final numbers. Success: the goal reached without a collision, or (no goal) the time limit
        reached cleanly. Route completion is None for scenarios without a goal."""
        crashed = self.collisions > 0
        clean = not crashed and self.off_road_events == 0
        success = (self.arrived and not crashed) if has_goal else (timed_out and clean)
        route = self.last.route
        completion = (
            (route.progress_m - self.start_progress_m) / max(route.length_m - self.start_progress_m, 1e-6)
            if np.isfinite(route.length_m)
            else float("nan")
        )
        return {
            "return": self.episode_return,
            "length": self.length,
            "distance_km": self.distance_m / 1000,
            "mean_speed_mps": self.speed_sum_mps / max(self.length, 1),
            "success": float(success),
            "crashed": float(crashed),
            "collisions": self.collisions,
            "pedestrian_collisions": self.pedestrian_collisions,
            "off_road_events": self.off_road_events,
            "red_lights": self.red_lights,
            "blocked": self.blocked,
            "route_completion": float(np.clip(completion, 0.0, 1.0)) if has_goal else None,
        }
