"""Procedural maps (``roads.pg_map``): the block string, lanes joined without gaps or kinks at
every node, footprints that never overlap (an independent point test on the compiled core's lane
rows), the same map for the same seed, a route on every map, and descriptions that both
simulators read."""

from __future__ import annotations

import re

import numpy as np
import pytest

from drivelab.errors import UsageError
from drivelab.scenarios.blocks import pg_map
from drivelab.scenarios.blocks.pg_blocks import BlockSite, first_block, straight_block
from drivelab.scenarios.blocks.pg_map import (
    BLOCK_PROBABILITIES,
    BUILDERS,
    Footprint,
    generate_map,
    overlaps,
    parse_spec,
)
from drivelab.scenarios.blocks.pg_roads import Socket
from drivelab.sim.core import lanes as L
from drivelab.sim.core.lanes import LaneTable
from drivelab.sim.junctions.rows import TURN_LEFT, TURN_RIGHT, TURN_STRAIGHT
from drivelab.sim.roads.highway_network import to_road_network

# Positions are sums and products of coordinates below ~2 km, so rounding leaves ~1e-12 m; a gap
# or kink that matters is centimetres and degrees. 1e-6 m and 1e-9 rad sit far from both.
POSITION_TOL_M, HEADING_TOL_RAD = 1e-6, 1e-9
EVERY_BLOCK = "SCrRyYXTO"


def _maps_of_every_block():
    return [
        generate_map(EVERY_BLOCK, seed, lane_count=count, lane_width_m=width)
        for seed, count, width in ((0, 2, 3.5), (1, 3, 3.5), (2, 2, None), (3, 3, None))
    ] + [generate_map(letter, seed) for letter in BUILDERS for seed in range(3)]


MAPS = _maps_of_every_block()


# --- the block string ----------------------------------------------------------------------------
def test_a_block_string_gives_those_blocks_after_the_spawn_road():
    assert parse_spec("OSX") == ("O", "S", "X")
    osx = generate_map("OSX", 0)
    assert osx.letters == "IOSX"
    assert [block.index for block in osx.blocks] == [0, 1, 2, 3]
    assert [len(block.sockets) for block in osx.blocks] == [1, 3, 1, 3]
    assert {m.letters for m in MAPS} >= {"I" + EVERY_BLOCK} | {"I" + letter for letter in BUILDERS}


@pytest.mark.parametrize(
    ("spec", "names"),
    [("OQX", "['Q']"), ("", "at least one block"), ("IOS", "['I']"), (0, "at least 1 block"),
     (-2, "at least 1"), (True, "block count"), (2.5, "block count")],
)  # fmt: skip
def test_a_bad_spec_is_refused_naming_the_problem(spec, names):
    with pytest.raises(UsageError, match=re.escape(names)):
        generate_map(spec, 0)


def test_a_block_string_that_cannot_be_built_is_refused():
    with pytest.raises(UsageError, match="no layout after"):
        generate_map("yyy", 0, lane_count=2)


def test_random_blocks_follow_metadrives_distribution():
    letters = "".join(generate_map(7, seed, lane_count=2).letters[1:] for seed in range(60))
    assert set(letters) <= set(BLOCK_PROBABILITIES) and len(letters) == 420
    share = {letter: letters.count(letter) / len(letters) for letter in BLOCK_PROBABILITIES}
    # 420 draws: a share's standard error is at most 2.4 %; rebuilt blocks are redrawn, so a
    # block that overlaps more often (C) is kept a little less often than it is drawn
    for letter, probability in BLOCK_PROBABILITIES.items():
        assert abs(share[letter] - probability) < 0.1, (letter, share)


# --- lanes join at every node ----------------------------------------------------------------------
def _ends(desc):
    """Per row: start point, end point, start heading, end heading."""
    lanes = [desc.lane(row) for row in range(desc.lane_count)]
    start = np.array([lane.position(0.0, 0.0) for lane in lanes])
    end = np.array([lane.position(lane.length, 0.0) for lane in lanes])
    start_heading = np.array([lane.heading_at(0.0) for lane in lanes])
    end_heading = np.array([lane.heading_at(lane.length) for lane in lanes])
    return start, end, start_heading, end_heading


def _angle(a, b):
    return np.abs((a - b + np.pi) % (2 * np.pi) - np.pi)


