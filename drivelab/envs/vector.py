"""VectorDriveEnv: K worlds of one scenario stepped, sensed, rewarded and judged as arrays.

The product of drivelab's environment layer (docs/architecture.md). One ``step`` maps the K
actions to controls, steps the simulator once for all K worlds (a WorldBatch out), applies the
episode rules, the reward terms and the metrics to (K,) arrays, and writes each sensor's (K, …)
observations. ``DriveEnv`` (envs/core.py) is its K = 1 view; ``SB3VecEnv`` (agents/sb3_env.py)
puts it behind stable-baselines3's ``VecEnv`` API.

Autoreset: gymnasium's NEXT_STEP by default (a finished world is reset by the step after the one
that ended it, as gymnasium's vector wrappers expect), or SAME_STEP (reset inside the ending step;
its last observation and info go to ``infos["final_obs"]`` / ``infos["final_info"]``), which the
SB3 adapter uses.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium import spaces
from gymnasium.utils import seeding
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from drivelab.envs.actions import ActionAdapter, make_action
from drivelab.envs.metrics import EpisodeMetrics
from drivelab.envs.rules import EpisodeRules, episode_time_limits_s
from drivelab.envs.spec import EnvSpec
from drivelab.envs.video import camera_for, draw_scene
from drivelab.errors import UsageError
from drivelab.perception.sensors import check_sensors_for, make_sensor, split_sensor_list
from drivelab.rewards.shapers import RewardShaper
from drivelab.scenarios import check_traffic, get_scenario
from drivelab.scenarios.options import check_backend_options
from drivelab.world.batch import WorldBatch
from drivelab.world.state import LIGHT_GREEN, LIGHT_RED, LIGHT_YELLOW

BACKENDS = ("auto", "fast", "highway")
LIGHT_LABEL_DISTANCE_M = 18.0  # RLAD's auxiliary label: a light within this distance ahead
LIGHT_LABELS = {-1: "none", LIGHT_GREEN: "green", LIGHT_YELLOW: "red_or_yellow", LIGHT_RED: "red_or_yellow"}
_LABEL_OF_STATE = np.array([LIGHT_LABELS[state] for state in sorted(LIGHT_LABELS)], dtype=object)  # state + 1
# A world draws its training episodes' seeds below this from its own generator; evaluation plays
# the seeds above it (``drivelab.training.seeds``), given with ``reset(options={"episode_seeds": …})``.
TRAINING_SEED_LIMIT = 2**31 - 1


AUTORESET_MODES = {"next_step": AutoresetMode.NEXT_STEP, "same_step": AutoresetMode.SAME_STEP}


def autoreset_mode_of(mode: AutoresetMode | str) -> AutoresetMode:
    """gymnasium's NEXT_STEP or SAME_STEP, given as the enum, its value or "next_step" / "same_step"."""
    for name, member in AUTORESET_MODES.items():
        if mode in (member, member.value, name):
            return member
    raise UsageError(f"unknown autoreset_mode {mode!r} (choose from {', '.join(AUTORESET_MODES)})")


def make_simulator(backend: str, scenario, traffic: str, control: str, num_worlds: int, overrides):
    """The simulator of ``backend`` ("auto", "fast" or "highway") for K worlds of ``scenario``."""
    if backend not in BACKENDS:
        raise UsageError(f"unknown backend {backend!r} (choose from {', '.join(BACKENDS)})")
    if backend == "auto":
        backend = "fast" if scenario.fast_backend else "highway"
    if backend == "highway" and not scenario.reference_backend:
        raise UsageError(f"scenario {scenario.name!r} runs on the compiled core only (backend fast or auto)")
    if backend == "fast":
        from drivelab.sim.core.backend import fast_simulator

        return fast_simulator(scenario, traffic, control, num_worlds, overrides)
    from drivelab.sim.reference.highway import HighwayBackend
    from drivelab.sim.reference.per_world import PerWorldSimulator

    return PerWorldSimulator(HighwayBackend, scenario, traffic, control, num_worlds, overrides)


