"""IntersectionEnv's episode set-up and arrivals as vehicle rows, without highway-env objects.

``spawn_intersection`` reproduces ``_make_vehicles``: vehicles arrive at the entries, the road
runs three seconds without an ego (``traffic.simulate``), a challenger arrives, the ego is placed
and the vehicles within 20 m of it leave. ``IntersectionTraffic`` reproduces ``_spawn_vehicle``,
which the simulator also calls between steps with the generator this set-up drew from. The
warm-up is bit for bit highway-env's where numpy does not dispatch AVX-512 kernels (else a
position can differ by ULPs; ``tests/sim/test_spawn.py``).
"""

from __future__ import annotations

import numpy as np
from gymnasium.utils import seeding

from drivelab.scenarios.options import Option, arranged_traffic_options, timing_options
from drivelab.sim.core import traffic as T
from drivelab.sim.core.spawn import (
    arrange_traffic,
    compact_routes,
    ego_kind,
    finish,
    make_on_lane,
    plan_route,
    randomize_behavior,
    too_close,
    vehicle_row,
)
from drivelab.world.scenario import Scenario

WARM_UP_STEPS = 3  # seconds of traffic before the ego is placed (``simulation_steps``)
EGO_CLEARANCE_M = 20.0  # vehicles nearer the ego than this are removed ("prevent early collisions")
IMPACT_COLUMNS = [T.IMPACT_X, T.IMPACT_Y, T.HAS_IMPACT]


class IntersectionTraffic:
    """IntersectionEnv._spawn_vehicle on vehicle rows: a vehicle may arrive at a random entry,
    routed to another exit, drawing from the world's generator in highway-env's order.
    (Departures, ``_clear_vehicles``, are compiled: ``simulator.clear_departed``.)

    :param road: the simulator's converted road (geometry, shortest paths, vehicle constants).
    """

    def __init__(self, road) -> None:
        self.road = road
        self.entries = [road.geometry.row_of[(f"o{k}", f"ir{k}", 0)] for k in range(4)]

    @classmethod
    def of(cls, road) -> IntersectionTraffic:
        """The road's IntersectionTraffic (one per road, kept in its cache)."""
        traffic = road.cache.get("intersection")
        if traffic is None:
            traffic = road.cache["intersection"] = cls(road)
        return traffic

    def spawn(
        self, vehicles, rng: np.random.Generator, spawn_probability: float = 0.6, longitudinal: float = 0.0,
        position_deviation: float = 1.0, speed_deviation: float = 1.0, go_straight: bool = False,
    ) -> np.ndarray | None:  # fmt: skip
        """The row of an arriving vehicle, or None when none arrives or it would be within 15 m
        of another vehicle (the draws are made all the same, as highway-env makes them).

        :param vehicles: the world's vehicle rows, (N, VEHICLE_COLUMNS) or a list of rows.
        :param rng: the world's generator (highway-env's ``np_random`` of that episode).
        """
        if rng.uniform() > spawn_probability:
            return None
        route = rng.choice(4, size=2, replace=False)  # the draws of choice(range(4), ...)
        route[1] = (route[0] + 2) % 4 if go_straight else route[1]
        row = make_on_lane(
            self.road,
            self.entries[route[0]],
            longitudinal + 5.0 + rng.normal() * position_deviation,
            8.0 + rng.normal() * speed_deviation,
        )
        if too_close(vehicles, row, 15):
            return None
        plan_route(row, self.road, f"o{route[1]}")
        randomize_behavior(row, rng)
        return row


