"""highway-env roads for seed 004's follow-line and follow-lane tasks (no traffic).

Both are closed circuits built from straights and circular arcs with highway-env's road network
(``StraightLane``, ``CircularLane``), turning right and left, so the ``highway`` backend runs them
like any other scenario. The follow-line circuit is one wide lane with a yellow line painted along
its centre (exported as ``RoadMap.guide_lines`` by the backend); the follow-lane circuit has three
lanes with dashed lines between them.

The ego is a ``PedalVehicle``: the seed's CARLA actions are throttle values, which in CARLA give a
speed that levels off, so its acceleration is the commanded one minus a speed-proportional drag
(``DRAG_PER_S``). Only this module and ``highway.py`` import highway-env.
"""

from __future__ import annotations

import numpy as np
from highway_env import utils
from highway_env.envs.common.abstract import AbstractEnv
from highway_env.road.lane import CircularLane, LineType, StraightLane
from highway_env.road.road import Road, RoadNetwork
from highway_env.vehicle.kinematics import Vehicle

from drivelab.envs.backends.fast.traffic import PEDAL_DRAG_PER_S

# the pedal's drag (seed 004's speeds), shared with the compiled kernel
DRAG_PER_S = PEDAL_DRAG_PER_S

# Circuits as (kind, length_m) straights and (kind, radius_m, turn_deg) arcs, starting at the
# origin heading +x; a positive turn is to the right (heading grows, y points right). Both close
# exactly (the closing straights were solved for by hand).
FOLLOW_LINE_TRACK = (
    ("straight", 70.0), ("arc", 30.0, 90.0), ("straight", 20.0), ("arc", 30.0, 90.0),
    ("straight", 10.0), ("arc", 25.0, -90.0), ("straight", 10.0), ("arc", 25.0, 90.0),
    ("straight", 10.0), ("arc", 30.0, 90.0), ("straight", 80.0), ("arc", 30.0, 90.0),
)  # fmt: skip
FOLLOW_LANE_TRACK = tuple(
    (kind, *(value * 4.0 if index == 0 else value for index, value in enumerate(rest)))
    for kind, *rest in FOLLOW_LINE_TRACK
)  # the same shape four times larger: radii 100–120 m suit the seed's small lane steering angles


class PedalVehicle(Vehicle):
    """A kinematic bicycle whose commanded acceleration is a pedal: drag pulls its speed down."""

    def act(self, action: dict | str | None = None) -> None:
        # highway-env calls act() without an action before every simulation frame: keep the pedal
        if isinstance(action, dict):
            self.pedal_mps2 = float(action.get("acceleration", 0.0))
        super().act(action)

    def step(self, dt: float) -> None:
        # seed 004 speeds: acceleration = pedal − drag · v, so a constant throttle levels off
        self.action["acceleration"] = getattr(self, "pedal_mps2", 0.0) - DRAG_PER_S * self.speed
        super().step(dt)


def build_circuit(track, lane_count: int, lane_width_m: float, speed_limit_mps: float) -> RoadNetwork:
    """A closed road of ``lane_count`` parallel lanes along ``track`` (see ``FOLLOW_LINE_TRACK``).

    Lane 0 is the leftmost; the outer lines are solid, the lines between lanes dashed. Nodes are
    named "0", "1", … so that node ``k`` starts segment ``k`` and the last segment ends at "0".
    """
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


class CircuitEnv(AbstractEnv):
    """A closed circuit without traffic; the ego starts on a random lane at a random place.

    Config keys beyond highway-env's: ``track``, ``lanes_count``, ``lane_width``, ``speed_limit``,
    ``initial_speed``. drivelab computes rewards and terminations itself; the two methods below
    only keep highway-env's own loop meaningful.
    """

    @classmethod
    def default_config(cls) -> dict:
        config = super().default_config()
        utils.update_config(
            config,
            {
                "action": {"type": "ContinuousAction"},
                "simulation_frequency": 10,  # 2 substeps per 5 Hz step: the ego alone, no collisions to catch
                "policy_frequency": 5,
                "duration": 60,
                "track": FOLLOW_LINE_TRACK,
                "lanes_count": 1,
                "lane_width": 7.0,
                "speed_limit": 20.0,
                "initial_speed": 5.0,
            },
        )
        return config

    def _reset(self) -> None:
        network = build_circuit(
            self.config["track"],
            self.config["lanes_count"],
            self.config["lane_width"],
            self.config["speed_limit"],
        )
        self.road = Road(network=network, np_random=self.np_random, record_history=False)
        rng = self.np_random
        lane_index = network.random_lane_index(rng)
        lane = network.get_lane(lane_index)
        ego = PedalVehicle.make_on_lane(
            self.road, lane_index, longitudinal=float(rng.uniform(0, lane.length)),
            speed=float(self.config["initial_speed"]),
        )  # fmt: skip
        self.controlled_vehicles = [ego]
        self.road.vehicles.append(ego)

    def _reward(self, action) -> float:
        return 0.0  # drivelab's reward shapers compute the reward from WorldStates

    def _is_terminated(self) -> bool:
        return bool(self.vehicle.crashed or not self.vehicle.on_road)

    def _is_truncated(self) -> bool:
        return self.time >= self.config["duration"]


class FollowLineEnv(CircuitEnv):
    """Seed 004's follow-line task: one 7 m lane around a 470 m circuit, a yellow centre line."""


class FollowLaneEnv(CircuitEnv):
    """Seed 004's follow-lane task: three 3.5 m lanes around a 1.6 km circuit."""

    @classmethod
    def default_config(cls) -> dict:
        config = super().default_config()
        config.update({"track": FOLLOW_LANE_TRACK, "lanes_count": 3, "lane_width": 3.5, "duration": 60})
        return config
