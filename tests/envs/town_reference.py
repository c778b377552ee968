"""The reference town's state as the compiled core's rows, for equivalence tests.

``reference_town(layout, traffic, seed)`` runs the reference (``HighwayBackend`` on
``TownEnv``) and ``town_rows(env)`` reads its vehicles and pedestrians into
``TOWN_VEHICLE_COLUMNS`` / ``PEDESTRIAN_COLUMNS`` rows, in the reference's list orders.
``town_arrays_from_network`` derives the town's kernel arrays from a highway-env network's node
names, as the reference does: the oracle that the road description's arrays must equal.
"""

from __future__ import annotations

import numpy as np

from drivelab.scenarios import SCENARIOS
from drivelab.scenarios.town.reference_env import TownEnv, TownVehicle
from drivelab.scenarios.town.road import LAYOUTS, TownLayout, TownLights, build_network, street_crossings
from drivelab.sim.core.lanes import LaneTable
from drivelab.sim.core.simulator import vehicles_to_array
from drivelab.sim.junctions import rows as R
from drivelab.sim.junctions.arrays import TownRoadArrays, route_table
from drivelab.sim.junctions.rules import LightTimings
from drivelab.sim.reference.highway import HighwayBackend


def reference_town(
    layout: str = "train", traffic: str = "regular", seed: int = 0, control: str = "meta", **config
) -> HighwayBackend:
    """A reset reference backend of the town (``backend.env`` is its ``TownEnv``)."""
    backend = HighwayBackend(SCENARIOS["town"], traffic, control, {"layout": layout, **config})
    backend.reset(seed)
    return backend


def town_tables(layout: str) -> tuple:
    """(LaneTable, TownRoadArrays) of a layout: the compiled core's view of its road."""
    return LaneTable.from_network(build_network(LAYOUTS[layout])), road_arrays(LAYOUTS[layout])


def town_rows(env: TownEnv, table: LaneTable, arrays) -> tuple[np.ndarray, np.ndarray, int]:
    """``(vehicles (N, TOWN_VEHICLE_COLUMNS), pedestrians (P, PEDESTRIAN_COLUMNS), ego row)`` of
    ``env`` (the unwrapped ``TownEnv``): vehicles in ``road.vehicles`` order, every pedestrian in
    spawn order (crashed ones too, flagged)."""
    road = env.road
    vehicles = vehicles_to_array(road.vehicles, table, town_class=TownVehicle)
    pedestrians = np.zeros((len(road.pedestrians), R.PEDESTRIAN_COLUMNS))
    for row, walker in zip(pedestrians, road.pedestrians, strict=True):
        row[R.P_X], row[R.P_Y] = walker.position
        row[R.P_HEADING], row[R.P_SPEED] = walker.heading, walker.speed
        row[R.P_SIDE], row[R.P_PACE], row[R.P_WAIT_S] = walker.side, walker.pace_mps, walker.wait_s
        row[R.P_CRASHED] = float(walker.crashed)
        row[R.P_HIT_EGO] = float(walker.hit_by is not None and walker.hit_by is road.ego)
        row[R.P_CENTRE_X], row[R.P_CENTRE_Y] = walker.centre
        row[R.P_ACROSS_X], row[R.P_ACROSS_Y] = walker.across
        matches = np.flatnonzero((arrays.crossings[:, :2] == walker.centre).all(axis=1))
        row[R.P_CROSSING] = matches[0]
    return vehicles, pedestrians, road.vehicles.index(road.ego)


def _junction_arm(node: str, kind: str) -> tuple[int, int] | None:
    """(junction, arm) of a node ``J{j}:{kind}{k}``, else None."""
    if f":{kind}" not in node:
        return None
    junction, arm = node[1:].split(f":{kind}")
    return int(junction), int(arm)


def town_arrays_from_network(
    network,
    approaches: list[tuple[int, int]],
    light_xyh: np.ndarray,
    crossings: np.ndarray,
    junction_count: int,
) -> TownRoadArrays:
    """The town's arrays from a highway-env ``RoadNetwork`` and its layout's lights (``approaches``
    (junction, arm) in light-row order with their ``light_xyh`` rows) and ``crossings``."""
    lanes = [(f, t, i) for f, to in network.graph.items() for t, ls in to.items() for i in range(len(ls))]
    size = len(lanes)
    junction, from_arm, to_arm, turn = (np.full(size, -1, dtype=np.int64) for _ in range(4))
    end_junction, end_arm, light = (np.full(size, -1, dtype=np.int64) for _ in range(3))
    light_row = {approach: m for m, approach in enumerate(approaches)}
    turns = {-1 % 4: R.TURN_RIGHT, 1: R.TURN_LEFT, 2: R.TURN_STRAIGHT}
    for r, (start, end, _) in enumerate(lanes):
        entry, leaving = _junction_arm(start, "ir"), _junction_arm(end, "il")
        if entry is not None and leaving is not None:
            junction[r], from_arm[r], to_arm[r] = entry[0], entry[1], leaving[1]
            turn[r] = turns[(leaving[1] - entry[1]) % 4]
        approach = _junction_arm(end, "ir")
        if approach is not None:
            end_junction[r], end_arm[r] = approach
            light[r] = light_row.get(approach, -1)
    streets = np.array([r for r, lane in enumerate(lanes) if ":ir" in lane[1]], dtype=np.int64)
    routes, lengths = route_table(network.graph, lanes, streets)
    return TownRoadArrays(
        junction=junction,
        from_arm=from_arm,
        to_arm=to_arm,
        turn=turn,
        end_junction=end_junction,
        end_arm=end_arm,
        light=light,
        in_junction=junction >= 0,
        light_xyh=np.asarray(light_xyh, dtype=float).reshape(-1, 3),
        light_junction=np.array([j for j, _ in approaches], dtype=np.int64),
        light_arm=np.array([k for _, k in approaches], dtype=np.int64),
        junction_count=int(junction_count),
        crossings=np.asarray(crossings, dtype=float).reshape(-1, 5),
        street_lanes=streets,
        routes=routes,
        route_length=lengths,
    )


def road_arrays(layout: TownLayout) -> TownRoadArrays:
    """The compiled kernels' arrays of ``layout`` read from its highway-env network's node names."""
    lights = TownLights(layout, LightTimings(), np.zeros(len(layout.junctions)))
    return town_arrays_from_network(
        build_network(layout),
        lights.approaches,
        np.column_stack([lights.positions, lights.headings]),
        street_crossings(layout),
        len(layout.junctions),
    )