class VectorDriveEnv(VectorEnv):
    """``num_envs`` worlds of one driving scenario, seen through drivelab's sensors and rewarded
    by its shapers, stepped together as arrays.

    :param num_envs: K, the number of worlds.
    :param scenario: a name of ``drivelab.scenarios.SCENARIOS`` or its gymnasium id.
    :param render_mode: "rgb_array" for ``render()``.
    :param autoreset_mode: gymnasium's ``AutoresetMode`` (or its value): NEXT_STEP (default) or
        SAME_STEP.
    :param env_spec: an :class:`~drivelab.envs.spec.EnvSpec` already built (then no other keyword).
    :param keywords: the environment's keywords (``obs``, ``action``, ``reward``, ``traffic``,
        ``backend``, ``duration_s``, …, ``config``: a highway-env config dict; the scenario's
        options at the top level), read into an :class:`~drivelab.envs.spec.EnvSpec`.
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 5, "autoreset_mode": AutoresetMode.NEXT_STEP}

    def __init__(
        self,
        num_envs: int = 1,
        scenario: str = "highway",
        *,
        render_mode: str | None = None,
        autoreset_mode: AutoresetMode | str = AutoresetMode.NEXT_STEP,
        env_spec: EnvSpec | None = None,
        **keywords: Any,
    ) -> None:
        if isinstance(num_envs, bool) or not isinstance(num_envs, (int, np.integer)) or num_envs < 1:
            raise UsageError(f"num_envs must be an integer >= 1 (got {num_envs!r})")
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise UsageError(f"render_mode must be None or 'rgb_array' (got {render_mode!r})")
        if env_spec is not None and keywords:
            raise UsageError(f"give the environment's keywords or its spec, not both ({', '.join(keywords)})")
        self.env_spec = spec = env_spec or EnvSpec.build(scenario=scenario, **keywords)
        self.autoreset_mode = autoreset_mode_of(autoreset_mode)
        self.scenario = get_scenario(spec.scenario)
        check_traffic(spec.traffic)
        action = self.scenario.action_kinds[0] if spec.action is None else spec.action
        reward = self.scenario.default_reward if spec.reward is None else spec.reward
        if not isinstance(action, ActionAdapter):
            action = make_action(action, **(spec.action_options or {}))
        self.adapter = action
        if self.adapter.name not in self.scenario.action_kinds:
            raise UsageError(
                f"scenario {spec.scenario!r} cannot take action {self.adapter.name!r} "
                f"(it takes {', '.join(self.scenario.action_kinds)})"
            )
        options = spec.backend_options
        check_backend_options(self.scenario, options, spec.traffic, self.adapter.control)
        self.sensors = [make_sensor(sensor) for sensor in split_sensor_list(spec.obs)]
        names = [s.name for s in self.sensors]
        if len(set(names)) != len(names):
            raise UsageError(f"sensor listed twice in {names}")
        check_sensors_for(self.scenario, self.sensors)
        self.reward_shaper = RewardShaper(reward)
        self.num_envs = int(num_envs)
        self.simulator = make_simulator(
            spec.backend, self.scenario, spec.traffic, self.adapter.control, self.num_envs, options
        )
        self.duration_s = float(spec.duration_s or self.simulator.duration_s)
        self.duration_given = spec.duration_s is not None
        self.rules = EpisodeRules(self.scenario, spec.offroad_terminal)
        self.metrics = EpisodeMetrics()
        self.render_mode = render_mode
        self.metadata = {
            **self.metadata,
            "render_fps": self.simulator.policy_frequency_hz,
            "autoreset_mode": self.autoreset_mode,
        }
        self.single_action_space = self.adapter.space
        if len(self.sensors) == 1:
            self.single_observation_space = self.sensors[0].space
        else:
            self.single_observation_space = spaces.Dict({s.name: s.space for s in self.sensors})
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        # each world's generator of episode seeds (a DriveEnv's ``np_random``)
        self.world_rngs: list[np.random.Generator] = [seeding.np_random()[0] for _ in range(self.num_envs)]
        self.world_seeds: list[int | None] = [None] * self.num_envs
        # each world's generator state before its latest episode-seed draw (what an episode started
        # from: training's episode log records it, resume_state.py)
        self.draw_states: list[dict | None] = [None] * self.num_envs
        self._batch: WorldBatch | None = None
        self._batch_deferred = False  # the last step's batch is the simulator's, made when read
        self.observations: np.ndarray | dict[str, np.ndarray] | None = None  # the last ones returned
        self.episode_seeds = np.zeros(self.num_envs, dtype=np.int64)
        self.pending_reset = np.zeros(self.num_envs, dtype=bool)  # NEXT_STEP: reset on the next step
        self._no_light_labels = np.full(self.num_envs, _LABEL_OF_STATE[0], dtype=object)
        self._fused = None  # the whole step as one compiled call, where one covers this configuration
        if self.scenario.circuit:
            from drivelab.envs.fused import CircuitStep

            self._fused = CircuitStep.of(self)

    @property
    def batch(self) -> WorldBatch | None:
        """The worlds after the last reset or step (None before the first reset)."""
        if self._batch_deferred:  # a compiled step's (envs/fused.py): made now, from its export
            self._batch, self._batch_deferred = self.simulator.batch, False
        return self._batch

    @batch.setter
    def batch(self, batch: WorldBatch | None) -> None:
        self._batch, self._batch_deferred = batch, False

    @property
    def started(self) -> bool:
        """The worlds have been reset (a batch exists, or is made when read)."""
        return self._batch_deferred or self._batch is not None

    # --- observations ------------------------------------------------------------------------
    def _observe(self, batch: WorldBatch) -> np.ndarray | dict[str, np.ndarray]:
        if len(self.sensors) == 1:
            return self.sensors[0].observe(batch)
        return {s.name: s.observe(batch) for s in self.sensors}

    def _observe_again(self, observations, batch: WorldBatch, worlds: np.ndarray):
        """Observe only ``worlds`` (just reset within this step) and write their rows in."""
        fresh = self._observe(batch.select(worlds))
        if isinstance(observations, dict):
            for name in observations:
                observations[name][worlds] = fresh[name]
        else:
            observations[worlds] = fresh
        return observations

    # --- episodes ----------------------------------------------------------------------------
    def _draw_seeds(self, mask: np.ndarray) -> None:
        """The next episode seed of every world of ``mask``, from that world's generator."""
        if not np.count_nonzero(mask):  # (ndarray.any's Python wrapper costs a microsecond a call)
            return
        for k in np.flatnonzero(mask):
            generator = self.world_rngs[k]
            self.draw_states[k] = generator.bit_generator.state
            self.episode_seeds[k] = int(generator.integers(TRAINING_SEED_LIMIT))

    def _start(
        self, mask: np.ndarray, batch: WorldBatch | None = None, episode_seeds: np.ndarray | None = None
    ) -> None:
        """New episodes in the worlds of ``mask``, every part reset by mask: episode seeds from each
        world's generator (or ``episode_seeds`` (K,) given). With ``batch``, the simulator has
        already started them (in its step) from the drawn seeds."""
        worlds = np.flatnonzero(mask)
        if batch is None:
            if episode_seeds is None:
                self._draw_seeds(mask)
            else:
                self.episode_seeds[mask] = episode_seeds[mask]
            batch = self.simulator.reset_where(mask, self.episode_seeds)
        self.adapter.reset(mask)
        for index, sensor in enumerate(self.sensors):
            rngs = [None] * self.num_envs
            if sensor.uses_rng:
                for k in worlds:
                    rngs[k] = np.random.default_rng([int(self.episode_seeds[k]), index])
            sensor.reset(batch, rngs, mask)
        route_limits = getattr(self.simulator, "route_time_limit_s", None)
        route_limits = np.inf if route_limits is None else route_limits
        limits = episode_time_limits_s(self.duration_s, self.duration_given, route_limits)
        self.rules.reset(mask, limits)
        self.metrics.reset(batch, mask)
        self.batch = batch

    def _seed_worlds(self, seed: int | list[int | None] | None) -> None:
        if seed is None:
            return
        seeds = (
            [seed + k for k in range(self.num_envs)] if isinstance(seed, (int, np.integer)) else list(seed)
        )
        if len(seeds) != self.num_envs:
            raise UsageError(f"reset got {len(seeds)} seeds for {self.num_envs} worlds")
        for k, world_seed in enumerate(seeds):
            if world_seed is not None:
                self.world_rngs[k], self.world_seeds[k] = seeding.np_random(int(world_seed))

    def reset(self, *, seed: int | list[int | None] | None = None, options: dict | None = None):
        """Start every world's episode; an int seed gives world k the seed ``seed + k`` (a list,
        one per world). ``options={"reset_mask": mask}`` (gymnasium's partial reset) starts only
        the worlds of ``mask``; ``options={"episode_seeds": seeds}`` (K,) plays those episodes
        (e.g. ``drivelab.training.seeds.evaluation_seeds``) instead of drawing the next ones from the worlds'
        generators, which it leaves as they are. Infos: ``episode_seed`` and ``traffic_light``
        per world."""
        check_reset_options(options)
        self._seed_worlds(seed)
        mask = np.ones(self.num_envs, dtype=bool)
        if options and options.get("reset_mask") is not None and self.batch is not None:
            mask = np.asarray(options["reset_mask"], dtype=bool).reshape(self.num_envs)
        self._start(mask, episode_seeds=_episode_seeds(options, self.num_envs))
        self.pending_reset &= ~mask
        if mask.all():
            self.observations = self._observe(self.batch)
        else:
            self.observations = self._observe_again(
                _copy(self.observations), self.batch, np.flatnonzero(mask)
            )
        return self.observations, self._reset_infos(mask)

    def _reset_infos(self, mask: np.ndarray) -> dict:
        infos = {"episode_seed": self.episode_seeds.copy(), "traffic_light": self.traffic_light_labels()}
        infos.update({f"_{key}": mask.copy() for key in list(infos)})
        return infos

    def step(self, actions: Any):
        """One policy step of every world (see the module docstring for autoreset)."""
        if not self.started:
            raise RuntimeError("call reset() before step()")
        restarting = self.pending_reset.copy()  # NEXT_STEP: these worlds begin a new episode now
        any_restarting = bool(np.count_nonzero(restarting))  # (ndarray.any costs a microsecond)
        if not any_restarting and self._fused is not None and self._fused.ready():
            return self._fused_step(actions, restarting)
        prev = self.batch
        controls = self.adapter.controls_for(actions, prev)
        if any_restarting:
            self._draw_seeds(restarting)
        stepped = self.simulator.step(controls, restarting, self.episode_seeds)
        batch, terminated, truncated = self.rules.apply(stepped)
        rewards, terms = self.reward_shaper(prev, batch, controls)
        self.metrics.update(batch, rewards)
        done = terminated | truncated
        events = batch.events
        infos = self._step_infos(
            terms, batch.ego.speed_mps.copy(), events.collided.copy(), events.off_road.copy(),
            events.arrived.copy(), done, truncated,
        )  # fmt: skip
        self.batch = batch
        if any_restarting:  # their values above judged no step of theirs: discarded
            if batch is not stepped:  # a restarted world starts with its simulator's events
                self.batch = batch.where(restarting, stepped)
            self._start(restarting, self.batch)
            rewards = np.where(restarting, 0.0, rewards)
            infos["reward_terms"] = {
                name: np.where(restarting, value.dtype.type(0), value)
                for name, value in infos["reward_terms"].items()
            }
            terminated, truncated = terminated & ~restarting, truncated & ~restarting
            done = terminated | truncated
            if "episode_metrics" in infos:
                infos["_episode_metrics"] = infos["_episode_metrics"] & ~restarting
            infos["episode_seed"] = self.episode_seeds.copy()
            infos["_episode_seed"] = restarting
        observations = self._observe(self.batch)
        infos["traffic_light"] = self.traffic_light_labels()
        return self._finish_step(observations, rewards, terminated, truncated, done, infos, restarting)

    def _fused_step(self, actions, restarting: np.ndarray):
        """``step`` as one compiled call (``envs/fused.py``; no world restarting): the batch is the
        simulator's, made when read."""
        fused = self._fused
        observations, out, flags = fused.step(self.adapter.to_controls(actions))
        self._batch, self._batch_deferred = None, True
        terminated, truncated = fused.ends(flags)
        done = terminated | truncated
        infos = self._step_infos(fused.terms(out), *fused.events(out, flags), done, truncated)
        infos["traffic_light"] = self._no_light_labels.copy()  # the circuits have no lights
        return self._finish_step(
            observations, fused.rewards(out), terminated, truncated, done, infos, restarting
        )

    def step_one(self, action):
        """DriveEnv's step of its one world through the compiled step (``_fused`` ready, no
        autoreset): ``(observation, reward, terminated, truncated, info)`` as DriveEnv returns them
        from ``step``, the world's info made directly (``world_info`` of the infos ``step`` gives)."""
        fused = self._fused
        observations, out, flags = fused.step(self.adapter.to_controls(np.asarray(action)[None]))
        self._batch, self._batch_deferred = None, True
        self.observations = observations
        info, reward, terminated, truncated = fused.world_step(out, flags)
        if terminated or truncated:
            has_goal = self.scenario.arrival != "none"
            info["episode_metrics"] = self.metrics.summaries([True], has_goal, np.array([truncated]))[0]
        info["traffic_light"] = _LABEL_OF_STATE[0]
        return observations[0], reward, terminated, truncated, info

    def _finish_step(self, observations, rewards, terminated, truncated, done, infos, restarting):
        """The end of a step: SAME_STEP's resets of the finished worlds, or NEXT_STEP's pending ones."""
        if self.autoreset_mode == AutoresetMode.SAME_STEP and np.count_nonzero(done):
            infos["final_obs"] = _rows_as_objects(observations, done)
            infos["final_info"] = _final_infos(infos, done)
            infos["_final_obs"] = infos["_final_info"] = done.copy()
            self._start(done)
            observations = self._observe_again(observations, self.batch, np.flatnonzero(done))
            infos["episode_seed"] = self.episode_seeds.copy()
            infos["_episode_seed"] = done | restarting
            infos["traffic_light"] = self.traffic_light_labels()
            self.pending_reset[:] = False
        elif self.autoreset_mode == AutoresetMode.NEXT_STEP:
            self.pending_reset = done
        self.observations = observations
        return observations, rewards, terminated, truncated, infos

    def _step_infos(
        self, terms: dict[str, np.ndarray], speed, crashed, off_road, arrived, done, truncated
    ) -> dict:
        """Per-world arrays: reward terms, speed, events (the arrays given are the infos' own), and
        the finished worlds' episode metrics."""
        every = np.ones(self.num_envs, dtype=bool)
        infos = {
            "reward_terms": dict(terms),
            "speed_mps": speed,
            "crashed": crashed,
            "off_road": off_road,
            "arrived": arrived,
            "_reward_terms": every,
            "_speed_mps": every,
            "_crashed": every,
            "_off_road": every,
            "_arrived": every,
        }
        if np.count_nonzero(done):
            summaries = self.metrics.summaries(done, self.scenario.arrival != "none", truncated)
            metrics = np.empty(self.num_envs, dtype=object)
            for k, summary in zip(np.flatnonzero(done), summaries, strict=True):
                metrics[k] = summary
            infos["episode_metrics"], infos["_episode_metrics"] = metrics, done.copy()
        return infos

    def traffic_light_labels(self) -> np.ndarray:
        """(K,) "none", "green" or "red_or_yellow": the light ahead within 18 m (RLAD's label)."""
        if not self.batch.traffic_lights.shape[1]:  # no lights in any world: no search
            return self._no_light_labels.copy()
        state, _ = self.batch.light_ahead(LIGHT_LABEL_DISTANCE_M)
        return _LABEL_OF_STATE[state + 1]

    def replay(self, starts: list[dict], actions: list[np.ndarray]):
        """Bring every world to where its recorded episode was: world k's episode-seed generator
        set to ``starts[k]`` (a bit-generator state), its episode started, then ``actions[k]``
        taken. Worlds are independent, so each starts late enough to end with the others (before
        that it drives an episode its reset discards). Returns the observations, as after a step."""
        lengths = np.array([len(a) for a in actions])
        total = int(lengths.max(initial=0))
        begin = total - lengths
        observations, _ = self.reset()
        for t in range(total + 1):
            starting = np.flatnonzero(begin == t)
            if len(starting):
                for k in starting:
                    self.world_rngs[k].bit_generator.state = starts[k]
                self._start(begin == t)  # and the first observation of those worlds, as reset gives it
                observations = self._observe_again(observations, self.batch, starting)
            if t == total:
                return observations
            step_actions = [
                np.asarray(actions[k][t - begin[k]]) if t >= begin[k] else self.single_action_space.sample()
                for k in range(self.num_envs)
            ]
            observations, _, terminated, truncated, _ = self.step(np.stack(step_actions))
            self.pending_reset[:] = False
            if ((terminated | truncated) & (begin <= t)).any():
                raise UsageError(
                    "the checkpoint's episode ends early when replayed (the environment changed?)"
                )
        return observations

    # --- rendering -----------------------------------------------------------------------------
    def render(self) -> tuple[np.ndarray, ...] | None:
        """One RGB frame per world, drawn as drivelab's videos draw their scenes (``render_world``)."""
        if self.batch is None or self.render_mode != "rgb_array":
            return None
        return tuple(self.render_world(k) for k in range(self.num_envs))

    def render_world(self, k: int) -> np.ndarray:
        """World ``k``'s scene as the videos' camera sees it (``envs/video.py``): landscape along the
        road, the ego a third of the way in (256×720, 103 m × 37 m), or, in the town and on the
        block maps, the map from above, north up (432×720, 240 m × 144 m)."""
        return draw_scene(self.batch.select(np.array([k])), camera_for(self.scenario))[0]


