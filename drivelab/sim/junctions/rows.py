"""Row layouts of the town's compiled state, shared by its set-up (``scenarios/town/``),
its kernels and the simulator.

Pedestrians live in their own ``(P, PEDESTRIAN_COLUMNS)`` array per world, in spawn order (the
order highway-env's ``TownRoad.pedestrians`` and ``road.objects`` hold them):

- X, Y, HEADING, SPEED: pose and speed (0 while waiting on the pavement);
- SIDE: -1 or +1, the pavement it stands on or walks from (along the crossing's walking heading);
- PACE: its walking speed, drawn at spawn; WAIT_S: seconds left on the pavement;
- CRASHED: 1 once hit; HIT_EGO: 1 when the ego hit it (highway-env's ``hit_by is ego``);
- CENTRE_X, CENTRE_Y: its crossing's centre; ACROSS_X, ACROSS_Y: the unit walking direction
  (cos, sin of the crossing's heading); CROSSING: the crossing's row in the road's crossing table.

Lane metadata (one entry per lane row, arrays of the road description): junction index or -1,
from/to arm, turn (TURN_* or -1 for a street), the approach at a street's end, light row or -1.
"""

from __future__ import annotations

(
    P_X, P_Y, P_HEADING, P_SPEED, P_SIDE, P_PACE, P_WAIT_S, P_CRASHED, P_HIT_EGO,
    P_CENTRE_X, P_CENTRE_Y, P_ACROSS_X, P_ACROSS_Y, P_CROSSING,
) = range(14)  # fmt: skip
PEDESTRIAN_COLUMNS = 14

TURN_RIGHT, TURN_STRAIGHT, TURN_LEFT = 0, 1, 2  # a junction lane's turn; -1 on a street
# the lane metadata's (L,) int64 arrays, in the kernels' argument order
LANE_METADATA = ("junction", "from_arm", "to_arm", "turn", "end_junction", "end_arm", "light")