@pytest.mark.parametrize("pg", MAPS, ids=lambda m: f"{m.letters}-{m.seed}-{m.lane_count}")
def test_lanes_are_continuous_and_tangent_at_every_node(pg):
    """Every lane into a node that roads leave meets one of their lanes at its start, in position
    and heading, and every lane leaving a node that roads enter starts where one of those ends."""
    desc = pg.description
    start, end, start_heading, end_heading = _ends(desc)
    checked = 0
    for n in range(len(desc.nodes)):
        into, out = np.flatnonzero(desc.lane_to == n), np.flatnonzero(desc.lane_from == n)
        if len(into) == 0 or len(out) == 0:
            continue  # the map's ends, a ramp's dead end
        gap = np.linalg.norm(end[into, None] - start[None, out], axis=-1)
        kink = _angle(end_heading[into, None], start_heading[None, out])
        joined = (gap < POSITION_TOL_M) & (kink < HEADING_TOL_RAD)
        assert joined.any(axis=1).all(), (desc.nodes[n], gap.min(axis=1))
        assert joined.any(axis=0).all(), (desc.nodes[n], gap.min(axis=0))
        checked += 1
    assert checked >= 2 * len(pg.blocks)  # at least both directions at every socket


@pytest.mark.parametrize("pg", MAPS[:4], ids=lambda m: f"{m.letters}-{m.seed}")
def test_lane_k_goes_on_as_lane_k_at_every_socket(pg):
    """At each block's entry socket the previous block's lane k meets the new block's lane k, both
    ways, at the socket's pose."""
    desc = pg.description
    start, end, start_heading, end_heading = _ends(desc)
    for block in pg.blocks[1:]:
        socket = block.entry
        for arrive in (socket.node, "-" + socket.node):
            node = desc.nodes.index(arrive)
            into, out = np.flatnonzero(desc.lane_to == node), np.flatnonzero(desc.lane_from == node)
            assert len(into) >= socket.lane_count and len(out) >= socket.lane_count
            for row in into:
                same = out[desc.lane_id[out] == desc.lane_id[row]]
                assert len(same) >= 1
                assert np.abs(end[row] - start[same]).max() < POSITION_TOL_M
                assert _angle(end_heading[row], start_heading[same]).max() < HEADING_TOL_RAD
        forward = np.flatnonzero(desc.lane_to == desc.nodes.index(socket.node))
        k = desc.lane_id[forward]
        expected = np.array(socket.position) + np.outer(
            (k + 0.5) * socket.lane_width, [-np.sin(socket.heading), np.cos(socket.heading)]
        )
        assert np.abs(end[forward] - expected).max() < POSITION_TOL_M


# --- footprints never overlap (independent of the generator's probes) ------------------------------
def _lane_points(rows, spacing_m=2.0):
    """(P, 2) points on every lane row of a LaneTable: centre line and both edges, at most
    ``spacing_m`` apart, with the row of each (P,); highway-env's position formulas."""
    count = np.maximum(np.ceil(rows[:, L.LENGTH] / spacing_m).astype(int), 1) + 1
    row = np.repeat(np.arange(len(rows)), count)
    first = np.repeat(np.cumsum(count) - count, count)
    s = (np.arange(len(row)) - first) / (count[row] - 1) * rows[row, L.LENGTH]
    points, owner = [], []
    for side in (-1.0, 0.0, 1.0):
        r = side * rows[row, L.WIDTH] / 2
        v = rows[row]
        phi = v[:, L.SENSE] * s / np.where(v[:, L.RADIUS] > 0, v[:, L.RADIUS], 1.0) + v[:, L.START_PHASE]
        radius = v[:, L.RADIUS] - r * v[:, L.SENSE]
        arc = np.column_stack(
            [v[:, L.CENTER_X] + radius * np.cos(phi), v[:, L.CENTER_Y] + radius * np.sin(phi)]
        )
        line = np.column_stack([
            v[:, L.START_X] + s * v[:, L.DIR_X] - r * v[:, L.DIR_Y],
            v[:, L.START_Y] + s * v[:, L.DIR_Y] + r * v[:, L.DIR_X],
        ])  # fmt: skip
        points.append(np.where((v[:, L.KIND] == L.CIRCLE)[:, None], arc, line))
        owner.append(row)
    return np.concatenate(points), np.concatenate(owner)


