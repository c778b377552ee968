"""The town's numbers and its light cycle, shared by the reference (``drivelab.scenarios.town.reference_env``)
and the compiled kernels: road geometry, speed limits, light timings, and the rules its vehicles
and pedestrians follow. Nothing here imports highway-env."""

from __future__ import annotations

from dataclasses import dataclass

from drivelab.world.state import LIGHT_GREEN, LIGHT_RED, LIGHT_YELLOW

# road geometry: highway-env's intersection (lane width 4 m, turn radii) at every junction
LANE_WIDTH_M = 4.0  # highway-env's AbstractLane.DEFAULT_WIDTH
RIGHT_TURN_RADIUS_M = LANE_WIDTH_M + 5
LEFT_TURN_RADIUS_M = RIGHT_TURN_RADIUS_M + LANE_WIDTH_M
OUTER_M = RIGHT_TURN_RADIUS_M + LANE_WIDTH_M / 2  # junction centre to stop line
SPEED_LIMIT_MPS = 10.0
TURN_SPEED_MPS = 5.0  # speed limit of the turning lanes in the junctions
ARM_DIRECTIONS = ((0, 1), (-1, 0), (0, -1), (1, 0))  # grid steps (column, row) of arms 0..3
CROSSING_WIDTH_M = 3.0  # a zebra crossing's width along the street

# traffic rules
STOP_MARGIN_M = 1.0  # front bumper to stop line once stopped
PAVEMENT_M = LANE_WIDTH_M + 1.5  # a waiting pedestrian stands this far from the street's axis
CROSSING_GAP_M, CROSSING_GAP_S = 6.0, 2.5  # a pedestrian waits while a vehicle closes in within
# 6 m + 2.5 s of travel of the crossing
CROSSING_CLEAR_M = 8.0  # nor while a vehicle stands within this of the crossing's centre
COURTESY_M = 15.0  # nor while a vehicle facing the crossing waits this close to it
FACING_COS = 0.7  # a vehicle "faces" the crossing when its heading is within ~45° of it
MEAN_WAIT_S = 20.0  # on the pavement between two crossings (exponential)
MOVING_MPS = 0.5  # a vehicle slower than this cannot hurt a pedestrian
WRECK_CLEARED_S = 10.0  # crashed NPC vehicles are towed away after this
ONCOMING_WATCH_M = 30.0  # a left turn yields to oncoming vehicles this close to the junction
TURN_BRAKE_MARGIN_M = 5.0  # slow to the next lane's limit this much before the braking distance
PEDESTRIAN_SIZE_M = 0.8  # a pedestrian's box, length and width
FIXED_ROUTE_COUNT = 25  # NoCrash's evaluation routes per town
ROUTE_GOAL_TRIES = 10  # random goals drawn before a random route gives up


@dataclass(frozen=True)
class LightTimings:
    """Seconds of each phase of a junction's cycle (per axis: green, yellow, then all red)."""

    green_s: float = 10.0
    yellow_s: float = 3.0
    all_red_s: float = 1.0

    @property
    def cycle_s(self) -> float:
        return 2 * (self.green_s + self.yellow_s + self.all_red_s)


def light_state(timings: LightTimings, arm: int, time_s: float, offset_s: float = 0.0) -> int:
    """LIGHT_GREEN / LIGHT_YELLOW / LIGHT_RED of ``arm`` at ``time_s`` for a junction whose cycle
    started at ``offset_s``: arms 0 and 2 go first, then arms 1 and 3."""
    half = timings.green_s + timings.yellow_s + timings.all_red_s
    phase = (time_s - offset_s) % timings.cycle_s
    if arm % 2 == 1:
        phase = (phase - half) % timings.cycle_s
    if phase < timings.green_s:
        return LIGHT_GREEN
    if phase < timings.green_s + timings.yellow_s:
        return LIGHT_YELLOW
    return LIGHT_RED