def _copy(observations):
    if isinstance(observations, dict):
        return {name: value.copy() for name, value in observations.items()}
    return observations.copy()


def _rows_as_objects(observations, mask: np.ndarray) -> np.ndarray:
    """(K,) object array holding each masked world's own observation (copied), gymnasium's layout
    of ``final_obs``."""
    rows = np.empty(len(mask), dtype=object)
    for k in np.flatnonzero(mask):
        if isinstance(observations, dict):
            rows[k] = {name: value[k].copy() for name, value in observations.items()}
        else:
            rows[k] = observations[k].copy()
    return rows


def _final_infos(infos: dict, mask: np.ndarray) -> np.ndarray:
    """(K,) object array of each finished world's own step info as a plain dict: its ``world_info``
    and its ``final_obs`` (a Python number for a discrete observation)."""
    rows = np.empty(len(mask), dtype=object)
    for k in np.flatnonzero(mask):
        final_obs = infos["final_obs"][k]
        final_obs = final_obs.item() if isinstance(final_obs, np.generic) else final_obs
        rows[k] = {**world_info(infos, k), "final_obs": final_obs}
    return rows


def world_info(infos: dict, k: int) -> dict:
    """World ``k``'s entries of gymnasium-style vector infos, as one plain dict (numbers as Python
    numbers: ``ndarray.item(k)`` of the (K,) arrays, cheaper than indexing then converting)."""
    info = {}
    for key, value in infos.items():
        if key[0] == "_" or key == "final_obs" or key == "final_info":
            continue
        if key == "reward_terms":
            info[key] = {name: v.item(k) for name, v in value.items()}
            continue
        mask = infos.get("_" + key)
        if mask is None or mask[k]:
            if value.ndim == 1:
                info[key] = value.item(k)
            else:
                item = value[k]
                info[key] = item.item() if isinstance(item, np.generic) else item
    return info


def check_reset_options(options) -> None:
    """A TypeError naming what ``reset``'s ``options`` must be (gymnasium's: a dict or None)."""
    if options is not None and not isinstance(options, dict):
        raise TypeError(
            f"reset options must be a dict (e.g. {{'episode_seed': 3}}) or None, "
            f"got {type(options).__name__} {options!r}"
        )


def _episode_seeds(options: dict | None, count: int) -> np.ndarray | None:
    """``options["episode_seeds"]`` as (K,) int64, checked; None when not given. Each must lie in
    [0, 2**63): an episode seed is an int64 (the simulators' and the infos' arrays), so a wider one
    would wrap to a negative number, another episode than the one asked for."""
    if not options or options.get("episode_seeds") is None:
        return None
    seeds = np.asarray(options["episode_seeds"])
    integers = np.issubdtype(seeds.dtype, np.integer)
    if (
        seeds.shape != (count,)
        or not integers
        or (seeds < 0).any()
        or (seeds.dtype.kind == "u" and (seeds > np.iinfo(np.int64).max).any())
    ):
        raise UsageError(
            f"reset option episode_seeds must be integers in [0, 2**63), one per world ({count}), "
            f"got {options['episode_seeds']!r}"
        )
    return seeds.astype(np.int64)