def spawn_intersection(
    seed: int, road, control: str
) -> tuple[np.ndarray, int, np.ndarray, np.random.Generator]:
    """IntersectionEnv._make_vehicles then the traffic level's changes. Returns (rows, ego row,
    regulation [period, road steps so far], the episode's generator for the arrivals)."""
    config = road.config
    if config["controlled_vehicles"] != 1:
        raise NotImplementedError("the fast backend drives one controlled vehicle")
    rng, _ = seeding.np_random(int(seed))
    geometry, traffic = road.geometry, IntersectionTraffic.of(road)
    count = config["initial_vehicle_count"]
    vehicles, spacing = [], np.linspace(0, 80, count)
    for t in range(count - 1):
        row = traffic.spawn(vehicles, rng, longitudinal=spacing[t])
        if row is not None:
            vehicles.append(row)
    rows = np.array(vehicles).reshape(-1, T.VEHICLE_COLUMNS)
    frequency = config["simulation_frequency"]
    regulation = np.array([float(road.regulation_period), 0.0])
    T.simulate(rows, road.table.rows, road.idm, WARM_UP_STEPS * frequency, 1 / frequency, regulation)
    compact_routes(rows)
    rows[:, IMPACT_COLUMNS] = 0.0  # as vehicles_to_array takes a highway-env vehicle over
    vehicles = list(rows)
    challenger = traffic.spawn(
        rows, rng, spawn_probability=1.0, longitudinal=60, position_deviation=0.1, speed_deviation=0.0,
        go_straight=True,
    )  # fmt: skip
    if challenger is not None:
        vehicles.append(challenger)
    ego_lane = geometry.row_of[("o0", "ir0", 0)]
    destination = config["destination"] or "o" + str(rng.integers(1, 4))
    position = geometry.position(ego_lane, 60.0 + 5.0 * rng.normal(1.0), 0.0)
    ego = vehicle_row(
        road, position, geometry.heading_at(ego_lane, 60.0), geometry.speed_limit(ego_lane), ego_kind(control)
    )
    if control == "meta":  # an MDPVehicle plans its route; a plain Vehicle has none
        plan_route(ego, road, destination)
    position = ego[T.X : T.Y + 1]
    vehicles = [v for v in vehicles if not np.linalg.norm(v[T.X : T.Y + 1] - position) < EGO_CLEARANCE_M]
    vehicles.append(ego)
    vehicles, ego_index = arrange_traffic(road, vehicles, len(vehicles) - 1, rng)
    return finish(road, vehicles), ego_index, regulation, rng


OPTIONS = (
    Option(
        "initial_vehicle_count", int, 10,
        "vehicles arriving at the entries before the ego is placed (after 3 s of traffic, those "
        "within 20 m of it leave)",
        minimum=0, traffic=True,
    ),
    Option(
        "spawn_probability", float, 0.6,
        "chance that a vehicle arrives at a random entry at each policy step",
        minimum=0, maximum=1, traffic=True,
    ),
    *arranged_traffic_options(),
    # a RegulatedRoad: right of way enforced every simulation_frequency // 2 frames
    *timing_options(15, 1, 5, minimum_simulation_hz=2),
)  # fmt: skip


SCENARIO = Scenario(
    "intersection",
    "highway_env.envs.intersection_env.IntersectionEnv",
    "unsignalised 4-way crossing, turn left to exit o1",
    # its traffic class is its own (see IntersectionIDMVehicle): highway-env's env sets its class's
    # IDM constants, which must not change the other scenarios' traffic
    config={
        "duration": 13,
        "destination": "o1",
        "other_vehicles_type": "drivelab.sim.reference.highway.IntersectionIDMVehicle",
    },
    traffic={
        "empty": {"keep_npcs": False, "initial_vehicle_count": 0, "spawn_probability": 0.0},
        "regular": {"initial_vehicle_count": 10, "spawn_probability": 0.6},
        "dense": {"initial_vehicle_count": 15, "spawn_probability": 0.9},
    },
    destination="o1",
    arrival="exit",
    traffic_flow=True,
    intersection_nodes=("ir0", "ir1", "ir2", "ir3"),
    meta_target_speeds=(0, 4.5, 9),
    spawn=spawn_intersection,
    arrivals=IntersectionTraffic.of,
    options=OPTIONS,
)
