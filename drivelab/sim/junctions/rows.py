"""Row layouts of the town's compiled state, shared by its set-up, its kernels and the simulator.

Pedestrians live in their own ``(P, PEDESTRIAN_COLUMNS)`` array per world, in spawn order (that of
highway-env's ``TownRoad.pedestrians``):

- X, Y, HEADING, SPEED: pose and speed (0 while waiting on the pavement);
- SIDE: -1 or +1, the pavement it stands on or walks from (along the crossing's walking heading);
- PACE: its walking speed, drawn at spawn; WAIT_S: seconds left on the pavement;
- CRASHED: 1 once hit; HIT_EGO: 1 when the ego hit it (highway-env's ``hit_by is ego``);
- CENTRE_X, CENTRE_Y: its crossing's centre; ACROSS_X, ACROSS_Y: the unit walking direction;
  CROSSING: the crossing's row in the road's crossing table.
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
