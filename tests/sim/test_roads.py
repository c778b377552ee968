"""Roads described as blocks (L0, exact): the description gives bit-for-bit the highway-env
networks the town and the circuits were built with before it existed, the same lane table and
road map without highway-env, and the town's lane metadata, lights, crossings and routes.

The oracles ``_old_town_network`` and ``_old_circuit_network`` are frozen copies of
``scenarios/town/road.py:build_network`` and ``scenarios/circuits/reference_env.py:build_circuit``
as they were before the description (main 2317419): a formula that drifts makes these tests fail.
"""

from __future__ import annotations

import dataclasses
import subprocess
import sys

import numpy as np
import pytest
from highway_env.road.lane import CircularLane, LineType, StraightLane
from highway_env.road.road import RoadNetwork

from drivelab.scenarios.circuits import FOLLOW_LANE, FOLLOW_LINE
from drivelab.scenarios.circuits.reference_env import FollowLaneEnv, FollowLineEnv, build_circuit
from drivelab.scenarios.circuits.tracks import FOLLOW_LANE_TRACK, FOLLOW_LINE_TRACK
from drivelab.scenarios.town import SCENARIO as TOWN
from drivelab.scenarios.town.reference_env import fixed_routes
from drivelab.scenarios.town.road import LAYOUTS, build_network, road_description
from drivelab.sim.core import lanes as L
from drivelab.sim.core.lanes import LaneTable
from drivelab.sim.junctions.arrays import shortest_route
from drivelab.sim.junctions.arrays_description import town_arrays
from drivelab.sim.junctions.rows import TURN_LEFT, TURN_RIGHT, TURN_STRAIGHT
from drivelab.sim.junctions.rules import (
    ARM_DIRECTIONS,
    CROSSING_WIDTH_M,
    LANE_WIDTH_M,
    LEFT_TURN_RADIUS_M,
    OUTER_M,
    RIGHT_TURN_RADIUS_M,
    SPEED_LIMIT_MPS,
    TURN_SPEED_MPS,
)
from drivelab.sim.junctions.traffic import connected_lanes
from drivelab.sim.reference.highway import _lane_stations, build_road_map
from drivelab.sim.roads import blocks
from drivelab.sim.roads.highway_network import to_road_network
from drivelab.sim.roads.road_map import centre_line, circuit_route, road_map
from drivelab.sim.roads.road_map import lane_points as _lane_points
from tests.envs.town_reference import town_arrays_from_network


