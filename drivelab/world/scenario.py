"""What a scenario declares (the presets live in ``drivelab.scenarios``): the simulators and
the rules read a Scenario handed to them and never look presets up themselves."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

from drivelab.world.options import Option

META_ACTIONS = ("LANE_LEFT", "IDLE", "LANE_RIGHT", "FASTER", "SLOWER")  # highway-env's meta-actions


@dataclass(frozen=True)
class Scenario:
    """A named driving task.

    :param env_class: dotted path of the highway-env environment class that builds the road.
    :param config: highway-env config shared by every traffic level.
    :param traffic: per traffic level, highway-env config overrides plus drivelab's
        ``extra_vehicles`` (NPCs added on random lanes) and ``keep_npcs`` (False removes them all).
    :param destination: road-network node the ego is routed to (None: follow the road).
    :param arrival: how the backend decides the goal is reached: "none", "merge_end", "exit".
    :param intersection_nodes: road-network nodes whose lanes count as junction area.
    :param junction_needs_both_ends: a lane is junction area only when it also ends at one of
        those nodes (the roundabout: its exits leave ring nodes too).
    :param meta_target_speeds: the speeds FASTER / SLOWER step through (None: 20, 25, 30 m/s).
    :param fast_backend: drivelab's fast backend runs it (the "auto" backend then picks it).
    :param camera: how videos and ``render()`` look at a world: "road" (along the road, the ego a
        third of the way in) or "map" (the map from above, north up: the town, the block maps).
    :param simulator: dotted path of the compiled core's simulator class that runs it
        (``FastSimulator``, or the scenario's own subclass), imported when a world is built.
    :param route_deviation_m: the episode fails when the ego is farther than this from its route.
    :param blocked_after_s: the episode fails when the ego stays below 0.1 m/s this long.
    :param default_reward: the reward preset a run gets when it names none.
    :param circuit: the road is a closed loop: the route is one whole lap (however long).
    :param guide_line: a yellow line is painted along the route (follow-line).
    :param keep_lane: leaving the ego's starting lane counts as leaving the road (follow-lane).
    :param procedural_maps: its worlds drive maps generated from seeds (the blocks); each
        episode's seed picks the map from the scenario's set.
    :param reference_backend: highway-env's reference backend can run it (``backend="highway"``).
    :param spawn: the compiled core's episode set-up of one world, ``spawn(seed, road, control)
        -> (vehicle rows, ego row, regulation (2,), generator between steps or None)`` (``road``:
        the simulator's converted road); None: the compiled core cannot run the scenario.
    :param spawn_many: the same for many worlds in one call, ``spawn_many(road, control, seeds
        (M,)) -> (rows (M, N, C), count (M,), ego row (M,))``, worlds without regulation or a
        generator between steps (None: ``spawn`` once per reset world).
    :param arrivals: ``arrivals(road)`` gives the object whose ``spawn(rows, rng, probability)``
        brings a vehicle in between steps (a scenario with a ``traffic_flow``).
    :param road: ``road(config)``: the scenario's ``RoadDescription`` from its merged config;
        None: the road is highway-env's (converted from its network).
    :param options: the config keys a user may set (``backend_options``), declared with their
        type, range, default and meaning (``drivelab.world.options``).
    :param check_options: the scenario's own cross-checks of its options, given every declared
        option's value (the user's over the defaults); raises a UsageError.
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
    simulator: str = "drivelab.sim.core.simulator.FastSimulator"
    camera: str = "road"
    route_deviation_m: float | None = None
    blocked_after_s: float | None = None
    action_kinds: tuple[str, ...] = ("meta", "grid", "continuous", "target_speed")
    default_reward: str = "highway"
    circuit: bool = False
    guide_line: bool = False
    keep_lane: bool = False
    junction_needs_both_ends: bool = False
    procedural_maps: bool = False
    reference_backend: bool = True
    spawn: Callable | None = field(default=None, repr=False)
    spawn_many: Callable | None = field(default=None, repr=False)
    arrivals: Callable | None = field(default=None, repr=False)
    road: Callable[[dict], object] | None = field(default=None, repr=False)
    options: tuple[Option, ...] = field(default=(), repr=False)
    check_options: Callable[[dict], None] | None = field(default=None, repr=False)

    def in_junction(self, lane_index: tuple) -> bool:
        """Whether highway-env lane (from, to, id) is junction area: it leaves a junction node
        (and ends at one, with ``junction_needs_both_ends``)."""
        if lane_index[0] not in self.intersection_nodes:
            return False
        return not self.junction_needs_both_ends or lane_index[1] in self.intersection_nodes
