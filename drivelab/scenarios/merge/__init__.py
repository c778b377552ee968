"""MergeEnv's episode set-up (``_make_vehicles``) as vehicle rows, without highway-env objects:
the same draws from the same generator in the same order, hence the same rows for a seed."""

from __future__ import annotations

import numpy as np
from gymnasium.utils import seeding

from drivelab.scenarios.options import arranged_traffic_options, timing_options
from drivelab.sim.core import traffic as T
from drivelab.sim.core.spawn import arrange_traffic, ego_kind, finish, vehicle_row
from drivelab.world.scenario import Scenario

# (longitudinal m, speed m/s) of the three highway vehicles MergeEnv places around the ego
HIGHWAY_VEHICLES = ((90.0, 29.0), (70.0, 31.0), (5.0, 31.5))


def spawn_merge(seed: int, road, control: str) -> tuple[np.ndarray, int, np.ndarray, None]:
    """The ego on lane ("a", "b", 1) at 30 m and 30 m/s, three vehicles on a random highway lane
    around it, one on the ramp at 110 m (20 m/s, aiming at 30 m/s), then the traffic level's
    changes and the obstacle at the ramp's end. Returns (rows, ego row, regulation, None)."""
    rng, _ = seeding.np_random(int(seed))
    geometry = road.geometry
    lane_of = geometry.row_of
    vehicles = [
        vehicle_row(road, geometry.position(lane_of[("a", "b", 1)], 30.0, 0.0), 0, 30.0, ego_kind(control))
    ]
    for longitudinal, speed in HIGHWAY_VEHICLES:
        lane = lane_of[("a", "b", int(rng.integers(2)))]
        position = geometry.position(lane, longitudinal + rng.uniform(-5.0, 5.0), 0.0)
        speed += rng.uniform(-1.0, 1.0)
        vehicles.append(vehicle_row(road, position, 0, speed, T.IDM))
    merging = vehicle_row(road, geometry.position(lane_of[("j", "k", 0)], 110.0, 0.0), 0, 20.0, T.IDM)
    merging[T.TARGET_SPEED] = 30.0
    vehicles.append(merging)
    vehicles, ego = arrange_traffic(road, vehicles, 0, rng)
    return finish(road, vehicles), ego, np.zeros(2), None


# MergeEnv reads no road or traffic key of its own: the traffic levels' and the timing's
OPTIONS = (*arranged_traffic_options(), *timing_options(15, 1, 5))


SCENARIO = Scenario(
    "merge",
    "highway_env.envs.merge_env.MergeEnv",
    "highway with an on-ramp merging in; ends after the merge (x > 370 m)",
    config={"duration": 40},
    traffic={"empty": {"keep_npcs": False}, "regular": {}, "dense": {"extra_vehicles": 6}},
    arrival="merge_end",
    arrival_x_m=370.0,
    spawn=spawn_merge,
    options=OPTIONS,
)
