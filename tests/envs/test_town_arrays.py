"""The town's kernel arrays against the reference's readings of node names and its routes."""

from __future__ import annotations

import numpy as np
import pytest

from drivelab.scenarios.town.reference_env import street_lanes
from drivelab.scenarios.town.road import (
    LAYOUTS,
    TownLights,
    approach_of,
    build_network,
    shortest_route,
)
from drivelab.sim.core.lanes import LaneTable
from drivelab.sim.junctions.rows import TURN_LEFT, TURN_RIGHT, TURN_STRAIGHT
from tests.envs.town_reference import road_arrays


@pytest.mark.parametrize("name", sorted(LAYOUTS))
def test_lane_metadata_matches_node_names(name):
    layout = LAYOUTS[name]
    network, arrays = build_network(layout), road_arrays(layout)
    table = LaneTable.from_network(network)
    lights = TownLights(layout, None, np.zeros(len(layout.junctions)))
    assert arrays.junction_count == len(layout.junctions)
    assert [
        tuple(map(int, pair)) for pair in zip(arrays.light_junction, arrays.light_arm, strict=True)
    ] == lights.approaches
    assert np.array_equal(arrays.light_xyh[:, :2], lights.positions)
    for index, row in table.row_of.items():
        start, end, _ = index
        approach = approach_of(index)
        assert (arrays.end_junction[row], arrays.end_arm[row]) == (approach or (-1, -1))
        assert arrays.light[row] == (lights.index[approach] if approach in lights.index else -1)
        assert arrays.in_junction[row] == (":ir" in start)
        if ":ir" in start:
            k, m = int(start.split(":ir")[1]), int(end.split(":il")[1])
            assert (arrays.junction[row], arrays.from_arm[row], arrays.to_arm[row]) == (
                int(start[1:].split(":")[0]),
                k,
                m,
            )
            expected = {(k - 1) % 4: TURN_RIGHT, (k + 1) % 4: TURN_LEFT, (k + 2) % 4: TURN_STRAIGHT}[m]
            assert arrays.turn[row] == expected
        else:
            assert arrays.junction[row] == arrays.turn[row] == arrays.from_arm[row] == -1
    assert [table.row_of[lane] for lane in street_lanes(network)] == arrays.street_lanes.tolist()


@pytest.mark.parametrize("name", sorted(LAYOUTS))
def test_route_table_is_every_shortest_route(name):
    network, arrays = build_network(LAYOUTS[name]), road_arrays(LAYOUTS[name])
    table = LaneTable.from_network(network)
    lanes = {row: index for index, row in table.row_of.items()}
    goals = [lanes[int(row)][1] for row in arrays.street_lanes]
    for row, index in lanes.items():
        for g, goal in enumerate(goals):
            route = shortest_route(network, index[:2], goal)
            assert arrays.route_length[row, g] == len(route)
            assert [lanes[int(r)] for r in arrays.routes[row, g, : len(route)]] == route
            assert (arrays.routes[row, g, len(route) :] == -1).all()
    assert arrays.route_length[arrays.street_lanes].max() + 1 <= 40  # fits a town row with a retarget
