"""The highway-env backend's WorldState export."""

import numpy as np
import pytest

from drivelab.envs.core import DriveEnv
from drivelab.scenarios import SCENARIOS
from drivelab.sim.reference.highway import HighwayBackend


def test_highway_road_map_and_lane_state():
    backend = HighwayBackend(SCENARIOS["highway"], "empty", "meta")
    world = backend.reset(seed=0)
    assert len(world.road.lane_polygons) == 3
    # the two solid outer lines of a 3-lane road whose lane centres are y = 0, 4, 8
    np.testing.assert_allclose(sorted(world.road.edges[:, 0, 1]), [-2.0, 10.0])
    assert world.ego.lane_count == 3 and world.ego.lane_width_m == 4.0
    assert world.ego.lateral_offset_m == pytest.approx(0.0, abs=1e-6)
    assert world.route.length_m == np.inf and world.vehicles.shape == (0, 6)


def test_route_progress_follows_the_ego():
    backend = HighwayBackend(SCENARIOS["highway"], "empty", "meta")
    first = backend.reset(seed=0)
    second = backend.step(1)  # IDLE for one second
    travelled = np.linalg.norm(second.ego.position - first.ego.position)
    assert second.route.progress_m - first.route.progress_m == pytest.approx(travelled, rel=1e-6)


def test_progress_counts_laps_on_the_racetrack():
    backend = HighwayBackend(SCENARIOS["racetrack"], "empty", "continuous")
    backend.reset(seed=0)
    route = backend.route
    assert route.closed
    lap_m = route.stations[-1]
    points = route.polyline
    progress = route.project(points[0])
    trace = []
    for point in np.concatenate([points[1:], points[1:], points[1:5]]):  # two laps and a bit
        progress = route.project(point, progress)
        trace.append(progress)
    assert np.all(np.diff(trace) >= -1e-6)
    assert trace[-1] > 2 * lap_m


def test_hard_steering_leaves_the_road_and_ends_the_episode():
    env = DriveEnv("highway", obs="kinematics", action="continuous", traffic="empty")
    env.reset(seed=0)
    for _ in range(40):
        _, _, terminated, _, info = env.step(np.array([-1.0, 0.0]))  # full left lock
        if terminated:
            break
    assert terminated and info["off_road"]
    assert info["episode_metrics"]["off_road_events"] == 1 and info["episode_metrics"]["success"] == 0.0


def test_intersection_arrival_is_success():
    env = DriveEnv("intersection", obs="kinematics", action="meta", traffic="empty")
    env.reset(seed=0)
    for _ in range(20):
        _, _, terminated, truncated, info = env.step(3)  # FASTER, the planned route does the turn
        if terminated or truncated:
            break
    assert info["arrived"] and info["episode_metrics"]["success"] == 1.0
    assert info["episode_metrics"]["route_completion"] > 0.5


@pytest.mark.parametrize("level, count", [("empty", 0), ("regular", 20), ("dense", 35)])
def test_traffic_levels(level, count):
    assert len(HighwayBackend(SCENARIOS["highway"], level, "meta").reset(seed=0).vehicles) == count


def test_the_intersection_keeps_its_idm_constants_to_itself():
    """highway-env's IntersectionEnv sets its traffic class's IDM constants at every reset; they
    land on the intersection's own subclass, so that the other scenarios' traffic (the town's
    IDM NPCs) does not change once an intersection has been built in the process."""
    from highway_env.vehicle.behavior import IDMVehicle

    from drivelab.sim.reference.highway import IntersectionIDMVehicle

    before = {
        name: getattr(IDMVehicle, name) for name in ("DISTANCE_WANTED", "COMFORT_ACC_MAX", "COMFORT_ACC_MIN")
    }
    backend = HighwayBackend(SCENARIOS["intersection"], "regular", "meta")
    backend.reset(0)
    assert {name: getattr(IDMVehicle, name) for name in before} == before
    assert (IntersectionIDMVehicle.DISTANCE_WANTED, IntersectionIDMVehicle.COMFORT_ACC_MIN) == (7, -3)
    others = [v for v in backend.env.road.vehicles if v is not backend.env.vehicle]
    assert {type(v) for v in others} == {IntersectionIDMVehicle}
