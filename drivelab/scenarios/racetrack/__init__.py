"""RacetrackEnv's episode set-up (``_make_vehicles``) as vehicle rows, without highway-env
objects: the same draws from the same generator in the same order, hence the same rows."""

from __future__ import annotations

import numpy as np
from gymnasium.utils import seeding

from drivelab.scenarios.options import Option, timing_options
from drivelab.sim.core import traffic as T
from drivelab.sim.core.spawn import arrange_traffic, finish, make_on_lane, random_lane_index, too_close
from drivelab.world.scenario import Scenario


def spawn_racetrack(seed: int, road, control: str) -> tuple[np.ndarray, int, np.ndarray, None]:
    """The ego on a random lane of the first straight, 20 to 50 m along it, at the speed limit;
    with traffic, a vehicle somewhere on the first curve (same lane) and up to
    ``other_vehicles`` - 1 more on random lanes, each kept only 20 m from every other. Returns
    (rows, ego row, regulation, None).

    highway-env's racetrack places its ego with ``make_on_lane``, which its meta-action vehicle
    class (a partial of MDPVehicle) lacks: only a continuous-control ego exists there.
    """
    if control == "meta":
        raise NotImplementedError("highway-env's racetrack has no meta-action ego")
    if road.config["controlled_vehicles"] != 1:
        raise NotImplementedError("the fast backend drives one controlled vehicle")
    rng, _ = seeding.np_random(int(seed))
    geometry = road.geometry
    lane_of = geometry.row_of
    lane_id = int(rng.integers(2))
    vehicles = [make_on_lane(road, lane_of[("a", "b", lane_id)], rng.uniform(20, 50), None, T.PLAIN)]
    others = road.config["other_vehicles"]
    if others > 0:
        curve = lane_of[("b", "c", lane_id)]
        longitudinal = rng.uniform(low=0.0, high=geometry.length(lane_of[("b", "c", 0)]))
        vehicles.append(make_on_lane(road, curve, longitudinal, 6.0 + rng.uniform(high=3.0)))
        for _ in range(rng.integers(others)):
            lane = random_lane_index(road, rng)
            longitudinal = rng.uniform(low=0.0, high=geometry.length(lane))
            row = make_on_lane(road, lane, longitudinal, 6.0 + rng.uniform(high=3.0))
            if not too_close(vehicles, row, 20):  # prevent early collisions
                vehicles.append(row)
    vehicles, ego = arrange_traffic(road, vehicles, 0, rng)
    return finish(road, vehicles), ego, np.zeros(2), None


# RacetrackEnv's road is fixed (its speed_limit key is RacetrackEnvLarge's): traffic and timing
OPTIONS = (
    Option(
        "other_vehicles", int, 1,
        "with at least 1: a vehicle on the first curve, then up to other_vehicles - 1 more on random "
        "lanes (each at least 20 m from the others)",
        minimum=0, traffic=True,
    ),
    *timing_options(15, 5, 5),
)  # fmt: skip


SCENARIO = Scenario(
    "racetrack",
    "highway_env.envs.racetrack_env.RacetrackEnv",
    "two-lane closed circuit with tight curves",
    # highway-env's own observation off: off-road is judged by drivelab, not highway-env
    config={"duration": 60, "observation": {"type": "Kinematics"}},
    traffic={
        "empty": {"other_vehicles": 0},
        "regular": {"other_vehicles": 1},
        "dense": {"other_vehicles": 5},
    },
    action_kinds=("grid", "continuous", "target_speed"),  # highway-env's racetrack: no meta-actions
    spawn=spawn_racetrack,
    options=OPTIONS,
)
