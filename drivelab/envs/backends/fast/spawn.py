"""Episode set-up without highway-env objects, drawing the same random numbers in the same order.

``spawn_highway`` reproduces ``HighwayEnv._create_vehicles`` (one controlled vehicle) with
``Vehicle.create_random`` and ``IDMVehicle.randomize_behavior``: given the same seed it places
the same vehicles at the same positions and speeds as highway-env does (tested).
"""

from __future__ import annotations

import numpy as np
from gymnasium.utils import seeding

from drivelab.envs.backends.fast import lanes as L
from drivelab.envs.backends.fast import traffic as T

DELTA_RANGE = (3.5, 4.5)  # IDMVehicle.DELTA_RANGE


def spawn_highway(seed: int, table: L.LaneTable, graph_keys: dict, config: dict, control: str, target_speeds):
    """Vehicle rows for a highway episode, the ego first, as highway-env would place them.

    :param graph_keys: ``{from: [to, ...]}`` of the road network, in its order.
    :param config: the highway-env config (vehicles_count, vehicles_density, ego_spacing, initial_lane_id).
    """
    rng, _ = seeding.np_random(int(seed))
    rows, row_of, lanes = [], table.row_of, table.rows
    longitudinals: list[float] = []

    def create_random(speed, lane_id, spacing):
        _from = rng.choice(list(graph_keys))
        _to = rng.choice(list(graph_keys[_from]))
        count = int(lanes[row_of[(_from, _to, 0)], L.LANE_COUNT])
        _id = lane_id if lane_id is not None else rng.choice(count)
        lane = row_of[(_from, _to, int(_id))]
        if speed is None:
            limit = lanes[lane, L.SPEED_LIMIT]
            speed = rng.uniform(0.7 * limit, 0.8 * limit)
        offset = spacing * (12 + 1.0 * speed) * np.exp(-5 / 40 * count)
        x0 = np.max(longitudinals) if longitudinals else 3 * offset
        x0 += offset * rng.uniform(0.9, 1.1)
        x, y = L.position(lanes, lane, x0, 0.0)
        # every highway lane starts at x = 0 along +x: a vehicle's longitudinal coordinate is its x
        longitudinals.append(x)
        row = np.zeros(T.VEHICLE_COLUMNS)
        row[T.X], row[T.Y], row[T.HEADING], row[T.SPEED] = x, y, L.heading_at(lanes, lane, x0), speed
        row[T.LANE] = row[T.TARGET_LANE] = L.closest_lane(lanes, x, y, row[T.HEADING])
        row[T.TARGET_SPEED] = speed
        row[T.DELTA] = 4.0
        row[T.LEN], row[T.WID] = T.CAR_LENGTH, T.CAR_WIDTH
        return row

    ego = create_random(25.0, config["initial_lane_id"], config["ego_spacing"])
    ego[T.CHECK_COLLISIONS] = 1.0
    if control == "meta":  # MDPVehicle snaps its target speed to the nearest allowed one
        speeds = np.asarray(target_speeds, dtype=float)
        ratio = (ego[T.SPEED] - speeds[0]) / (speeds[-1] - speeds[0])
        ego[T.TARGET_SPEED] = speeds[int(np.clip(np.round(ratio * (speeds.size - 1)), 0, speeds.size - 1))]
        ego[T.KIND] = T.CONTROLLED
    else:  # a plain kinematic vehicle has no target speed
        ego[T.KIND], ego[T.TARGET_SPEED] = T.PLAIN, 0.0
    rows.append(ego)
    for _ in range(config["vehicles_count"]):
        row = create_random(None, None, 1 / config["vehicles_density"])
        row[T.KIND] = T.IDM
        row[T.TIMER] = (np.sum(row[[T.X, T.Y]]) * np.pi) % 1.0  # IDMVehicle's initial timer
        row[T.DELTA] = rng.uniform(low=DELTA_RANGE[0], high=DELTA_RANGE[1])
        rows.append(row)
    return np.array(rows)
