"""EpisodeRules over K worlds equals the one-world rules DriveEnv applied before the batch-first core
(written out below as the oracle: blocked timer, route deviation, offroad_terminal, per-world time
limits), on random worlds whose episodes start at different steps."""

import dataclasses

import numpy as np
import pytest

from drivelab.envs.core import DriveEnv
from drivelab.envs.rules import EpisodeRules, episode_time_limits_s
from drivelab.world.batch import WorldBatch
from drivelab.world.state import Events
from tests.batch_worlds import world_sequences

NUM_WORLDS = 8


def _shaken(world, rng: np.random.Generator, calm: bool):
    """``world`` with the ego often standing still, pushed off its route and off the road, and an
    occasional collision or arrival, so that every rule fires; a ``calm`` world instead drives on its
    route without any event (its episode runs into the time limit)."""
    if calm:
        point, _ = world.route.poses_at(world.route.progress_m)
        ego = dataclasses.replace(world.ego, position=point, speed_mps=max(world.ego.speed_mps, 1.0))
        return dataclasses.replace(world, ego=ego, events=Events())
    ego = dataclasses.replace(
        world.ego,
        speed_mps=0.0 if rng.random() < 0.6 else world.ego.speed_mps,
        position=world.ego.position + rng.normal(0.0, 1.0, size=2),
    )
    events = Events(
        collided=bool(rng.random() < 0.05),
        off_road=bool(rng.random() < 0.2),
        arrived=bool(rng.random() < 0.05),
        red_light_crossed=bool(rng.random() < 0.05),
    )
    return dataclasses.replace(world, ego=ego, events=events)


def _one_world_rules(scenario, offroad_terminal: bool, stopped_s: float, time_limit_s: float, world):
    """(events, terminated, truncated, stopped_s) of one world, as DriveEnv.finish_step decided them."""
    events = world.events
    if scenario.blocked_after_s is not None or scenario.route_deviation_m is not None:
        stopped_s = 0.0 if world.ego.speed_mps >= 0.1 else stopped_s + world.dt_s
        blocked = scenario.blocked_after_s is not None and stopped_s > scenario.blocked_after_s
        off_route = False
        if scenario.route_deviation_m is not None:
            point, _ = world.route.poses_at(world.route.progress_m)
            off_route = float(np.linalg.norm(world.ego.position - point)) > scenario.route_deviation_m
        if blocked or off_route:
            events = dataclasses.replace(events, blocked=blocked, off_route=off_route)
    terminated = bool(
        events.collided
        or events.arrived
        or events.red_light_crossed
        or events.blocked
        or events.off_route
        or (offroad_terminal and events.off_road)
    )
    truncated = bool(not terminated and world.time_s >= time_limit_s - 1e-9)
    return events, terminated, truncated, stopped_s


@pytest.mark.parametrize(
    "scenario, offroad_terminal",
    [("highway", True), ("highway", False), ("town", True), ("intersection", False)],
)
def test_rules_equal_the_one_world_rules_world_by_world(scenario, offroad_terminal):
    env = DriveEnv(scenario, obs="kinematics", offroad_terminal=offroad_terminal)
    # rules that fire within a few steps: blocked after 1.5 policy steps, off the route past 1.5 m
    sequence = world_sequences(scenario, num_worlds=NUM_WORLDS)
    dt_s = sequence[0][0][0].dt_s
    env.scenario = dataclasses.replace(env.scenario, blocked_after_s=1.5 * dt_s, route_deviation_m=1.5)
    rules = EpisodeRules(env.scenario, offroad_terminal)
    limits = dt_s * (2 + np.arange(NUM_WORLDS) % 4)  # episodes of 2 to 5 steps before truncation
    rng = np.random.default_rng(3)
    single: list[dict] = [{} for _ in range(NUM_WORLDS)]  # each world's DriveEnv state
    seen = {"blocked": 0, "off_route": 0, "terminated": 0, "truncated": 0, "off_road_only": 0}
    for t, (worlds, started) in enumerate(sequence):
        worlds = [w if started[k] else _shaken(w, rng, calm=k % 2 == 1) for k, w in enumerate(worlds)]
        batch, terminated, truncated = rules.apply(WorldBatch.stack(worlds)) if t else (None, None, None)
        rules.reset(started, limits)
        for k in range(NUM_WORLDS):
            if started[k]:
                single[k] = {"stopped_s": 0.0, "time_limit_s": limits[k]}
                continue
            events, done, cut, single[k]["stopped_s"] = _one_world_rules(
                env.scenario, offroad_terminal, single[k]["stopped_s"], single[k]["time_limit_s"], worlds[k]
            )
            assert batch[k].events == events, (t, k)
            assert (terminated[k], truncated[k]) == (done, cut), (t, k)
            seen["blocked"] += events.blocked
            seen["off_route"] += events.off_route
            seen["terminated"] += done
            seen["truncated"] += cut
            seen["off_road_only"] += events == Events(off_road=True)
    assert all(count > 0 for count in seen.values()), seen  # every rule was exercised


def test_rules_without_scenario_rules_keep_the_events():
    env = DriveEnv("highway", obs="kinematics")
    rules = EpisodeRules(env.scenario, offroad_terminal=True)
    batch = WorldBatch.stack(list(world_sequences("highway", num_worlds=NUM_WORLDS)[1][0]))
    rules.reset(np.ones(NUM_WORLDS, dtype=bool), 100.0)
    judged, terminated, truncated = rules.apply(batch)
    assert judged is batch
    expected = batch.events.collided | batch.events.off_road | batch.events.arrived
    np.testing.assert_array_equal(terminated, expected)
    assert not truncated.any()


def test_reset_by_mask_keeps_the_other_worlds_timers():
    scenario = dataclasses.replace(DriveEnv("highway").scenario, blocked_after_s=2.5)
    rules = EpisodeRules(scenario)
    worlds = list(world_sequences("highway", num_worlds=NUM_WORLDS)[1][0])
    stopped = WorldBatch.stack(
        [dataclasses.replace(w, ego=dataclasses.replace(w.ego, speed_mps=0.0)) for w in worlds]
    )
    rules.reset(np.ones(NUM_WORLDS, dtype=bool), np.full(NUM_WORLDS, 1e9))
    rules.apply(stopped)
    rules.apply(stopped)  # 2 s standing still everywhere (dt 1 s)
    rules.reset(np.arange(NUM_WORLDS) < 3, 1e9)  # worlds 0–2 start again
    judged, terminated, _ = rules.apply(stopped)  # 3 s for worlds 3–7, 1 s for 0–2
    np.testing.assert_array_equal(judged.events.blocked, np.arange(NUM_WORLDS) >= 3)
    np.testing.assert_array_equal(terminated, np.arange(NUM_WORLDS) >= 3)


def test_episode_time_limit():
    assert episode_time_limits_s(40.0, False, np.inf) == 40.0  # no route limit
    assert episode_time_limits_s(40.0, False, 75.0) == 75.0  # the route's own limit
    assert episode_time_limits_s(40.0, True, 75.0) == 40.0  # a given duration caps it
    assert episode_time_limits_s(80.0, True, 75.0) == 75.0
    routes = episode_time_limits_s(40.0, True, [np.inf, 30.0, 75.0])  # one per world
    np.testing.assert_array_equal(routes, [40.0, 30.0, 40.0])
