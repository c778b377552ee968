"""Two-way roads, lane-count tapers and the parameter spaces the procedural blocks are made of.

A procedural map (``pg_map``) is a chain of blocks (``pg_blocks``, ``pg_junctions``), MetaDrive's
way (``metadrive/component/pgblock/``): each block starts at a ``Socket`` of the block before it
and ends at sockets of its own. Lanes are laid with ``blocks.Straight`` and ``blocks.Arc`` in
highway-env's geometry (heading grows turning right, lateral offsets grow to the right, lane 0 is
the leftmost). A road's reference line is its centre line: forward lane k lies (k + ½)·w to its
right, the reverse road's lane k (k + ½)·w to its left; the reverse of road (a, b) runs from node
``-b`` to node ``-a``, as MetaDrive names its reverse roads.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from drivelab.sim.roads.blocks import Arc, Straight, road_lines
from drivelab.sim.roads.description import LINE_CONTINUOUS, LINE_NONE, LINE_STRIPED, LaneRecord

Segment = Straight | Arc


class BlockFailed(Exception):
    """A block cannot be built with the drawn parameters (the generator retries, as MetaDrive's
    BIG does when a block fails)."""


# --- parameter spaces (MetaDrive's ``component/pg_space.py``: Box, Discrete, Constant) ----------
@dataclass(frozen=True)
class Box:
    """A float drawn uniformly from [low, high]."""

    low: float
    high: float

    def sample(self, rng: np.random.Generator) -> float:
        return float(rng.uniform(self.low, self.high))


@dataclass(frozen=True)
class Discrete:
    """An int drawn uniformly from {low, …, high} (both included)."""

    low: int
    high: int

    def sample(self, rng: np.random.Generator) -> int:
        return int(rng.integers(self.low, self.high + 1))


def sample_parameters(space: dict[str, Box | Discrete], rng: np.random.Generator) -> dict:
    """One draw of every parameter of ``space``, in its order."""
    return {name: value.sample(rng) for name, value in space.items()}


# --- poses and sockets --------------------------------------------------------------------------
@dataclass(frozen=True)
class Socket:
    """Where a block's outgoing road ends and the next block may start.

    :param position: (2,) the road's centre line at its end.
    :param heading: direction of forward travel (rad; highway-env's, growing to the right).
    :param lane_count: / ``lane_width``: lanes per direction and their width (m).
    :param node: the end node of the outgoing forward road; the next block's first road starts
        there, and its reverse road ends at ``reverse_node(node)``.
    """

    position: tuple[float, float]
    heading: float
    lane_count: int
    lane_width: float
    node: str


def reverse_node(node: str) -> str:
    """The node of the reverse road at ``node`` (MetaDrive's ``-`` prefix)."""
    return node[1:] if node.startswith("-") else "-" + node


def right_normal(heading: float) -> np.ndarray:
    """(2,) the unit vector to the right of ``heading`` (highway-env's lateral axis)."""
    return np.array([-np.sin(heading), np.cos(heading)])


def lane_offset(k: int, width: float) -> float:
    """Offset of lane ``k`` to the right of its road's centre line."""
    return (k + 0.5) * width


def reversed_segment(segment: Segment) -> Segment:
    """The segment that runs ``segment``'s reference line backwards."""
    if isinstance(segment, Arc):
        return Arc(segment.radius_m, -segment.turn_deg)
    return segment


def end_pose(segment: Segment, position: np.ndarray, heading: float) -> tuple[np.ndarray, float]:
    """Position (2,) and heading of ``segment``'s reference line at its end."""
    reference = segment.lane(position, heading, 0.0, start_node="", end_node="")
    return reference.position(reference.length, 0.0), float(reference.heading_at(reference.length))


def lay_lanes(
    out: list[LaneRecord], segment: Segment, position: np.ndarray, heading: float, count: int, width: float,
    start: str, end: str, speed_limit: float, lines=road_lines, **lane,
) -> None:  # fmt: skip
    """Append ``count`` forward lanes of ``segment`` from the pose (one road ``start`` → ``end``);
    ``lines(k, count)``: lane k's markings."""
    for k in range(count):
        out.append(
            segment.lane(
                position, heading, lane_offset(k, width), start_node=start, end_node=end, width=width,
                lines=lines(k, count), speed_limit=speed_limit, **lane,
            )
        )  # fmt: skip


def lay_road(
    out: list[LaneRecord], segment: Segment, position: np.ndarray, heading: float, count: int, width: float,
    start: str, end: str, speed_limit: float, reverse: dict | None = None, reverse_count: int | None = None,
) -> tuple[np.ndarray, float]:  # fmt: skip
    """A two-way road along ``segment`` from the pose: ``count`` lanes forward (``start`` → ``end``)
    and ``reverse_count`` (default ``count``) back (``-end`` → ``-start``); ``reverse``: extra
    LaneRecord fields of the reverse lanes. Returns the end pose of the centre line."""
    lay_lanes(out, segment, position, heading, count, width, start, end, speed_limit)
    end_position, end_heading = end_pose(segment, position, heading)
    lay_lanes(
        out, reversed_segment(segment), end_position, end_heading + np.pi,
        count if reverse_count is None else reverse_count, width, reverse_node(end), reverse_node(start),
        speed_limit, **(reverse or {}),
    )  # fmt: skip
    return end_position, end_heading


# --- lane-count tapers (MetaDrive's bottleneck lanes, ``pgblock/bottleneck.py``) -----------------
def s_curve(shift_m: float, length_m: float) -> tuple[float, float]:
    """(radius m, angle deg) of each of the two opposite arcs that move a lane ``shift_m``
    sideways over ``length_m``: 2ρ·sin φ = L and 2ρ·(1 − cos φ) = d, so tan(φ/2) = d / L."""
    angle = 2.0 * np.arctan(shift_m / length_m)
    return length_m / (2.0 * np.sin(angle)), float(np.degrees(angle))


def lay_taper(
    out: list[LaneRecord], position: np.ndarray, heading: float, from_count: int, to_count: int, width: float,
    length_m: float, nodes: tuple[str, str, str], speed_limit: float,
) -> tuple[np.ndarray, float]:  # fmt: skip
    """One direction of a road whose lane count goes from ``from_count`` to ``to_count`` over
    ``length_m``, as two roads (``nodes[0]`` → ``nodes[1]`` → ``nodes[2]``) of half the length.

    The lanes both counts have run straight; each other lane k (counted from the left) bends in
    an S of two opposite arcs between its own place and that of the last shared lane: a dropped
    lane (merge) ends on it, a new lane (split) starts on it. Returns the end pose."""
    shared, widest = min(from_count, to_count), max(from_count, to_count)
    half = length_m / 2.0
    normal = right_normal(heading)
    direction = 1.0 if to_count > from_count else -1.0  # a split moves right, a merge left
    for part, (start, end) in enumerate(zip(nodes[:-1], nodes[1:], strict=True)):
        for k in range(widest):
            lines = road_lines(k, widest)
            if k >= shared:
                lines = (LINE_STRIPED, LINE_CONTINUOUS if k == widest - 1 else LINE_NONE)
            common = dict(start_node=start, end_node=end, width=width, lines=lines, speed_limit=speed_limit)
            if k < shared:
                start_point = position + half * part * np.array([np.cos(heading), np.sin(heading)])
                out.append(Straight(half).lane(start_point, heading, lane_offset(k, width), **common))
                continue
            shift = (k - shared + 1) * width
            radius, angle = s_curve(shift, length_m)
            first = Arc(radius, direction * angle)
            first_offset = lane_offset(k if direction < 0 else shared - 1, width)
            lane_start = position + first_offset * normal
            if part == 0:
                out.append(first.lane(lane_start, heading, 0.0, **common))
            else:
                middle, middle_heading = end_pose(first, lane_start, heading)
                out.append(Arc(radius, -direction * angle).lane(middle, middle_heading, 0.0, **common))
    return position + length_m * np.array([np.cos(heading), np.sin(heading)]), heading