def _inside(rows, points, tol=1e-6):
    """(P,) whether each point lies strictly inside a lane row (tol inside its ends and edges);
    highway-env's local coordinates (``lanes.local_coordinates``), vectorised."""
    v = rows[None]
    d = points[:, None, :]
    dx, dy = d[..., 0] - v[..., L.START_X], d[..., 1] - v[..., L.START_Y]
    s_line, r_line = dx * v[..., L.DIR_X] + dy * v[..., L.DIR_Y], -dx * v[..., L.DIR_Y] + dy * v[..., L.DIR_X]
    cx, cy = d[..., 0] - v[..., L.CENTER_X], d[..., 1] - v[..., L.CENTER_Y]
    phi = np.arctan2(cy, cx)
    phi = v[..., L.START_PHASE] + ((phi - v[..., L.START_PHASE] + np.pi) % (2 * np.pi) - np.pi)
    s_arc = v[..., L.SENSE] * (phi - v[..., L.START_PHASE]) * v[..., L.RADIUS]
    r_arc = v[..., L.SENSE] * (v[..., L.RADIUS] - np.hypot(cx, cy))
    arc = v[..., L.KIND] == L.CIRCLE
    s, r = np.where(arc, s_arc, s_line), np.where(arc, r_arc, r_line)
    return ((s > tol) & (s < v[..., L.LENGTH] - tol) & (np.abs(r) < v[..., L.WIDTH] / 2 - tol)).any(axis=1)


def overlapping_blocks(pg) -> list[tuple[int, int]]:
    """(a, b) pairs of blocks where a point of b's lanes lies inside a lane of a."""
    rows = LaneTable.from_description(pg.description).rows
    points, owner = _lane_points(rows)
    block_of_point = pg.lane_block[owner]
    found = []
    boxes = {}
    for b in range(len(pg.blocks)):
        mine = points[block_of_point == b]
        boxes[b] = (mine.min(axis=0), mine.max(axis=0))
    for a in range(len(pg.blocks)):
        lanes_a = rows[pg.lane_block == a]
        for b in range(len(pg.blocks)):
            low_a, high_a = boxes[a]
            if a == b or np.any(boxes[b][1] < low_a) or np.any(boxes[b][0] > high_a):
                continue
            mine = points[block_of_point == b]
            mine = mine[np.all((mine >= low_a) & (mine <= high_a), axis=1)]
            if len(mine) and _inside(lanes_a, mine).any():
                found.append((a, b))
    return found


def test_500_random_maps_have_no_overlapping_footprints_and_a_route():
    """Seeds 0-499 with 3 to 7 blocks: no block's lanes enter another's, and the route runs
    road to road from the spawn road to the end of a socket road of the last block."""
    for seed in range(500):
        pg = generate_map(3 + seed % 5, seed)
        assert len(pg.blocks) == 4 + seed % 5
        assert overlapping_blocks(pg) == [], (seed, pg.letters)
        assert pg.route[0] == pg.spawn_road and pg.route[-1] == pg.destination_road
        assert all(a[1] == b[0] for a, b in zip(pg.route[:-1], pg.route[1:], strict=True))
        assert all(b in pg.description.graph[a] for a, b in pg.route)
        assert pg.destination_road[1] in {socket.node for socket in pg.blocks[-1].sockets}


def test_the_overlap_check_finds_crossing_blocks_when_the_probes_are_off(monkeypatch):
    """Without the generator's footprint test, chains of curves cross themselves (so the check
    above can fail), and the generator's probes reject a road laid across another."""
    monkeypatch.setattr(pg_map, "overlaps", lambda *args: False)
    crossing = [seed for seed in range(20) if overlapping_blocks(generate_map("CCCCCCC", seed, lane_count=3))]
    assert len(crossing) >= 3
    monkeypatch.undo()
    assert all(not overlapping_blocks(generate_map("CCCCCCC", seed, lane_count=3)) for seed in crossing)
    first = first_block(2, 3.5, 20.0)
    across = straight_block(
        BlockSite(1, Socket((25.0, -30.0), np.pi / 2, 2, 3.5, "a"), 20.0), {"length": 60.0}
    )
    away = straight_block(BlockSite(1, Socket((25.0, 30.0), np.pi / 2, 2, 3.5, "a"), 20.0), {"length": 60.0})
    assert overlaps(across, [Footprint.of(first)]) and not overlaps(away, [Footprint.of(first)])


