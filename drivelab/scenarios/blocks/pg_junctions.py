"""The junction blocks of procedural maps: 4-way intersection ``X``, T-intersection ``T`` and
roundabout ``O``, with MetaDrive's meaning (``metadrive/component/pgblock/std_intersection.py``,
``std_t_intersection.py``, ``roundabout.py``) and drivelab's own geometry.

Intersections: every arm is a two-way road of the entry's lane count (MetaDrive's
StdInterSection keeps it); lane k of one arm turns into lane k of another on concentric arcs
(right turns of radius E − offset, left turns E + offset around the junction's corners, E = 10 m
+ lanes × width from the centre to each stop line: MetaDrive's fixed radius 10) or runs straight
on. Exits are 35 m arms; the block's sockets are their ends: right, straight, left (MetaDrive's
Goal 0, 1, 2). An intersection may be signalised: one light per arm at its stop line, arms 0/2
and 1/3 in phase (the town's lights, ``blocks.town``).

Roundabout: a one-way ring turning left (right-hand traffic) with its inner island at
``inner_radius``; each of 4 arms meets it with an entry and an exit curve tangent both to the
arm's lanes and to the ring (radius ``exit_radius`` + lanes × width at the arm's centre line, so
the outermost lane's edge turns at ``exit_radius``). The curve of lane k joins ring lane k.
"""

from __future__ import annotations

import numpy as np

from drivelab.scenarios.blocks.pg_blocks import Block, BlockSite, JunctionLayout, _socket, _start, node
from drivelab.scenarios.blocks.pg_roads import (
    BlockFailed,
    Box,
    Discrete,
    end_pose,
    lay_lanes,
    lay_road,
    reverse_node,
    right_normal,
)
from drivelab.sim.junctions.rows import TURN_LEFT, TURN_RIGHT, TURN_STRAIGHT
from drivelab.sim.roads.blocks import Arc, Straight, road_lines
from drivelab.sim.roads.description import LINE_NONE, LaneRecord

JUNCTION_RADIUS_M = 10.0  # MetaDrive's intersection radius (fixed in its parameter space)
EXIT_ROAD_M = 35.0  # the arms after a junction or roundabout (MetaDrive's EXIT_PART_LENGTH)
MIN_RING_ARC_DEG = 10.0  # a roundabout whose ring between two arms would be shorter fails
EXITS = (3, 2, 1)  # socket order: the right, straight and left arms

SPACES = {
    # MetaDrive's intersection space also draws change_lane_num and decrease_increase, which its
    # standard (default) intersection does not use
    "X": {},
    "T": {"t_type": Discrete(0, 2)},  # which of the right, straight and left exits is left out
    "O": {"exit_radius": Box(5.0, 15.0), "inner_radius": Box(15.0, 45.0)},
}

_TURNS = ((-1, TURN_RIGHT), (1, TURN_LEFT), (2, TURN_STRAIGHT))  # the town's laying order


def _direction(heading: float) -> np.ndarray:
    return np.array([np.cos(heading), np.sin(heading)])


def _no_lines(k: int, count: int) -> tuple[int, int]:
    return LINE_NONE, LINE_NONE


def _arm_nodes(site: BlockSite, letter: str, arm: int) -> tuple[str, str]:
    """(node where arm ``arm``'s incoming lanes end, node where its outgoing lanes start)."""
    if arm == 0:
        return site.entry.node, reverse_node(site.entry.node)
    leaving = node(site, letter, arm, 0)
    return reverse_node(leaving), leaving


def _intersection(site: BlockSite, parameters: dict, letter: str, exits: tuple[int, ...]) -> Block:
    """An intersection with arm 0 (the entry) and ``exits`` (in socket order)."""
    position, heading, count, width = _start(site)
    reach = JUNCTION_RADIUS_M + count * width  # centre to each stop line
    centre = position + reach * _direction(heading)
    arms = tuple(sorted((0, *exits)))
    speed, j = site.speed_limit_mps, site.junction_index
    lanes: list[LaneRecord] = []
    segments = {-1: Arc(reach, 90.0), 1: Arc(reach, -90.0), 2: Straight(2.0 * reach)}
    stop_lines = []
    for k in arms:
        in_heading = heading + k * np.pi / 2  # arm k's incoming lanes drive towards the centre
        stop = position if k == 0 else centre - reach * _direction(in_heading)
        stop_lines.append([*(stop + count * width / 2 * right_normal(in_heading)), in_heading])
        for step, turn in _TURNS:
            exit_arm = (k + step) % 4
            if exit_arm not in arms:
                continue
            lay_lanes(
                lanes, segments[step], stop, in_heading, count, width, _arm_nodes(site, letter, k)[0],
                _arm_nodes(site, letter, exit_arm)[1], speed, lines=_no_lines, junction=j, from_arm=k,
                to_arm=exit_arm, turn=turn,
            )  # fmt: skip
    sockets = []
    for arm in exits:
        out_heading = heading + np.pi + arm * np.pi / 2
        end = node(site, letter, arm, 1)
        end_position, end_heading = lay_road(
            lanes, Straight(EXIT_ROAD_M), centre + reach * _direction(out_heading), out_heading, count, width,
            _arm_nodes(site, letter, arm)[1], end, speed, reverse={"end_junction": j, "end_arm": arm},
        )  # fmt: skip
        sockets.append(_socket(end_position, end_heading, count, width, end))
    layout = JunctionLayout(
        (float(centre[0]), float(centre[1])), arms, site.signalised, site.entry.node, np.array(stop_lines)
    )
    return Block(site.index, letter, parameters, site.entry, tuple(sockets), tuple(lanes), layout)


