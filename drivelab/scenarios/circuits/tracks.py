"""The CARLA study's two circuits as tracks for ``blocks.circuit``, with the roads their tasks drive.

Tracks are (kind, length_m) straights and (kind, radius_m, turn_deg) arcs, starting at the origin
heading +x; a positive turn is to the right (heading grows, y points right). Both close exactly
(the closing straights were solved for by hand).
"""

from __future__ import annotations

FOLLOW_LINE_TRACK = (
    ("straight", 70.0), ("arc", 30.0, 90.0), ("straight", 20.0), ("arc", 30.0, 90.0),
    ("straight", 10.0), ("arc", 25.0, -90.0), ("straight", 10.0), ("arc", 25.0, 90.0),
    ("straight", 10.0), ("arc", 30.0, 90.0), ("straight", 80.0), ("arc", 30.0, 90.0),
)  # fmt: skip
FOLLOW_LANE_TRACK = tuple(
    (kind, *(value * 4.0 if index == 0 else value for index, value in enumerate(rest)))
    for kind, *rest in FOLLOW_LINE_TRACK
)  # the same shape four times larger: radii 100–120 m suit the seed's small lane steering angles

# the circuit environments' road config (highway-env config keys): one 7 m lane with a guide line,
# or three 3.5 m lanes
FOLLOW_LINE_ROAD = {"track": FOLLOW_LINE_TRACK, "lanes_count": 1, "lane_width": 7.0, "speed_limit": 20.0}
FOLLOW_LANE_ROAD = {"track": FOLLOW_LANE_TRACK, "lanes_count": 3, "lane_width": 3.5, "speed_limit": 20.0}