# --- the same seed, the same map ---------------------------------------------------------------------
def _arrays(desc):
    return {name: value for name, value in vars(desc).items() if isinstance(value, np.ndarray)}


@pytest.mark.parametrize("spec", ["OSX", 5, EVERY_BLOCK])
def test_the_same_seed_gives_the_same_map(spec):
    for seed in (0, 7):
        one, two = generate_map(spec, seed, lane_width_m=None), generate_map(spec, seed, lane_width_m=None)
        assert one.description.nodes == two.description.nodes and one.route == two.route
        for name, value in _arrays(one.description).items():
            assert np.array_equal(value, getattr(two.description, name), equal_nan=True), name
        assert np.array_equal(one.lane_block, two.lane_block)
    other = generate_map(spec, 1, lane_width_m=None)
    assert other.description.lane_count != one.description.lane_count or not np.array_equal(
        other.description.start, one.description.start, equal_nan=True
    )


# --- what the simulators read -------------------------------------------------------------------------
@pytest.mark.parametrize("pg", MAPS[:6], ids=lambda m: f"{m.letters}-{m.seed}")
def test_descriptions_convert_for_both_simulators(pg):
    table = LaneTable.from_description(pg.description)
    network = to_road_network(pg.description)
    assert np.array_equal(table.rows, LaneTable.from_network(network).rows)
    assert table.indices == pg.description.indices
    arcs = table.rows[:, L.KIND] == L.CIRCLE
    assert np.all(table.rows[:, L.LENGTH] > 1.0) and np.all(table.rows[arcs, L.RADIUS] > 1.0)
    route = [network.get_lane((a, b, 0)) for a, b in pg.route]
    assert len(route) == len(pg.route)


def test_junctions_turn_as_their_arms_say_and_carry_lights_when_signalised():
    pg = generate_map("XT", 3, lane_count=2, signalised=True)
    desc = pg.description
    t_arms = pg.blocks[2].junction.arms
    assert desc.junction_count == 2 and desc.junction_arms == ((0, 1, 2, 3), t_arms) and len(t_arms) == 3
    assert desc.junction_signalised.all() and len(desc.light_arm) == 7
    start, end, start_heading, end_heading = _ends(desc)
    change = {TURN_RIGHT: np.pi / 2, TURN_LEFT: -np.pi / 2, TURN_STRAIGHT: 0.0}
    arm_step = {TURN_RIGHT: 3, TURN_LEFT: 1, TURN_STRAIGHT: 2}
    inside = np.flatnonzero(desc.junction >= 0)
    assert len(inside) == 2 * (12 + 6)  # 2 lanes on each of X's 12 and T's 6 connections
    for row in inside:
        assert (desc.to_arm[row] - desc.from_arm[row]) % 4 == arm_step[desc.turn[row]]
        assert _angle(end_heading[row] - start_heading[row], change[desc.turn[row]]) < HEADING_TOL_RAD
    for j, arms in enumerate(desc.junction_arms):  # every arm has its approach lanes and a light
        approaches = desc.end_arm[desc.end_junction == j]
        assert sorted(set(approaches)) == sorted(arms) and np.bincount(approaches).max() == 2
        lit = desc.light[desc.end_junction == j]
        assert np.all(lit >= 0) and np.array_equal(desc.light_arm[lit], approaches)
    assert len(generate_map("XT", 3, lane_count=2).description.light_arm) == 0


def test_merge_and_split_change_the_lane_count_and_osx_has_its_lanes():
    assert generate_map("y", 0, lane_count=3).blocks[1].sockets[0].lane_count in (1, 2)
    assert generate_map("Y", 0, lane_count=2).blocks[1].sockets[0].lane_count in (3, 4)
    osx = generate_map("OSX", 0, lane_count=3)
    # I: 2 roads; O: 4 entry + 4 exit curves, 8 ring parts, 3 arms; S: 1; X: 12 turns, 3 arms;
    # each two-way road counts twice, 3 lanes each
    assert osx.description.lane_count == 3 * (2 * 2 + 8 + 8 + 2 * 3 + 2 + 12 + 2 * 3)
