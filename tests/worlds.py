"""Hand-built WorldStates for tests."""

import dataclasses

import numpy as np

from drivelab.world.state import Ego, Events, RoadMap, Route, WorldState


def world(
    *,
    vehicles=(),
    progress_m=0.0,
    route_length_m=float("inf"),
    events=None,
    time_s=0.0,
    **ego,
) -> WorldState:
    """A straight-road world: ego at the origin heading +x unless overridden."""
    ego_state = Ego(position=np.zeros(2), heading=0.0, speed_mps=20.0)
    ego_state = dataclasses.replace(ego_state, **ego)
    polyline = np.array([[0.0, 0.0], [1000.0, 0.0]])
    return WorldState(
        time_s=time_s,
        dt_s=1.0,
        ego=ego_state,
        vehicles=np.asarray(vehicles, dtype=float).reshape(-1, 6),
        road=RoadMap.empty(),
        route=Route(polyline, progress_m, route_length_m),
        events=events or Events(),
    )
