"""highway-env roads for the CARLA study's follow-line and follow-lane tasks (no traffic).

Both are closed circuits of straights and arcs described as blocks (``roads.blocks.circuit``)
and turned into highway-env's road network, so that the ``highway`` backend runs them. The ego is
a ``PedalVehicle``: the seed's CARLA actions are throttle values, so its acceleration is the
commanded one minus a speed-proportional drag (``DRAG_PER_S``).
"""

from __future__ import annotations

from highway_env import utils
from highway_env.envs.common.abstract import AbstractEnv
from highway_env.road.road import Road, RoadNetwork
from highway_env.vehicle.kinematics import Vehicle

from drivelab.scenarios.circuits.tracks import (  # noqa: F401 (re-exported for the circuits' users)
    FOLLOW_LANE_ROAD,
    FOLLOW_LANE_TRACK,
    FOLLOW_LINE_ROAD,
    FOLLOW_LINE_TRACK,
)
from drivelab.sim.core.traffic import PEDAL_DRAG_PER_S
from drivelab.sim.roads.blocks import circuit
from drivelab.sim.roads.highway_network import to_road_network

# the pedal's drag (the CARLA study's speeds), shared with the compiled kernel
DRAG_PER_S = PEDAL_DRAG_PER_S


class PedalVehicle(Vehicle):
    """A kinematic bicycle whose commanded acceleration is a pedal: drag pulls its speed down."""

    def act(self, action: dict | str | None = None) -> None:
        # highway-env calls act() without an action before every simulation frame: keep the pedal
        if isinstance(action, dict):
            self.pedal_mps2 = float(action.get("acceleration", 0.0))
        super().act(action)

    def step(self, dt: float) -> None:
        # the CARLA study speeds: acceleration = pedal − drag · v, so a constant throttle levels off
        self.action["acceleration"] = getattr(self, "pedal_mps2", 0.0) - DRAG_PER_S * self.speed
        super().step(dt)


def build_circuit(track, lane_count: int, lane_width_m: float, speed_limit_mps: float) -> RoadNetwork:
    """``roads.blocks.circuit`` of ``track`` (see ``FOLLOW_LINE_TRACK``) as highway-env lanes."""
    return to_road_network(circuit(track, lane_count, lane_width_m, speed_limit_mps))


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
                **FOLLOW_LINE_ROAD,  # track, lanes_count, lane_width, speed_limit
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
    """The CARLA study's follow-line task: one 7 m lane around a 470 m circuit, a yellow centre line."""


class FollowLaneEnv(CircuitEnv):
    """The CARLA study's follow-lane task: three 3.5 m lanes around a 1.6 km circuit."""

    @classmethod
    def default_config(cls) -> dict:
        config = super().default_config()
        config.update({**FOLLOW_LANE_ROAD, "duration": 60})
        return config
