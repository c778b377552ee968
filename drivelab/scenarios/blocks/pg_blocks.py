"""The road blocks of procedural maps, with MetaDrive's letters and parameter ranges: the spawn
road ``I``, straight ``S``, curve ``C``, in-ramp ``r``, out-ramp ``R``, merge ``y`` and split
``Y`` (the junctions ``X``, ``T`` and the roundabout ``O`` are in ``pg_junctions``).

The ranges are MetaDrive's (``metadrive/component/pg_space.py``; the fixed ramp and bottleneck
lengths from ``pgblock/ramp.py`` and ``pgblock/bottleneck.py``); the geometry is drivelab's own,
built from straight and circular lanes (see ``pg_roads``). Node names follow MetaDrive's
``<block index><letter><part>_<road>_`` (``pgblock/pg_block.py``); the spawn road is
(``>``, ``>>``) as in ``pgblock/first_block.py``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from drivelab.scenarios.blocks.pg_roads import (
    BlockFailed,
    Box,
    Discrete,
    Socket,
    end_pose,
    lane_offset,
    lay_road,
    lay_taper,
    reverse_node,
    right_normal,
)
from drivelab.sim.roads.blocks import Arc, Straight
from drivelab.sim.roads.description import LINE_CONTINUOUS, LaneRecord

# first block (``pgblock/first_block.py``): a 10 m spawn road, then exit_length − 10 m
SPAWN_ROAD_M, FIRST_EXIT_M = 10.0, 40.0
# ramps (``pgblock/ramp.py``): the ramp bends 10° on 40 m arcs around a 20 m connector
RAMP_RADIUS_M, RAMP_ANGLE_DEG, RAMP_CONNECTOR_M, RAMP_STRAIGHT_M = 40.0, 10.0, 20.0, 15.0
IN_RAMP_EXTRA_M, OUT_RAMP_EXTRA_M, SOCKET_ROAD_M = 10.0, 15.0, 20.0
RAMP_SPEED_LIMIT_MPS = 12.0
BOTTLENECK_M = 20.0  # a lane-count taper's length (``pgblock/bottleneck.py``)
MAX_LANES = 5  # BIG rejects a block whose sockets have more (or fewer than 1) lanes

SPACES: dict[str, dict[str, Box | Discrete]] = {
    "I": {},
    "S": {"length": Box(40.0, 80.0)},
    "C": {
        "length": Box(40.0, 80.0),
        "radius": Box(25.0, 60.0),
        "angle": Box(45.0, 135.0),
        "dir": Discrete(0, 1),
    },
    "r": {"length": Box(20.0, 40.0), "extension_length": Box(20.0, 40.0)},
    "R": {"length": Box(20.0, 40.0), "extension_length": Box(20.0, 40.0)},
    "y": {"length": Box(20.0, 50.0), "lane_num": Discrete(1, 2)},
    "Y": {"length": Box(20.0, 50.0), "lane_num": Discrete(1, 2)},
}


@dataclass(frozen=True)
class JunctionLayout:
    """A junction block's metadata, in the town's terms (``blocks.Junction``).

    :param centre: (2,) the junction's centre.
    :param arms: the arms present, in laying order. Arm 0 is the one the block is entered from;
        arm k − 1 is a right turn from arm k, k + 1 a left turn, k + 2 straight on (the town's
        arms, turned to the block's heading).
    :param entry_node: the node the previous block's road enters arm 0 at (its stop line).
    :param stop_lines: (len(arms), 3) per arm the middle of its incoming lanes at the stop line
        and their heading: where its light stands.
    """

    centre: tuple[float, float]
    arms: tuple[int, ...]
    signalised: bool
    entry_node: str
    stop_lines: np.ndarray


@dataclass(frozen=True, eq=False)
class Block:
    """One built block.

    :param index: position in the map (0: the spawn road ``I``).
    :param letter: MetaDrive's block ID.
    :param parameters: the drawn parameters (MetaDrive's names).
    :param entry: the socket it was built on (I: the origin, node ``>``).
    :param sockets: where the next block may start (X: right, straight, left exits).
    :param lanes: its lanes (forward and reverse roads; ramps are one-way).
    :param junction: X and T: the junction's layout; else None.
    """

    index: int
    letter: str
    parameters: dict
    entry: Socket
    sockets: tuple[Socket, ...]
    lanes: tuple[LaneRecord, ...]
    junction: JunctionLayout | None = None


@dataclass(frozen=True)
class BlockSite:
    """What a block builder is given: its ``index``, the ``entry`` socket it starts at, the lanes'
    speed limit, the junction number it gets if it is one, and whether junctions have lights."""

    index: int
    entry: Socket
    speed_limit_mps: float
    junction_index: int = 0
    signalised: bool = False


def node(site: BlockSite, letter: str, part: int, road: int) -> str:
    """MetaDrive's node name ``<index><letter><part>_<road>_``."""
    return f"{site.index}{letter}{part}_{road}_"


def _start(site: BlockSite) -> tuple[np.ndarray, float, int, float]:
    entry = site.entry
    return np.array(entry.position, dtype=float), entry.heading, entry.lane_count, entry.lane_width


def _socket(position: np.ndarray, heading: float, count: int, width: float, name: str) -> Socket:
    return Socket((float(position[0]), float(position[1])), float(heading), count, width, name)


def _one_socket(site, letter, parameters, lanes, position, heading, count, end) -> Block:
    """A block with one socket, at the pose where its last road (to node ``end``) ends."""
    socket = _socket(position, heading, count, site.entry.lane_width, end)
    return Block(site.index, letter, parameters, site.entry, (socket,), tuple(lanes))


def first_block(lane_count: int, lane_width: float, speed_limit_mps: float) -> Block:
    """``I``: from the origin along +x, the 10 m spawn road (``>`` → ``>>``) then 40 m."""
    entry = Socket((0.0, 0.0), 0.0, lane_count, lane_width, ">")
    lanes: list[LaneRecord] = []
    position, heading = np.zeros(2), 0.0
    for start, end, length in ((">", ">>", SPAWN_ROAD_M), (">>", ">>>", FIRST_EXIT_M)):
        position, heading = lay_road(
            lanes, Straight(length), position, heading, lane_count, lane_width, start, end, speed_limit_mps
        )
    socket = _socket(position, heading, lane_count, lane_width, ">>>")
    return Block(0, "I", {}, entry, (socket,), tuple(lanes))


def straight_block(site: BlockSite, parameters: dict) -> Block:
    """``S``: a straight road ``length`` long."""
    position, heading, count, width = _start(site)
    lanes: list[LaneRecord] = []
    end = node(site, "S", 0, 0)
    position, heading = lay_road(
        lanes, Straight(parameters["length"]), position, heading, count, width, site.entry.node, end,
        site.speed_limit_mps,
    )  # fmt: skip
    return _one_socket(site, "S", parameters, lanes, position, heading, count, end)


def curve_block(site: BlockSite, parameters: dict) -> Block:
    """``C``: an arc of ``angle`` degrees (``dir`` 1: to the right) and ``radius`` at the road's
    centre line, then a straight ``length`` long. MetaDrive measures the radius at the rightmost
    lane; at the centre line every lane of both directions keeps a positive radius (≥ 4.75 m
    with 5 lanes of 4.5 m)."""
    position, heading, count, width = _start(site)
    turn = parameters["angle"] if parameters["dir"] == 1 else -parameters["angle"]
    lanes: list[LaneRecord] = []
    middle, end = node(site, "C", 0, 0), node(site, "C", 0, 1)
    position, heading = lay_road(
        lanes, Arc(parameters["radius"], turn), position, heading, count, width, site.entry.node, middle,
        site.speed_limit_mps,
    )  # fmt: skip
    position, heading = lay_road(
        lanes, Straight(parameters["length"]), position, heading, count, width, middle, end,
        site.speed_limit_mps,
    )  # fmt: skip
    return _one_socket(site, "C", parameters, lanes, position, heading, count, end)


def _ramp_chain(out: list[LaneRecord], segments, position, heading, nodes, width: float) -> None:
    """A one-lane, one-way ramp along ``segments`` through ``nodes`` (one more than segments)."""
    for segment, start, end in zip(segments, nodes[:-1], nodes[1:], strict=True):
        out.append(
            segment.lane(
                position, heading, 0.0, start_node=start, end_node=end, width=width,
                lines=(LINE_CONTINUOUS, LINE_CONTINUOUS), speed_limit=RAMP_SPEED_LIMIT_MPS,
            )
        )  # fmt: skip
        position, heading = end_pose(segment, position, heading)


def _run(segments) -> np.ndarray:
    """(2,) the displacement of a chain of segments starting at the origin heading +x."""
    position, heading = np.zeros(2), 0.0
    for segment in segments:
        position, heading = end_pose(segment, position, heading)
    return position


def _two_way_taper(out, position, heading, forward, backward, width, nodes, speed):
    """A taper section (``lay_taper``) from ``forward[0]`` to ``forward[1]`` lanes through
    ``nodes``, and its reverse road from ``backward[0]`` to ``backward[1]`` lanes."""
    end_position, end_heading = lay_taper(out, position, heading, *forward, width, BOTTLENECK_M, nodes, speed)
    reverse = tuple(reverse_node(n) for n in nodes[::-1])
    lay_taper(out, end_position, end_heading + np.pi, *backward, width, BOTTLENECK_M, reverse, speed)
    return end_position, end_heading


def in_ramp_block(site: BlockSite, parameters: dict) -> Block:
    """``r``: a main road with a one-lane ramp joining from the right onto an acceleration lane
    (``extension_length``), which then merges. The ramp (15 + 10 m straight, a 10° left bend, a
    20 m connector, a 10° right bend) runs beside the first straight, which is ``length`` plus
    the ramp's run long."""
    position, heading, count, width = _start(site)
    speed, lanes = site.speed_limit_mps, []
    ramp = [
        Straight(RAMP_STRAIGHT_M + IN_RAMP_EXTRA_M), Arc(RAMP_RADIUS_M, -RAMP_ANGLE_DEG),
        Straight(RAMP_CONNECTOR_M), Arc(RAMP_RADIUS_M, RAMP_ANGLE_DEG),
    ]  # fmt: skip
    run = _run(ramp)
    names = [site.entry.node] + [node(site, "r", 0, k) for k in range(5)]
    position, heading = lay_road(
        lanes, Straight(parameters["length"] + run[0]), position, heading, count, width, names[0], names[1],
        speed,
    )  # fmt: skip
    # the ramp ends where the acceleration lane (lane ``count`` of the next road) starts
    join = position + lane_offset(count, width) * right_normal(heading)
    rotation = np.array([[np.cos(heading), -np.sin(heading)], [np.sin(heading), np.cos(heading)]])
    ramp_nodes = [node(site, "r", 1, k) for k in range(len(ramp))] + [names[1]]
    _ramp_chain(lanes, ramp, join - rotation @ run, heading, ramp_nodes, width)
    extension = Straight(parameters["extension_length"])
    position, heading = lay_road(
        lanes, extension, position, heading, count + 1, width, names[1], names[2], speed, reverse_count=count
    )
    # the acceleration lane merges, then a socket road
    position, heading = _two_way_taper(
        lanes, position, heading, (count + 1, count), (count, count), width, tuple(names[2:5]), speed
    )
    socket_road = Straight(SOCKET_ROAD_M)
    position, heading = lay_road(lanes, socket_road, position, heading, count, width, *names[4:6], speed)
    return _one_socket(site, "r", parameters, lanes, position, heading, count, names[5])


def out_ramp_block(site: BlockSite, parameters: dict) -> Block:
    """``R``: a main road (``length``) that gains a deceleration lane on the right (a split, then
    ``extension_length``), which leaves as a one-lane ramp to a dead end (a 10° right bend, a 20 m
    connector, a 10° left bend, 15 + 15 m straight); the main road goes on beside the ramp."""
    position, heading, count, width = _start(site)
    speed, lanes = site.speed_limit_mps, []
    ramp = [
        Arc(RAMP_RADIUS_M, RAMP_ANGLE_DEG), Straight(RAMP_CONNECTOR_M), Arc(RAMP_RADIUS_M, -RAMP_ANGLE_DEG),
        Straight(RAMP_STRAIGHT_M + OUT_RAMP_EXTRA_M),
    ]  # fmt: skip
    names = [site.entry.node] + [node(site, "R", 0, k) for k in range(5)]
    position, heading = lay_road(
        lanes, Straight(parameters["length"]), position, heading, count, width, names[0], names[1], speed
    )
    # the deceleration lane opens (a split in this direction; the other direction keeps its lanes)
    position, heading = _two_way_taper(
        lanes, position, heading, (count, count + 1), (count, count), width, tuple(names[1:4]), speed
    )
    extension = Straight(parameters["extension_length"])
    position, heading = lay_road(
        lanes, extension, position, heading, count + 1, width, names[3], names[4], speed, reverse_count=count
    )
    leave = position + lane_offset(count, width) * right_normal(heading)
    ramp_nodes = [names[4]] + [node(site, "R", 1, k) for k in range(len(ramp))]
    _ramp_chain(lanes, ramp, leave, heading, ramp_nodes, width)
    main = Straight(_run(ramp)[0] + SOCKET_ROAD_M)
    position, heading = lay_road(lanes, main, position, heading, count, width, names[4], names[5], speed)
    return _one_socket(site, "R", parameters, lanes, position, heading, count, names[5])


def _lane_change_block(site: BlockSite, parameters: dict, letter: str, change: int) -> Block:
    position, heading, count, width = _start(site)
    new_count = count + change
    if not 1 <= new_count <= MAX_LANES:
        raise BlockFailed(f"{letter}: {count} lanes cannot become {new_count}")
    speed, lanes = site.speed_limit_mps, []
    names = [site.entry.node] + [node(site, letter, 0, k) for k in range(4)]
    straight = Straight(parameters["length"])
    position, heading = lay_road(lanes, straight, position, heading, count, width, names[0], names[1], speed)
    position, heading = _two_way_taper(
        lanes, position, heading, (count, new_count), (new_count, count), width, tuple(names[1:4]), speed
    )
    position, heading = lay_road(lanes, straight, position, heading, new_count, width, *names[3:5], speed)
    return _one_socket(site, letter, parameters, lanes, position, heading, new_count, names[4])


def merge_block(site: BlockSite, parameters: dict) -> Block:
    """``y``: ``length`` of road, a 20 m taper that drops ``lane_num`` lanes on the right (each
    direction: the other direction gains them), then ``length`` of the narrower road."""
    return _lane_change_block(site, parameters, "y", -parameters["lane_num"])


def split_block(site: BlockSite, parameters: dict) -> Block:
    """``Y``: as ``y``, but the lane count rises by ``lane_num``."""
    return _lane_change_block(site, parameters, "Y", parameters["lane_num"])
