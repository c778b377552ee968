"""RoundaboutEnv's episode set-up (``_make_vehicles``) as vehicle rows, without highway-env
objects: the same draws from the same generator in the same order, hence the same rows."""

from __future__ import annotations

import numpy as np
from gymnasium.utils import seeding

from drivelab.scenarios.options import Option, arranged_traffic_options, timing_options
from drivelab.sim.core.spawn import (
    arrange_traffic,
    ego_kind,
    finish,
    make_on_lane,
    plan_route,
    randomize_behavior,
    vehicle_row,
)
from drivelab.world.scenario import Scenario

RING = ("se", "ex", "ee", "nx", "ne", "wx", "we", "sx")  # the nodes around the ring
DESTINATIONS = ["exr", "sxr", "nxr"]  # the exits RoundaboutEnv routes its traffic to
EGO_DESTINATION = "nxs"
POSITION_DEVIATION = SPEED_DEVIATION = 2.0


def _npc(road, rng: np.random.Generator, lane: tuple, longitudinal: float, destination: str | None = None):
    """A vehicle on ``lane`` about ``longitudinal`` along it at about 16 m/s, routed to
    ``destination`` (None: a random exit), with a random DELTA (RoundaboutEnv's draws, in order)."""
    s = longitudinal + rng.normal() * POSITION_DEVIATION
    row = make_on_lane(road, road.geometry.row_of[lane], s, 16.0 + rng.normal() * SPEED_DEVIATION)
    plan_route(row, road, rng.choice(DESTINATIONS) if destination is None else destination)
    randomize_behavior(row, rng)
    return row


def spawn_roundabout(seed: int, road, control: str) -> tuple[np.ndarray, int, np.ndarray, None]:
    """The ego entering from the south (routed north under meta-actions), a vehicle on the ring's
    inner lane, two on its outer lane and one entering from the east, each routed to a random
    exit with a random DELTA, then the traffic level's changes. Returns (rows, ego row,
    regulation, None)."""
    rng, _ = seeding.np_random(int(seed))
    geometry = road.geometry
    ego_lane = geometry.row_of[("ser", "ses", 0)]
    position, heading = geometry.position(ego_lane, 125.0, 0.0), geometry.heading_at(ego_lane, 140.0)
    ego = vehicle_row(road, position, heading, 8.0, ego_kind(control))
    if control == "meta":  # an MDPVehicle plans its route; a plain Vehicle has none
        plan_route(ego, road, EGO_DESTINATION)
    incoming = road.config.get("incoming_vehicle_destination")
    vehicles = [
        ego,
        _npc(road, rng, ("we", "sx", 1), 5.0, None if incoming is None else DESTINATIONS[incoming]),
    ]
    # the other vehicles: ahead of and behind it on the outer lane, then one entering from the east
    for lane, longitudinal in ((("we", "sx", 0), 20.0), (("we", "sx", 0), -20.0), (("eer", "ees", 0), 50.0)):
        vehicles.append(_npc(road, rng, lane, longitudinal))
    vehicles, ego_index = arrange_traffic(road, vehicles, 0, rng)
    return finish(road, vehicles), ego_index, np.zeros(2), None


OPTIONS = (
    Option(
        "incoming_vehicle_destination", int, None,
        f"the exit of the vehicle entering from the west (0, 1, 2: {', '.join(DESTINATIONS)}); null: random",
        minimum=0, maximum=len(DESTINATIONS) - 1, nullable=True,
    ),
    *arranged_traffic_options(),
    *timing_options(15, 1, 5),
)  # fmt: skip


SCENARIO = Scenario(
    "roundabout",
    "highway_env.envs.roundabout_env.RoundaboutEnv",
    "two-lane roundabout, enter from the south and leave to the north",
    config={"duration": 11},
    traffic={"empty": {"keep_npcs": False}, "regular": {}, "dense": {"extra_vehicles": 5}},
    destination="nxs",
    intersection_nodes=RING,
    meta_target_speeds=(0, 8, 16),
    spawn=spawn_roundabout,
    junction_needs_both_ends=True,
    options=OPTIONS,
)
