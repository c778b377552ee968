"""EpisodeMetrics over K worlds gives, for every episode, the one-world metrics' summary of that world
alone, on random worlds whose episodes start and end at different steps."""

import dataclasses
import math

import numpy as np
import pytest

from drivelab.envs.metrics import EpisodeMetrics
from drivelab.world.batch import WorldBatch
from drivelab.world.state import Events
from tests.batch_worlds import world_sequences
from tests.envs.one_world_metrics import OneWorldMetrics

NUM_WORLDS = 8


def _with_events(world, rng: np.random.Generator):
    """``world`` with random events (collisions with vehicles or pedestrians, leaving the road,
    red lights, blocked, arrival), each lasting a step or more."""
    collided = bool(rng.random() < 0.3)
    events = Events(
        collided=collided,
        collision_with=str(rng.choice(["vehicle", "pedestrian"])) if collided else "",
        off_road=bool(rng.random() < 0.3),
        arrived=bool(rng.random() < 0.1),
        red_light_crossed=bool(rng.random() < 0.2),
        blocked=bool(rng.random() < 0.1),
    )
    return dataclasses.replace(world, events=events)


def _assert_same_summary(batched: dict, single: dict) -> None:
    assert list(batched) == list(single)
    for key, value in single.items():
        assert type(batched[key]) is type(value), key
        if isinstance(value, float) and math.isnan(value):
            assert math.isnan(batched[key]), key
        else:
            assert batched[key] == value, (key, batched[key], value)


@pytest.mark.parametrize("scenario, has_goal", [("highway", False), ("intersection", True), ("town", True)])
def test_batch_metrics_equal_episode_metrics_world_by_world(scenario, has_goal):
    sequence = world_sequences(scenario, num_worlds=NUM_WORLDS)
    rng = np.random.default_rng(5)
    metrics, single = EpisodeMetrics(), [None] * NUM_WORLDS
    summaries = 0
    for t, (worlds, started) in enumerate(sequence):
        worlds = [w if started[k] else _with_events(w, rng) for k, w in enumerate(worlds)]
        batch = WorldBatch.stack(worlds)
        if t == 0:
            metrics.reset(batch)
        else:
            rewards = rng.normal(size=NUM_WORLDS)
            metrics.update(batch, rewards)  # the worlds that just started are reset right after
            metrics.reset(batch, started)
            for k in np.flatnonzero(~started):
                single[k].update(worlds[k], float(rewards[k]))
        for k in np.flatnonzero(started):
            single[k] = OneWorldMetrics(worlds[k])
        # episodes end where the next step starts a new one, and every episode at the last step
        ending = sequence[t + 1][1] if t + 1 < len(sequence) else np.ones(NUM_WORLDS, dtype=bool)
        timed_out = rng.random(NUM_WORLDS) < 0.5
        batched = metrics.summaries(ending, has_goal, timed_out)
        assert len(batched) == ending.sum()
        for summary, k in zip(batched, np.flatnonzero(ending), strict=True):
            _assert_same_summary(summary, single[k].summary(has_goal, bool(timed_out[k])))
            summaries += 1
    assert summaries >= 2 * NUM_WORLDS


def test_counts_on_a_known_episode():
    from tests.worlds import world

    moving = [world(position=np.array([3.0 * i, 4.0 * i]), speed_mps=5.0) for i in range(4)]
    moving[1] = dataclasses.replace(moving[1], events=Events(collided=True, collision_with="pedestrian"))
    moving[2] = dataclasses.replace(moving[2], events=Events(collided=True, collision_with="pedestrian"))
    moving[3] = dataclasses.replace(moving[3], events=Events(off_road=True, red_light_crossed=True))
    still = [world() for _ in range(4)]
    metrics = EpisodeMetrics()
    metrics.reset(WorldBatch.stack([moving[0], still[0]]))
    for step in range(1, 4):
        metrics.update(WorldBatch.stack([moving[step], still[step]]), np.array([1.0, -0.5]))
    first, second = metrics.summaries(
        np.array([True, True]), has_goal=False, timed_out=np.array([True, True])
    )
    assert first["distance_km"] == pytest.approx(0.015)  # 3 steps of 5 m
    assert (first["collisions"], first["pedestrian_collisions"], first["off_road_events"]) == (1, 1, 1)
    assert (first["red_lights"], first["return"], first["length"]) == (1, 3.0, 3)
    assert (first["crashed"], first["success"], first["route_completion"]) == (1.0, 0.0, None)
    assert (second["crashed"], second["success"], second["return"], second["distance_km"]) == (
        0.0,
        1.0,
        -1.5,
        0.0,
    )
    assert second["mean_speed_mps"] == 20.0


@pytest.mark.parametrize(
    "events, success",
    [({"collided": True}, 0.0), ({"red_light_crossed": True}, 1.0), ({"blocked": True}, 1.0), ({}, 1.0)],
)
def test_an_arrival_with_a_collision_on_its_step_is_no_success(events, success):
    """NoCrash (seed 000): a success is a route completed without collision, so a collision on the
    arrival step itself fails the episode, though both end it together; a red light run or a block
    on that step is an infraction counted per km, not a failure."""
    from tests.worlds import world

    steps = [world(position=np.array([5.0 * i, 0.0]), speed_mps=5.0) for i in range(3)]
    steps[2] = dataclasses.replace(steps[2], events=Events(arrived=True, **events))
    metrics = EpisodeMetrics()
    metrics.reset(WorldBatch.stack([steps[0]]))
    for step in (1, 2):
        metrics.update(WorldBatch.stack([steps[step]]), np.zeros(1))
    (summary,) = metrics.summaries(np.array([True]), has_goal=True, timed_out=np.zeros(1, bool))
    assert summary["success"] == success and summary["crashed"] == float("collided" in events)


def test_a_goal_without_a_finite_route_has_no_completion():
    """The merge arrives at a line, not at a route's end: its episodes report no route completion
    (None, which evaluation's mean skips), never NaN."""
    from drivelab.envs.vector import VectorDriveEnv

    env = VectorDriveEnv(2, scenario="merge", obs="kinematics")
    env.reset(seed=0)
    finished = []
    while len(finished) < 2:
        _, _, terminated, truncated, infos = env.step(np.full(2, 1))
        done = terminated | truncated
        finished += [infos["episode_metrics"][k] for k in np.flatnonzero(done)]
    assert all(summary["route_completion"] is None for summary in finished)
