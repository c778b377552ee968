"""The reference town's state as the compiled core's rows, for equivalence tests.

``reference_town(layout, traffic, seed)`` runs the reference (``HighwayBackend`` on
``TownEnv``) and ``town_rows(env)`` reads its vehicles and pedestrians into
``TOWN_VEHICLE_COLUMNS`` / ``PEDESTRIAN_COLUMNS`` rows, in the reference's list orders.
"""

from __future__ import annotations

import numpy as np

from drivelab.scenarios import SCENARIOS
from drivelab.scenarios.town.reference_env import TownEnv, TownVehicle
from drivelab.scenarios.town.road import LAYOUTS, road_arrays
from drivelab.sim.core.lanes import LaneTable
from drivelab.sim.core.simulator import vehicles_to_array
from drivelab.sim.junctions import rows as R
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
    from drivelab.scenarios.town.road import build_network

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
