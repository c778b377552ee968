"""Procedural block maps (MetaDrive's PG maps, the MetaDrive study's "OSX"): the preset and its
compiled-core hooks (only the compiled core runs them: highway-env has no such road).

Config keys (``backend_options``), MetaDrive's names and defaults: ``map`` (a block string such as
``"OSX"`` or a number of random blocks; 3), ``start_seed`` (0) and ``num_scenarios`` (1): the maps
of seeds ``start_seed`` … ``start_seed + num_scenarios − 1``; ``lane_count`` (3; null: 2 or 3 per
map), ``lane_width`` (3.5; null: U[3, 4.5] per map), ``signalised`` (false; true: the town's
traffic lights at every X and T intersection) and ``traffic_density`` (the traffic levels: empty
0, regular 0.1, dense 0.2).
"""

from __future__ import annotations

from drivelab.scenarios.blocks.pg_map import MAX_LANES, parse_spec
from drivelab.scenarios.blocks.spawn import (
    MAP_DEFAULTS,
    BlocksMap,
    MapSet,
    spawn_blocks_episode,
    traffic_density,
)
from drivelab.scenarios.options import Option, timing_options
from drivelab.sim.roads.description import RoadDescription
from drivelab.world.scenario import Scenario

DENSITIES = {"empty": 0.0, "regular": 0.1, "dense": 0.2}
# MetaDrive steps its agents every 0.1 s (5 physics steps of 0.02 s, metadrive/envs/base_env.py):
# 10 decisions a second over 20 simulation frames of the compiled core
POLICY_FREQUENCY_HZ, SIMULATION_FREQUENCY_HZ = 10, 20
# MetaDrive's horizon: 1000 steps of 0.1 s (an episode's own limit is its route's, see
# ``blocks_spawn.route_time_limit_s``; this applies where no route gives one)
HORIZON_S = 100.0


def blocks_road(config: dict) -> RoadDescription:
    """The road of the first map of the config's set (seed ``start_seed``)."""
    maps = MapSet.from_config(config)
    return maps.generate(maps.start_seed).description


def spawn_blocks(seed: int, bmap: BlocksMap, control: str):
    """An episode on ``bmap`` (the map ``seed`` picked) at the config's traffic density:
    ``blocks_spawn.spawn_blocks_episode``."""
    return spawn_blocks_episode(seed, bmap, control, traffic_density(bmap.road.config))


# MetaDrive's map and traffic keys (``MapSet.from_config`` and ``traffic_density`` read them)
OPTIONS = (
    Option(
        "map", (str, int), MAP_DEFAULTS["map"],
        "the blocks after the spawn road: a block string such as OSX, or a number of random blocks",
        expected="a block string such as 'OSX' or a block count", check=parse_spec,  # parse_spec: >= 1
    ),
    Option("start_seed", int, MAP_DEFAULTS["start_seed"], "the seed of the set's first map", minimum=0),
    Option(
        "num_scenarios", int, MAP_DEFAULTS["num_scenarios"],
        "maps in the set (seeds start_seed …); each episode drives the map its seed picks", minimum=1,
    ),
    Option(
        "lane_count", int, MAP_DEFAULTS["lane_count"], "lanes per direction; null: 2 or 3 per map",
        minimum=1, maximum=MAX_LANES, nullable=True,
    ),
    Option(
        "lane_width", float, MAP_DEFAULTS["lane_width"], "lane width, m; null: U[3, 4.5] per map",
        minimum=2, maximum=6, nullable=True,
    ),
    Option(
        "signalised", bool, MAP_DEFAULTS["signalised"],
        "traffic lights at every X and T intersection (NPCs stop at red; running one is an event)",
    ),
    Option(
        "traffic_density", float, DENSITIES["regular"],
        "MetaDrive's traffic density: vehicles per 10 m of a block's lanes", minimum=0, maximum=1,
        traffic=True,
    ),
    # the blocks' junctions are regulated: right of way every simulation_frequency // 2 frames
    *timing_options(
        SIMULATION_FREQUENCY_HZ, POLICY_FREQUENCY_HZ, POLICY_FREQUENCY_HZ, minimum_simulation_hz=2
    ),
)  # fmt: skip


SCENARIO = Scenario(
    "blocks",
    "highway_env.envs.common.abstract.AbstractEnv",  # only its default config is read
    "procedural block maps (MetaDrive's; map=OSX or N random blocks, num_scenarios maps from "
    "start_seed): route from the spawn road to the last block, IDM/MOBIL traffic",
    config={
        **{key: value for key, value in MAP_DEFAULTS.items() if key != "traffic_density"},
        "duration": HORIZON_S,
        "simulation_frequency": SIMULATION_FREQUENCY_HZ,
        "policy_frequency": POLICY_FREQUENCY_HZ,
    },
    traffic={level: {"traffic_density": density} for level, density in DENSITIES.items()},
    arrival="route_end",
    continuous_policy_frequency_hz=POLICY_FREQUENCY_HZ,
    meta_target_speeds=(0, 5, 10, 15, 20),
    action_kinds=("continuous", "grid", "meta", "target_speed"),
    default_reward="metadrive",
    procedural_maps=True,
    simulator="drivelab.scenarios.blocks.simulator.BlocksSimulator",
    camera="map",
    reference_backend=False,
    spawn=spawn_blocks,
    road=blocks_road,
    options=OPTIONS,
)
