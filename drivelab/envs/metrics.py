"""EpisodeMetrics: what evaluation reports about the episodes of K worlds, kept as (K,) accumulators
reset by mask."""

from __future__ import annotations

import numpy as np

from drivelab.world.batch import COLLISION_PEDESTRIAN, WorldBatch

_PEDESTRIAN_CODE = np.int8(COLLISION_PEDESTRIAN)  # compared with the int8 codes without a cast
_ACCUMULATORS = (
    "episode_return", "length", "distance_m", "speed_sum_mps", "collisions", "pedestrian_collisions",
    "off_road_events", "red_lights", "blocked", "arrived",
)  # fmt: skip


class EpisodeMetrics:
    """:class:`EpisodeMetrics` for K worlds at once: ``(K,)`` accumulators, reset by mask.

    ``reset(batch, mask)`` starts the episodes of the masked worlds, ``update(batch, rewards)`` adds
    one step of every world, and ``summaries(mask, has_goal, timed_out)`` gives the summary dict of
    each masked world (the same keys and values as ``EpisodeMetrics.summary``).
    """

    def __init__(self) -> None:
        self._allocate(0)

    def _allocate(self, count: int) -> None:
        self.episode_return = np.zeros(count)
        self.length = np.zeros(count, dtype=np.int64)
        self.distance_m = np.zeros(count)
        self.speed_sum_mps = np.zeros(count)
        self.collisions = np.zeros(count, dtype=np.int64)
        self.pedestrian_collisions = np.zeros(count, dtype=np.int64)
        self.off_road_events = np.zeros(count, dtype=np.int64)
        self.red_lights = np.zeros(count, dtype=np.int64)
        self.blocked = np.zeros(count, dtype=np.int64)
        self.arrived = np.zeros(count, dtype=bool)
        self.start_progress_m = np.zeros(count)
        # the last world's ego position (K, 2), collision and off-road flags, and route
        self.last_position = np.zeros((count, 2))
        self.last_collided = np.zeros(count, dtype=bool)
        self.last_off_road = np.zeros(count, dtype=bool)
        self.last_progress_m = np.zeros(count)
        self.last_route_length_m = np.zeros(count)

    def reset(self, batch: WorldBatch, mask: np.ndarray | None = None) -> None:
        """Start the episodes of the worlds where ``mask`` (K,; default all) from their first world
        in ``batch``. A new number of worlds starts every world."""
        count = batch.num_worlds
        if mask is None or count != len(self.length):
            self._allocate(count)
            mask = np.ones(count, dtype=bool)
        mask = np.asarray(mask, dtype=bool)
        for name in _ACCUMULATORS:
            getattr(self, name)[mask] = 0
        self.start_progress_m[mask] = batch.route.progress_m[mask]
        self._remember(batch, mask)

    def _remember(self, batch: WorldBatch, mask: np.ndarray | slice) -> None:
        """Keep what the next update compares against: the worlds where ``mask`` of ``batch``."""
        self.last_position[mask] = batch.ego.position[mask]
        self.last_collided[mask] = batch.events.collided[mask]
        self.last_off_road[mask] = batch.events.off_road[mask]
        self.last_progress_m[mask] = batch.route.progress_m[mask]
        self.last_route_length_m[mask] = batch.route.length_m[mask]

    def update(self, batch: WorldBatch, rewards: np.ndarray) -> None:
        """Add the step of every world that led to ``batch``, with its ``rewards`` (K,)."""
        events = batch.events
        self.episode_return += rewards
        self.length += 1
        moved = batch.ego.position - self.last_position
        self.distance_m += np.sqrt(np.add.reduce(moved * moved, axis=1))  # np.linalg.norm's arithmetic
        self.speed_sum_mps += batch.ego.speed_mps
        new_collision = events.collided & ~self.last_collided
        self.collisions += new_collision
        self.pedestrian_collisions += new_collision & (events.collision_kind == _PEDESTRIAN_CODE)
        self.off_road_events += events.off_road & ~self.last_off_road
        self.red_lights += events.red_light_crossed
        self.blocked += events.blocked
        self.arrived |= events.arrived
        self._remember(batch, slice(None))

    def summaries(
        self, mask: np.ndarray, has_goal: bool, timed_out: np.ndarray
    ) -> list[dict[str, float | None]]:
        """The final numbers of each world where ``mask`` (K,), in order (``EpisodeMetrics.summary``
        for each; ``timed_out`` (K,) says whose episode reached its time limit)."""
        crashed = self.collisions > 0
        clean = ~crashed & (self.off_road_events == 0)
        success = self.arrived if has_goal else (np.asarray(timed_out, dtype=bool) & clean)
        finite = np.isfinite(self.last_route_length_m)
        with np.errstate(invalid="ignore"):
            completion = np.where(
                finite,
                (self.last_progress_m - self.start_progress_m)
                / np.maximum(self.last_route_length_m - self.start_progress_m, 1e-6),
                np.nan,
            )
        completion = np.clip(completion, 0.0, 1.0)
        mean_speed = self.speed_sum_mps / np.maximum(self.length, 1)
        ended = np.flatnonzero(mask)  # only the worlds whose episode ends: a dict each
        columns = {
            "return": self.episode_return[ended].astype(float).tolist(),
            "length": self.length[ended].astype(int).tolist(),
            "distance_km": (self.distance_m[ended] / 1000).astype(float).tolist(),
            "mean_speed_mps": mean_speed[ended].astype(float).tolist(),
            "success": success[ended].astype(float).tolist(),
            "crashed": crashed[ended].astype(float).tolist(),
            "collisions": self.collisions[ended].astype(int).tolist(),
            "pedestrian_collisions": self.pedestrian_collisions[ended].astype(int).tolist(),
            "off_road_events": self.off_road_events[ended].astype(int).tolist(),
            "red_lights": self.red_lights[ended].astype(int).tolist(),
            "blocked": self.blocked[ended].astype(int).tolist(),
            # a goal without a route of finite length (the merge's arrival line) has no completion
            "route_completion": [
                value if has_goal and np.isfinite(value) else None for value in completion[ended].tolist()
            ],
        }
        return [dict(zip(columns, values, strict=True)) for values in zip(*columns.values(), strict=True)]