def _connected_lanes(desc) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The lanes highway-env's ``Road.neighbour_vehicles`` also searches (its
    ``neighbour_vehicles_connected_lanes``), as CSR: for lane row r, ``rows[offsets[r]:
    offsets[r + 1]]`` are first every road leaving r's end node (graph order), then every road
    entering its start node (graph order of their origins), each as the lane of r's id on that
    road, else its lane 0; ``before`` (E,) is True for the latter (offset -their length, the
    former +r's length). Shapes: offsets (L + 1,), rows (E,), before (E,) bool."""
    graph, offsets, rows, before = desc.graph, [0], [], []
    for f, t, i in desc.indices:
        for lanes in graph.get(t, {}).values():
            rows.append(lanes[i] if i < len(lanes) else lanes[0])
            before.append(False)
        for to in graph.values():
            if f in to:
                lanes = to[f]
                rows.append(lanes[i] if i < len(lanes) else lanes[0])
                before.append(True)
        offsets.append(len(rows))
    return np.array(offsets, dtype=np.int64), np.array(rows, dtype=np.int64), np.array(before, dtype=bool)


def _arrays_equal(arrays, other) -> bool:
    """Two TownRoadArrays: every array equal (exactly), and the same junction count."""
    names = [name for name in arrays.__dataclass_fields__ if name != "junction_count"]
    return arrays.junction_count == other.junction_count and all(
        np.array_equal(getattr(arrays, name), getattr(other, name)) for name in names
    )


# --- frozen oracles: the town and circuit construction before the road description ------------
class _OldLayout:
    def __init__(self, cells, streets, block_m):
        self.junctions, self.streets, self.block_m = cells, streets, block_m

    def arms(self, junction):
        column, row = self.junctions[junction]
        found = {}
        for a, b in self.streets:
            if junction not in (a, b):
                continue
            other = b if a == junction else a
            step = (self.junctions[other][0] - column, self.junctions[other][1] - row)
            found[ARM_DIRECTIONS.index(step)] = other
        return found

    def centre(self, junction):
        column, row = self.junctions[junction]
        return np.array([column * self.block_m, row * self.block_m], dtype=float)


def _old_grid(columns, rows, missing=()):
    cells = tuple((c, r) for r in range(rows) for c in range(columns))
    index = {cell: k for k, cell in enumerate(cells)}
    streets = []
    for (c, r), k in index.items():
        for step in ((1, 0), (0, 1)):
            other = (c + step[0], r + step[1])
            if other in index and ((c, r), other) not in missing:
                streets.append((k, index[other]))
    return cells, tuple(streets)


def _old_rotation(arm):
    angle = np.radians(90 * arm)
    return np.array([[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]])


def _old_stop_line(layout, junction, arm):
    return layout.centre(junction) + _old_rotation(arm) @ np.array([LANE_WIDTH_M / 2, OUTER_M])


def _old_town_network(layout):
    net = RoadNetwork()
    n, c, s = LineType.NONE, LineType.CONTINUOUS, LineType.STRIPED
    w = LANE_WIDTH_M
    for j in range(len(layout.junctions)):
        centre, arms = layout.centre(j), layout.arms(j)
        for k in arms:
            angle, rotation = np.radians(90 * k), _old_rotation(k)
            if (k - 1) % 4 in arms:
                net.add_lane(f"J{j}:ir{k}", f"J{j}:il{(k - 1) % 4}", CircularLane(
                    centre + rotation @ np.array([OUTER_M, OUTER_M]), RIGHT_TURN_RADIUS_M,
                    angle + np.radians(180), angle + np.radians(270),
                    line_types=[n, c], speed_limit=TURN_SPEED_MPS,
                ))  # fmt: skip
            if (k + 1) % 4 in arms:
                net.add_lane(f"J{j}:ir{k}", f"J{j}:il{(k + 1) % 4}", CircularLane(
                    centre + rotation @ np.array([-LEFT_TURN_RADIUS_M + w / 2, LEFT_TURN_RADIUS_M - w / 2]),
                    LEFT_TURN_RADIUS_M, angle, angle + np.radians(-90), clockwise=False,
                    line_types=[n, n], speed_limit=TURN_SPEED_MPS,
                ))  # fmt: skip
            if (k + 2) % 4 in arms:
                net.add_lane(f"J{j}:ir{k}", f"J{j}:il{(k + 2) % 4}", StraightLane(
                    centre + rotation @ np.array([w / 2, OUTER_M]),
                    centre + rotation @ np.array([w / 2, -OUTER_M]),
                    line_types=[n, n], speed_limit=SPEED_LIMIT_MPS,
                ))  # fmt: skip
    for a, b in layout.streets:
        for start_j, end_j in ((a, b), (b, a)):
            out_arm = next(k for k, other in layout.arms(start_j).items() if other == end_j)
            in_arm = (out_arm + 2) % 4
            start = layout.centre(start_j) + _old_rotation(out_arm) @ np.array([-w / 2, OUTER_M])
            net.add_lane(
                f"J{start_j}:il{out_arm}",
                f"J{end_j}:ir{in_arm}",
                StraightLane(
                    start,
                    _old_stop_line(layout, end_j, in_arm),
                    line_types=[s, c],
                    speed_limit=SPEED_LIMIT_MPS,
                ),
            )
    return net


def _old_crossings(layout):
    rows = []
    for a, b in layout.streets:
        centre = (layout.centre(a) + layout.centre(b)) / 2
        along = layout.centre(b) - layout.centre(a)
        heading = float(np.arctan2(along[1], along[0])) + np.pi / 2
        rows.append([*centre, heading, 2 * LANE_WIDTH_M, CROSSING_WIDTH_M])
    return np.array(rows, dtype=float).reshape(-1, 5)


def _old_lights(layout):
    approaches = [
        (j, k) for j in range(len(layout.junctions)) if len(layout.arms(j)) >= 3 for k in layout.arms(j)
    ]
    positions = np.array([_old_stop_line(layout, j, k) for j, k in approaches]).reshape(-1, 2)
    headings = np.radians([90.0 * k - 90.0 for _, k in approaches])
    return approaches, np.column_stack([positions, headings]).reshape(-1, 3)


def _old_circuit_network(track, lane_count, lane_width_m, speed_limit_mps):
    network = RoadNetwork()
    position, heading = np.zeros(2), 0.0
    offsets = (np.arange(lane_count) - (lane_count - 1) / 2) * lane_width_m
    for index, (kind, *values) in enumerate(track):
        start, end = str(index), str((index + 1) % len(track))
        for lane_id, offset in enumerate(offsets):
            line_types = (
                LineType.CONTINUOUS if lane_id == 0 else LineType.STRIPED,
                LineType.CONTINUOUS if lane_id == lane_count - 1 else LineType.NONE,
            )
            normal = np.array([-np.sin(heading), np.cos(heading)])  # to the right
            if kind == "straight":
                (length,) = values
                direction = np.array([np.cos(heading), np.sin(heading)])
                lane = StraightLane(
                    position + offset * normal, position + offset * normal + length * direction,
                    line_types=line_types, width=lane_width_m, speed_limit=speed_limit_mps,
                )  # fmt: skip
            else:
                radius, turn_deg = values
                side = 1.0 if turn_deg > 0 else -1.0
                centre = position + side * radius * normal
                start_phase = heading - side * np.pi / 2
                lane = CircularLane(
                    centre, radius - side * offset, start_phase, start_phase + np.radians(turn_deg),
                    clockwise=side > 0, line_types=line_types, width=lane_width_m,
                    speed_limit=speed_limit_mps,
                )  # fmt: skip
            network.add_lane(start, end, lane)
        reference = network.get_lane((start, end, 0))
        position = reference.position(reference.length, -offsets[0])
        heading = float(reference.heading_at(reference.length))
    return network


# --- the roads under test ----------------------------------------------------------------------
TOWNS = {  # name: (description, oracle layout)
    "train": (blocks.grid(3, 3, 70.0), _OldLayout(*_old_grid(3, 3), 70.0)),
    "test": (blocks.grid(3, 2, 60.0, palette="dusk"), _OldLayout(*_old_grid(3, 2), 60.0)),
    # links left out: T-junctions and corners facing other ways, a dead end, a straight join
    "sparse": (
        blocks.grid(3, 3, 50.0, missing=(((1, 1), (2, 1)), ((0, 0), (1, 0)), ((1, 2), (2, 2)))),
        _OldLayout(*_old_grid(3, 3, (((1, 1), (2, 1)), ((0, 0), (1, 0)), ((1, 2), (2, 2)))), 50.0),
    ),
}
CIRCUITS = {
    "follow-line": (FOLLOW_LINE_TRACK, 1, 7.0, 20.0),
    "follow-lane": (FOLLOW_LANE_TRACK, 3, 3.5, 20.0),
    "narrow-two-lane": (FOLLOW_LINE_TRACK, 2, 3.0, 12.0),
}


def _roads():
    roads = {name: (desc, _old_town_network(layout)) for name, (desc, layout) in TOWNS.items()}
    for name, args in CIRCUITS.items():
        roads[name] = (blocks.circuit(*args, guide_line=name == "follow-line"), _old_circuit_network(*args))
    return roads


ROADS = _roads()


def _assert_same_network(network: RoadNetwork, oracle: RoadNetwork) -> None:
    """Same graph order and every lane attribute equal (arrays exactly)."""
    assert [(f, list(to)) for f, to in network.graph.items()] == [
        (f, list(to)) for f, to in oracle.graph.items()
    ]
    for f, to in oracle.graph.items():
        for t, lanes in to.items():
            assert len(network.graph[f][t]) == len(lanes)
            for lane, expected in zip(network.graph[f][t], lanes, strict=True):
                assert type(lane) is type(expected)
                assert vars(lane).keys() == vars(expected).keys()
                for name, value in vars(expected).items():
                    assert np.array_equal(np.asarray(getattr(lane, name)), np.asarray(value)), (f, t, name)


@pytest.mark.parametrize("name", sorted(ROADS))
def test_description_gives_the_old_network_bit_for_bit(name):
    desc, oracle = ROADS[name]
    _assert_same_network(to_road_network(desc), oracle)


def test_the_town_and_circuit_builders_give_the_old_networks():
    for name in ("train", "test"):
        _assert_same_network(build_network(LAYOUTS[name]), ROADS[name][1])
    for name, args in CIRCUITS.items():
        _assert_same_network(build_circuit(*args), ROADS[name][1])


def test_a_formula_that_drifts_is_caught():
    desc, oracle = ROADS["train"]
    moved = np.array(desc.centre)
    moved[1, 0] = np.nextafter(moved[1, 0], np.inf)  # one ULP on one arc's centre
    drifted = dataclasses.replace(desc, centre=moved)
    with pytest.raises(AssertionError):
        _assert_same_network(to_road_network(drifted), oracle)


@pytest.mark.parametrize("name", sorted(ROADS))
def test_lane_table_from_the_description_needs_no_highway_env(name):
    desc, oracle = ROADS[name]
    table, expected = LaneTable.from_description(desc), LaneTable.from_network(oracle)
    assert table.indices == expected.indices and table.nodes == expected.nodes
    assert np.array_equal(table.rows, expected.rows)


def _loop_polyline(network: RoadNetwork, start: tuple) -> np.ndarray:
    """The highway backend's route polyline of a circuit from lane ``start`` (its _plan_route)."""
    nodes = [start[0], start[1]]
    while nodes[-1] != nodes[0]:
        nodes.append(next(iter(network.graph[nodes[-1]])))
    lanes = [
        (a, b, min(start[2], len(network.graph[a][b]) - 1))
        for a, b in zip(nodes[:-1], nodes[1:], strict=True)
    ]
    return np.concatenate(
        [_lane_points(network.get_lane(i), _lane_stations(network.get_lane(i)), 0.0) for i in lanes]
    )


@pytest.mark.parametrize("name", sorted(ROADS))
def test_road_map_is_the_highway_backends(name):
    desc, oracle = ROADS[name]
    built, expected = road_map(desc), build_road_map(oracle)
    for field in ("lane_polygons", "lane_centerlines"):
        assert len(getattr(built, field)) == len(getattr(expected, field)) == desc.lane_count
        assert all(
            np.array_equal(a, b) for a, b in zip(getattr(built, field), getattr(expected, field), strict=True)
        )
    for field in ("lane_widths_m", "markings", "marking_kinds", "edges"):
        assert np.array_equal(getattr(built, field), getattr(expected, field)), field
    if name in TOWNS:
        assert np.array_equal(built.crossings, _old_crossings(TOWNS[name][1]))
    else:
        assert built.crossings.shape == (0, 5)
    if name == "follow-line":  # the guide line: one lap along lane 0 from node "0"
        (guide,) = built.guide_lines
        assert np.array_equal(guide, _loop_polyline(oracle, ("0", "1", 0)))
    else:
        assert built.guide_lines == ()


@pytest.mark.parametrize("name", sorted(CIRCUITS))
def test_circuit_routes_are_the_highway_backends(name):
    desc, oracle = ROADS[name]
    for row, index in enumerate(desc.indices):
        rows = circuit_route(desc, row)
        assert len(rows) == len(CIRCUITS[name][0]) and rows[0] == row
        assert np.array_equal(centre_line(desc, rows), _loop_polyline(oracle, index))


@pytest.mark.parametrize("name", sorted(TOWNS))
def test_town_metadata_equals_the_node_name_oracle(name):
    desc, layout = TOWNS[name]
    oracle = _old_town_network(layout)
    approaches, light_xyh = _old_lights(layout)
    expected = town_arrays_from_network(
        oracle, approaches, light_xyh, _old_crossings(layout), len(layout.junctions)
    )
    arrays = town_arrays(desc)
    assert _arrays_equal(arrays, expected)
    assert desc.junction_arms == tuple(tuple(layout.arms(j)) for j in range(len(layout.junctions)))
    assert desc.junction_signalised.tolist() == [
        len(layout.arms(j)) >= 3 for j in range(len(layout.junctions))
    ]
    assert np.array_equal(desc.junction_centre, [layout.centre(j) for j in range(len(layout.junctions))])
    # each crossing lies across its two street lanes: on both lanes' lines, halfway along
    table = LaneTable.from_description(desc)
    for crossing, lanes in zip(desc.crossings, desc.crossing_lanes, strict=True):
        assert all(desc.end_junction[r] >= 0 for r in lanes)
        lengths = table.rows[lanes, 6]  # LENGTH
        assert lengths[0] == lengths[1]
        ends = desc.start[lanes] + desc.end[lanes]
        np.testing.assert_allclose(ends.sum(axis=0) / 4, crossing[:2], atol=1e-9)


@pytest.mark.parametrize("name", sorted(TOWNS))
def test_turns_follow_the_arms(name):
    desc, _ = TOWNS[name]
    junction_lanes = np.flatnonzero(desc.in_junction)
    expected = {-1 % 4: TURN_RIGHT, 1: TURN_LEFT, 2: TURN_STRAIGHT}
    turns = [expected[(desc.to_arm[r] - desc.from_arm[r]) % 4] for r in junction_lanes]
    assert desc.turn[junction_lanes].tolist() == turns
    assert (desc.turn[~desc.in_junction] == -1).all()
    # X: 12 lanes, T: 6, corner: 2 (every arm can reach every other one)
    for j, arms in enumerate(desc.junction_arms):
        assert (desc.junction == j).sum() == len(arms) * (len(arms) - 1)


@pytest.mark.parametrize("name", sorted(LAYOUTS))
def test_route_table_is_every_shortest_route(name):
    desc = road_description(LAYOUTS[name])
    arrays, network = town_arrays(desc), ROADS[name][1]
    indices = desc.indices
    goals = [indices[g][1] for g in arrays.street_lanes]
    assert [indices[r] for r in arrays.street_lanes] == [
        (f, t, 0) for f, to in network.graph.items() for t in to if ":ir" in t
    ]
    for row, index in enumerate(indices):
        for g, goal in enumerate(goals):
            route = shortest_route(network.graph, index[:2], goal)
            assert arrays.route_length[row, g] == len(route)
            assert [indices[r] for r in arrays.routes[row, g, : len(route)]] == route
            assert (arrays.routes[row, g, len(route) :] == -1).all()


@pytest.mark.parametrize("name", sorted(LAYOUTS))
def test_fixed_routes_are_unchanged(name):
    routes = fixed_routes(build_network(LAYOUTS[name]))
    assert len(routes) == 25 and routes == fixed_routes(ROADS[name][1])


def test_scenarios_describe_their_roads():
    for layout in ("train", "test"):
        _assert_same_network(to_road_network(TOWN.road({"layout": layout})), ROADS[layout][1])
    _assert_same_network(to_road_network(TOWN.road({})), ROADS["train"][1])
    for scenario, env in ((FOLLOW_LINE, FollowLineEnv), (FOLLOW_LANE, FollowLaneEnv)):
        config = env.default_config()
        road = scenario.road(config)
        expected = build_circuit(
            config["track"], config["lanes_count"], config["lane_width"], config["speed_limit"]
        )
        _assert_same_network(to_road_network(road), expected)
        _assert_same_network(to_road_network(scenario.road({})), expected)
        assert len(road.guide_lines) == int(scenario.guide_line)


def test_the_fast_path_builds_no_highway_env_object():
    code = (
        "import sys\n"
        "from drivelab.sim.core.lanes import LaneTable\n"
        "from drivelab.sim.roads.road_map import road_map\n"
        "from drivelab.sim.junctions.arrays_description import town_arrays\n"
        "from drivelab.scenarios.circuits import FOLLOW_LINE\n"
        "from drivelab.scenarios.town import SCENARIO\n"
        "for road in (SCENARIO.road({'layout': 'test'}), FOLLOW_LINE.road({})):\n"
        "    LaneTable.from_description(road), road_map(road)\n"
        "town_arrays(SCENARIO.road({'layout': 'test'}))\n"
        "print(sorted(m for m in sys.modules if m.startswith('highway_env')))\n"
    )
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert result.stdout.strip() == "[]"


@pytest.mark.parametrize("name", sorted(ROADS))
def test_connected_lanes_are_the_ones_highway_env_searches(name):
    desc, oracle = ROADS[name]
    offsets, rows, before = _connected_lanes(desc)
    indices = desc.indices
    for row, (f, t, i) in enumerate(indices):
        expected = []  # Road.neighbour_vehicles with neighbour_vehicles_connected_lanes
        for to, lanes in oracle.graph.get(t, {}).items():
            expected.append(((t, to, i if i < len(lanes) else 0), False))
        for origin, to_dict in oracle.graph.items():
            if f in to_dict:
                expected.append(((origin, f, i if i < len(to_dict[f]) else 0), True))
        found = [
            (indices[r], bool(b))
            for r, b in zip(
                rows[offsets[row] : offsets[row + 1]], before[offsets[row] : offsets[row + 1]], strict=True
            )
        ]
        assert found == expected


@pytest.mark.parametrize("name", sorted(ROADS))
def test_the_town_kernels_search_table_is_the_descriptions(name):
    """``junctions.traffic.connected_lanes`` derives the same search from the lane table alone: each
    lane itself (offset 0), then the description's connected lanes in order, offset by the lane's
    length for those it leads into and by minus their own length for those leading into it."""
    desc, _ = ROADS[name]
    lanes = LaneTable.from_description(desc).rows
    search, offset, size, _ = connected_lanes(lanes)
    offsets, rows, before = _connected_lanes(desc)
    for row in range(len(lanes)):
        connected = rows[offsets[row] : offsets[row + 1]]
        shifts = np.where(
            before[offsets[row] : offsets[row + 1]], -lanes[connected, L.LENGTH], lanes[row, L.LENGTH]
        )
        assert size[row] == 1 + len(connected)
        assert search[row, : size[row]].tolist() == [row, *connected.tolist()]
        np.testing.assert_array_equal(offset[row, : size[row]], [0.0, *shifts])


@pytest.mark.parametrize(
    "scenario, control, overrides",
    [
        ("town", "meta", {}),
        ("town", "continuous", {"layout": "test", "fixed_routes": True}),
        ("follow-line", "continuous", {}),
        ("follow-lane", "continuous", {}),
    ],
)
def test_a_described_road_converts_as_highway_env_builds_it(scenario, control, overrides):
    """The compiled core's road from the description (no highway-env object) equals the one it
    converts from a highway-env env built from the same config: lanes, road map, config, timing,
    target speeds, vehicle sizes and every ego route."""
    from drivelab.scenarios import SCENARIOS
    from drivelab.sim.core.simulator import _convert_road, _describe_road
    from drivelab.sim.reference.highway import HighwayBackend

    spec = SCENARIOS[scenario]
    described = _describe_road(spec, "regular", control, overrides)
    builder = HighwayBackend(spec, "regular", control, overrides)
    builder.reset(0)
    built = _convert_road(builder, spec)
    np.testing.assert_array_equal(described.table.rows, built.table.rows)
    assert described.table.indices == built.table.indices
    for name in ("lane_centerlines", "lane_polygons"):
        for a, b in zip(getattr(described.road_map, name), getattr(built.road_map, name), strict=True):
            np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(described.road_map.markings, built.road_map.markings)
    rendering = {"offscreen_rendering"}  # set by highway-env's env at construction, for its own renderer
    assert {k: v for k, v in described.config.items() if k not in rendering} == {
        k: v for k, v in built.config.items() if k not in rendering
    }
    np.testing.assert_array_equal(described.target_speeds, built.target_speeds)
    scalars = ("frames", "dt_s", "policy_frequency_hz", "duration_s", "ego_length", "ego_width", "npc_length")
    for name in (*scalars, "npc_width", "lane_change_delay", "idm_delta", "keep_npcs", "extra_vehicles"):
        assert getattr(described, name) == getattr(built, name), name
    np.testing.assert_array_equal(described.in_junction, built.in_junction)
    if spec.circuit:  # the town's ego routes are planned per episode, not per lane
        assert described.routes.keys() == built.routes.keys()
        for row, tracker in built.routes.items():
            np.testing.assert_array_equal(described.routes[row].polyline, tracker.polyline)
