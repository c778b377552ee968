"""EpisodeMetrics: what evaluation reports about the episodes of K worlds, kept as (K,) accumulators
reset by mask."""

from __future__ import annotations

import numpy as np
from numba import njit

from drivelab.world.batch import COLLISION_PEDESTRIAN, WorldBatch

_FLOAT_ROWS, _INT_ROWS, _FLAG_ROWS = 3, 6, 3


@njit(cache=True)
def add_step(
    floats, ints, flags, last_position, rewards, position, speed, collided, kind, off_road, red, blocked, won
) -> None:
    """One step of every world into the accumulators (rows as ``EpisodeMetrics._allocate`` names
    them), then the step's position and flags kept as the last ones. The distance is
    ``sqrt(dx² + dy²)``, np.linalg.norm's arithmetic on two components."""
    for k in range(rewards.size):
        dx, dy = position[k, 0] - last_position[k, 0], position[k, 1] - last_position[k, 1]
        floats[0, k] += rewards[k]
        floats[1, k] += np.sqrt(dx * dx + dy * dy)
        floats[2, k] += speed[k]
        new_collision = collided[k] and not flags[1, k]
        ints[0, k] += 1
        ints[1, k] += new_collision
        ints[2, k] += new_collision and kind[k] == COLLISION_PEDESTRIAN
        ints[3, k] += off_road[k] and not flags[2, k]
        ints[4, k] += red[k]
        ints[5, k] += blocked[k]
        flags[0, k] |= won[k]
        flags[1, k], flags[2, k] = collided[k], off_road[k]
        last_position[k, 0], last_position[k, 1] = position[k, 0], position[k, 1]


class EpisodeMetrics:
    """:class:`EpisodeMetrics` for K worlds at once: ``(K,)`` accumulators, reset by mask.

    ``reset(batch, mask)`` starts the episodes of the masked worlds, ``update(batch, rewards)`` adds
    one step of every world, and ``summaries(mask, has_goal, timed_out)`` gives the summary dict of
    each masked world (the same keys and values as ``EpisodeMetrics.summary``).
    """

    def __init__(self) -> None:
        self._allocate(0)

    def _allocate(self, count: int) -> None:
        # the accumulators are rows of three arrays (one compiled update adds a step to all of them)
        self._floats = np.zeros((_FLOAT_ROWS, count))
        self._ints = np.zeros((_INT_ROWS, count), dtype=np.int64)
        self._flags = np.zeros((_FLAG_ROWS, count), dtype=bool)
        self.episode_return, self.distance_m, self.speed_sum_mps = self._floats[:3]
        self.length, self.collisions, self.pedestrian_collisions = self._ints[:3]
        self.off_road_events, self.red_lights, self.blocked = self._ints[3:]
        self.arrived = self._flags[0]
        self.start_progress_m = np.zeros(count)
        # the last world's ego position (K, 2), collision and off-road flags, and route
        self.last_position = np.zeros((count, 2))
        self.last_collided, self.last_off_road = self._flags[1:]
        self.last_progress_m = np.zeros(count)
        self.last_route_length_m = np.zeros(count)

    @property
    def accumulators(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The (floats, ints, flags) rows ``add_step`` updates in place (replaced when the number
        of worlds changes)."""
        return self._floats, self._ints, self._flags

    def reset(self, batch: WorldBatch, mask: np.ndarray | None = None) -> None:
        """Start the episodes of the worlds where ``mask`` (K,; default all) from their first world
        in ``batch``. A new number of worlds starts every world."""
        count = batch.num_worlds
        if mask is None or count != len(self.length):
            self._allocate(count)
            mask = np.ones(count, dtype=bool)
        mask = np.asarray(mask, dtype=bool)
        self._floats[:, mask], self._ints[:, mask], self.arrived[mask] = 0.0, 0, False  # last flags: below
        self.start_progress_m[mask] = batch.route.progress_m[mask]
        # what the next update compares against
        self.last_position[mask] = batch.ego.position[mask]
        self.last_collided[mask] = batch.events.collided[mask]
        self.last_off_road[mask] = batch.events.off_road[mask]
        self.last_progress_m[mask] = batch.route.progress_m[mask]
        self.last_route_length_m[mask] = batch.route.length_m[mask]

    def update(self, batch: WorldBatch, rewards: np.ndarray) -> None:
        """Add the step of every world that led to ``batch``, with its ``rewards`` (K,)."""
        events, ego = batch.events, batch.ego
        add_step(
            self._floats, self._ints, self._flags, self.last_position, np.asarray(rewards, dtype=float),
            ego.position, ego.speed_mps, events.collided, events.collision_kind, events.off_road,
            events.red_light_crossed, events.blocked, events.arrived,
        )  # fmt: skip
        self.last_progress_m[:] = batch.route.progress_m
        self.last_route_length_m[:] = batch.route.length_m

    def summaries(
        self, mask: np.ndarray, has_goal: bool, timed_out: np.ndarray
    ) -> list[dict[str, float | None]]:
        """The final numbers of each world where ``mask`` (K,), in order (``EpisodeMetrics.summary``
        for each; ``timed_out`` (K,) says whose episode reached its time limit)."""
        ended = np.flatnonzero(mask)  # only the worlds whose episode ends: a dict each
        length, collisions = self.length[ended], self.collisions[ended]
        off_road_events = self.off_road_events[ended]
        crashed = collisions > 0
        # NoCrash's success (the RLAD paper: "routes completed without collision"): the goal reached
        # with no collision, one on the arrival step included; without a goal, the time limit
        # reached with no collision and no off-road event
        clean = ~crashed & (off_road_events == 0)
        if has_goal:
            success = self.arrived[ended] & ~crashed
        else:
            success = np.asarray(timed_out, dtype=bool)[ended] & clean
        start_m, route_m = self.start_progress_m[ended], self.last_route_length_m[ended]
        with np.errstate(invalid="ignore"):
            completion = np.where(
                np.isfinite(route_m),
                (self.last_progress_m[ended] - start_m) / np.maximum(route_m - start_m, 1e-6),
                np.nan,
            )
        completion = np.minimum(np.maximum(completion, 0.0), 1.0)  # np.clip (NaN kept)
        columns = {
            "return": self.episode_return[ended].tolist(),
            "length": length.tolist(),
            "distance_km": (self.distance_m[ended] / 1000).tolist(),
            "mean_speed_mps": (self.speed_sum_mps[ended] / np.maximum(length, 1)).tolist(),
            "success": success.astype(float).tolist(),
            "crashed": crashed.astype(float).tolist(),
            "collisions": collisions.tolist(),
            "pedestrian_collisions": self.pedestrian_collisions[ended].tolist(),
            "off_road_events": off_road_events.tolist(),
            "red_lights": self.red_lights[ended].tolist(),
            "blocked": self.blocked[ended].tolist(),
            # a goal without a route of finite length (the merge's arrival line) has no completion
            "route_completion": [
                value if has_goal and np.isfinite(value) else None for value in completion.tolist()
            ],
        }
        return [dict(zip(columns, values, strict=True)) for values in zip(*columns.values(), strict=True)]