def intersection_block(site: BlockSite, parameters: dict) -> Block:
    """``X``: a 4-way intersection; sockets at the right, straight and left exits."""
    return _intersection(site, parameters, "X", EXITS)


def t_intersection_block(site: BlockSite, parameters: dict) -> Block:
    """``T``: an intersection without the exit ``t_type`` (0 right, 1 straight, 2 left)."""
    exits = tuple(arm for k, arm in enumerate(EXITS) if k != parameters["t_type"])
    return _intersection(site, parameters, "T", exits)


def _open_ring_lines(k: int, count: int) -> tuple[int, int]:
    """A ring part where the arms' curves join: ``road_lines`` without the solid outer edge."""
    return road_lines(k, count)[0], LINE_NONE


def roundabout_block(site: BlockSite, parameters: dict) -> Block:
    """``O``: a roundabout with 4 arms; sockets at the right, straight and left exits.

    An arm's curve (radius ρ at its centre line) is tangent to the arm's centre line at distance
    t from the ring's centre and to the island's circle (radius R) from outside: |F| = ρ + R for
    its centre F, so t = √(R² + 2ρR); it meets the ring γ = asin(ρ / (ρ + R)) around from the arm
    and turns 90° − γ. Between two arms the ring turns 90° − 2γ (closed) and 2γ at each arm."""
    position, heading, count, width = _start(site)
    curve_radius = parameters["exit_radius"] + count * width
    island = parameters["inner_radius"]
    reach = np.sqrt(island**2 + 2.0 * curve_radius * island)
    gamma = np.degrees(np.arcsin(curve_radius / (curve_radius + island)))
    between = 90.0 - 2.0 * gamma
    if between < MIN_RING_ARC_DEG:
        raise BlockFailed(f"O: the ring between arms would turn {between:.1f}°")
    centre = position + reach * _direction(heading)
    speed, lanes = site.speed_limit_mps, []
    curve = Arc(curve_radius, 90.0 - gamma)

    def foot(arm: int) -> np.ndarray:  # where arm's centre line meets its curves
        return position if arm == 0 else centre - reach * _direction(heading + arm * np.pi / 2)

    entry_at = {arm: node(site, "O", arm, 2) for arm in range(4)}  # on the ring
    exit_at = {arm: node(site, "O", arm, 3) for arm in range(4)}
    for arm in range(4):
        lay_lanes(
            lanes, curve, foot(arm), heading + arm * np.pi / 2, count, width, _arm_nodes(site, "O", arm)[0],
            entry_at[arm], speed,
        )  # fmt: skip
    ring_position, ring_heading = end_pose(curve, position, heading)
    for arm in (0, 3, 2, 1):  # around the ring from arm 0's entry
        after = (arm - 1) % 4
        for segment, start, end, closed in (
            (Arc(island, -between), entry_at[arm], exit_at[after], True),
            (Arc(island, -2.0 * gamma), exit_at[after], entry_at[after], False),
        ):
            lay_lanes(
                lanes, segment, ring_position, ring_heading, count, width, start, end, speed,
                lines=road_lines if closed else _open_ring_lines,
            )  # fmt: skip
            if not closed:  # the exit curve leaves where this ring part starts
                lay_lanes(
                    lanes, curve, ring_position, ring_heading, count, width, start,
                    _arm_nodes(site, "O", after)[1], speed,
                )  # fmt: skip
            ring_position, ring_heading = end_pose(segment, ring_position, ring_heading)
    sockets = []
    for arm in EXITS:
        end = node(site, "O", arm, 1)
        end_position, end_heading = lay_road(
            lanes, Straight(EXIT_ROAD_M), foot(arm), heading + np.pi + arm * np.pi / 2, count, width,
            _arm_nodes(site, "O", arm)[1], end, speed,
        )  # fmt: skip
        sockets.append(_socket(end_position, end_heading, count, width, end))
    return Block(site.index, "O", parameters, site.entry, tuple(sockets), tuple(lanes))
