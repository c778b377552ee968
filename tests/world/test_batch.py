"""WorldBatch: K worlds as arrays, and WorldState as its one-world view."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from drivelab.envs.core import DriveEnv
from drivelab.world.batch import COLLISION_PEDESTRIAN, EgoBatch, EventsBatch, RouteBatch, WorldBatch, assemble
from drivelab.world.state import LIGHT_RED, Ego, Events, RoadMap, Route, WorldState


def _assert_same_world(a: WorldState, b: WorldState) -> None:
    assert a.time_s == b.time_s and a.dt_s == b.dt_s
    assert all(np.array_equal(getattr(a.ego, f), getattr(b.ego, f)) for f in a.ego.__dataclass_fields__)
    np.testing.assert_array_equal(a.vehicles, b.vehicles)
    np.testing.assert_array_equal(a.pedestrians, b.pedestrians)
    np.testing.assert_array_equal(a.traffic_lights, b.traffic_lights)
    np.testing.assert_array_equal(a.route.polyline, b.route.polyline)
    assert (a.route.progress_m, a.route.length_m, a.route.closed) == (
        b.route.progress_m,
        b.route.length_m,
        b.route.closed,
    )
    assert a.events == b.events and a.road is b.road
    assert (a.max_speed_mps, a.speed_limit_mps) == (b.max_speed_mps, b.speed_limit_mps)


def _worlds(scenario: str, count: int, steps: int = 3) -> list[WorldState]:
    env = DriveEnv(scenario, obs="kinematics", traffic="dense")
    worlds = []
    for seed in range(count):
        env.reset(seed=seed)
        env.action_space.seed(seed)
        for _ in range(steps + seed):  # different vehicle counts and route progress per world
            env.step(env.action_space.sample())
        worlds.append(env.world)
    return worlds


@pytest.mark.parametrize("scenario", ["highway", "intersection"])
def test_stack_then_index_gives_the_worlds_back(scenario):
    worlds = _worlds(scenario, 4)
    batch = WorldBatch.stack(worlds)
    assert batch.num_worlds == 4 and batch.vehicles.shape[0] == 4
    assert batch.vehicle_valid.sum(axis=1).tolist() == [len(w.vehicles) for w in worlds]
    assert len(batch.roads) == 1 and batch.road is worlds[0].road
    for k, world in enumerate(worlds):
        _assert_same_world(batch[k], world)


def _hand_built(x: float, lights: np.ndarray, pedestrians: np.ndarray, closed: bool) -> WorldState:
    polyline = np.array([[0.0, 0.0], [30.0, 0.0], [30.0, 40.0]])[: 3 if closed else 2]
    return WorldState(
        time_s=x,
        dt_s=0.2,
        ego=Ego(position=np.array([x, 0.5]), heading=0.1, speed_mps=3.0, lane_width_m=4.0),
        vehicles=np.zeros((0, 6)),
        road=RoadMap.empty(),
        route=Route(polyline, progress_m=x, length_m=float("inf") if closed else 30.0, closed=closed),
        events=Events(collided=True, collision_with="pedestrian"),
        traffic_lights=lights,
        pedestrians=pedestrians,
    )


def test_routes_lights_and_events_match_the_single_world_methods():
    light = np.array([[20.0, 0.0, 0.0, LIGHT_RED]])
    worlds = [
        _hand_built(2.0, light, np.zeros((0, 6)), closed=False),
        _hand_built(25.0, np.zeros((0, 4)), np.ones((2, 6)), closed=True),
        _hand_built(10.0, np.concatenate([light, light + [5, 0, 0, 0]]), np.zeros((0, 6)), closed=False),
    ]
    batch = WorldBatch.stack(worlds)
    assert batch.events.collision_kind.tolist() == [COLLISION_PEDESTRIAN] * 3
    distances = np.array([[-5.0, 0.0, 12.0, 31.0, 90.0]] * 3) + batch.route.progress_m[:, None]
    points, headings = batch.route.poses_at(distances)
    for k, world in enumerate(worlds):
        expected_points, expected_headings = world.route.poses_at(distances[k])
        np.testing.assert_allclose(points[k], expected_points, atol=1e-12)
        np.testing.assert_allclose(headings[k], expected_headings, atol=1e-12)
        state, distance = batch.light_ahead(40.0)
        single = world.light_ahead(40.0)
        assert (state[k], distance[k]) == ((-1, np.inf) if single is None else single)
    users, valid = batch.road_users()
    assert users.shape == (3, 2, 6) and valid.sum(axis=1).tolist() == [0, 2, 0]


def test_where_takes_the_masked_worlds_from_the_other_batch():
    first, second = _worlds("highway", 3), _worlds("merge", 3, steps=1)
    merged = WorldBatch.stack(first).where(np.array([False, True, False]), WorldBatch.stack(second))
    assert len(merged.roads) == 2
    _assert_same_world(merged[0], first[0])
    _assert_same_world(merged[1], second[1])
    _assert_same_world(merged[2], first[2])


def test_with_events_and_replaced_keep_the_other_fields_and_start_an_empty_cache():
    batch = WorldBatch.stack(_worlds("highway", 2))
    batch.cache["made"] = 1  # a value a reader derived from this batch
    blocked = np.array([True, False])
    changed = batch.with_events(blocked=blocked)
    assert changed.events.blocked is blocked and changed.cache == {} and batch.cache
    assert changed.events.collided is batch.events.collided and not batch.events.blocked.any()
    for name in batch.__dataclass_fields__:
        if name not in ("events", "cache"):
            assert getattr(changed, name) is getattr(batch, name), name
    for k in range(2):
        assert changed[k].events == dataclasses.replace(batch[k].events, blocked=bool(blocked[k]))
    with pytest.raises(TypeError, match="speed"):
        batch.replaced(speed=1.0)
    with pytest.raises(TypeError, match="cache"):
        batch.replaced(cache={})


def test_heading_cos_sin_is_numpys_made_once_per_batch():
    batch = WorldBatch.stack(_worlds("highway", 3))
    cos_h, sin_h = batch.heading_cos_sin()
    np.testing.assert_array_equal(cos_h, np.cos(batch.ego.heading))
    np.testing.assert_array_equal(sin_h, np.sin(batch.ego.heading))
    assert batch.heading_cos_sin()[0] is cos_h  # kept in the batch's cache
    changed = batch.with_events(blocked=np.ones(3, dtype=bool))  # another batch: its own values
    assert changed.heading_cos_sin()[0] is not cos_h


def test_assemble_is_the_constructor_without_its_frozen_init():
    batch = WorldBatch.stack(_worlds("highway", 2))
    for part in (batch.ego, batch.events, batch.route, batch):
        cls = type(part)
        fields = {f.name: getattr(part, f.name) for f in dataclasses.fields(cls) if f.init}
        made, built = assemble(cls, **fields), cls(**fields)
        assert type(made) is cls
        for name in fields:
            assert getattr(made, name) is getattr(built, name), name
        if "cache" in cls.__dataclass_fields__:  # each value its own empty cache
            assert made.cache == {} and made.cache is not assemble(cls, **fields).cache
        with pytest.raises(dataclasses.FrozenInstanceError):
            made.time_s = None  # still frozen
    # WorldBatch's one default (slots) is filled in; a missing or unknown field is refused by name
    fields = {f.name: getattr(batch, f.name) for f in dataclasses.fields(WorldBatch) if f.init}
    del fields["slots"]
    assert assemble(WorldBatch, **fields).slots is None
    ego = {f.name: getattr(batch.ego, f.name) for f in dataclasses.fields(EgoBatch)}
    del ego["heading"]
    with pytest.raises(TypeError, match="heading"):
        assemble(EgoBatch, **ego)
    with pytest.raises(TypeError, match="wings"):
        assemble(
            RouteBatch,
            wings=1,
            **{f.name: getattr(batch.route, f.name) for f in dataclasses.fields(RouteBatch) if f.init},
        )
    events = batch.events.replaced(arrived=np.array([True, False]))
    assert isinstance(events, EventsBatch) and events.arrived.tolist() == [True, False]
    assert events.collided is batch.events.collided
