"""What a scenario declares (the presets live in ``drivelab.envs.scenarios``): the simulators and
the rules read a Scenario handed to them and never look presets up themselves."""

from __future__ import annotations

from dataclasses import dataclass, field

META_ACTIONS = ("LANE_LEFT", "IDLE", "LANE_RIGHT", "FASTER", "SLOWER")  # highway-env's meta-actions


@dataclass(frozen=True)
class Scenario:
    """A named driving task.

    :param env_class: dotted path of the highway-env environment class that builds the road.
    :param config: highway-env config shared by every traffic level.
    :param traffic: per traffic level, highway-env config overrides plus the drivelab-only key
        ``extra_vehicles`` (NPCs added on random lanes after highway-env populated the road) and
        ``keep_npcs`` (False removes every NPC highway-env created).
    :param destination: road-network node the ego is routed to (None: follow the road).
    :param arrival: how the backend decides the goal is reached: "none", "merge_end", "exit".
    :param intersection_nodes: road-network nodes whose lanes count as junction area.
    :param meta_target_speeds: the speeds FASTER / SLOWER step through (None: highway-env's
        default 20, 25, 30 m/s), as in highway-env's own config of the scenario.
    :param fast_backend: drivelab's fast backend runs it (the "auto" backend then picks it).
    :param route_deviation_m: the episode fails when the ego is farther than this from its route.
    :param blocked_after_s: the episode fails when the ego stays below 0.1 m/s this long.
    :param default_reward: the reward preset a run gets when it names none.
    :param circuit: the road is a closed loop: the route is one whole lap (however long).
    :param guide_line: a yellow line is painted along the route (follow-line).
    :param keep_lane: leaving the ego's starting lane counts as leaving the road (follow-lane).
    """

    name: str
    env_class: str
    description: str
    config: dict = field(default_factory=dict)
    traffic: dict = field(default_factory=dict)
    destination: str | None = None
    arrival: str = "none"
    arrival_x_m: float | None = None  # "merge_end": the goal is reached past this x
    traffic_flow: bool = False  # vehicles leave at the exits and arrive at the entries between steps
    intersection_nodes: tuple[str, ...] = ()
    continuous_policy_frequency_hz: int = 5
    meta_target_speeds: tuple[float, ...] | None = None
    fast_backend: bool = True
    route_deviation_m: float | None = None
    blocked_after_s: float | None = None
    action_kinds: tuple[str, ...] = ("meta", "grid", "continuous", "target_speed")
    default_reward: str = "highway"
    circuit: bool = False
    guide_line: bool = False
    keep_lane: bool = False

    def in_junction(self, lane_index: tuple) -> bool:
        """Whether highway-env lane (from, to, id) is junction area: it leaves a junction node
        (on the roundabout, it must also end at one: the exits leave the ring too)."""
        if lane_index[0] not in self.intersection_nodes:
            return False
        return self.name != "roundabout" or lane_index[1] in self.intersection_nodes
