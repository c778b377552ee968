"""RunConfig: everything that defines a training run, validated once at the boundary."""

from __future__ import annotations

import dataclasses
import hashlib
import json
import unicodedata
from dataclasses import dataclass, field
from pathlib import Path

from drivelab.envs.spec import ENV_KEYWORDS, check_env_options
from drivelab.errors import UsageError, like_default
from drivelab.scenarios import SCENARIOS, scenario_name
from drivelab.yaml_io import dump_yaml


@dataclass(frozen=True)
class RunConfig:
    """A training run. Loaded from YAML and CLI options; written resolved into the run directory.

    :param algo: registered algorithm name (``drivelab envs`` lists them).
    :param env: scenario name.
    :param obs: sensor specs, e.g. ``["lidar:beams=120", "topdown"]``.
    :param action: action kind ("meta", "grid", "continuous").
    :param reward: reward preset or ``term=weight`` list.
    :param traffic: "empty", "regular" or "dense".
    :param backend: "auto" (the default: fast where it runs the scenario, else highway), "fast"
        (drivelab's compiled port of highway-env's traffic model) or "highway" (highway-env itself).
    :param steps: total environment steps to train for.
    :param seed: seeds the agent, the environments and evaluation.
    :param eval_every: environment steps between periodic evaluations (0: five over the run).
    :param eval_episodes: episodes per periodic evaluation.
    :param eval_video: record one episode of each periodic evaluation.
    :param checkpoint_every: environment steps between checkpoints (0: ten over the run).
    :param hyperparams: algorithm keyword overrides (e.g. ``{"learning_rate": 1e-3}``).
    :param env_options: extra DriveEnv keywords (``duration_s``, ``action_options``, ...).
    :param n_envs: worlds stepped together while training.
    :param eval_maps: procedural maps only (``blocks``): ``"START:COUNT"``, evaluation on the maps
        of seeds START … START + COUNT − 1 instead of the training set (e.g. ``"1000:100"``).
    :param init_from: a run directory or shipped agent whose policy weights start this run (an
        imitation policy fine-tuned by PPO or A2C); a resume starts from the run's own checkpoint.
    """

    algo: str
    env: str = "highway"
    obs: tuple[str, ...] = ("kinematics",)
    action: str = "meta"
    reward: str = "highway"
    traffic: str = "regular"
    backend: str = "auto"
    steps: int = 10_000
    seed: int = 0
    name: str | None = None
    eval_every: int = 0
    eval_episodes: int = 5
    eval_video: bool = False
    checkpoint_every: int = 0
    hyperparams: dict = field(default_factory=dict)
    env_options: dict = field(default_factory=dict)
    n_envs: int = 1
    eval_maps: str | None = None
    init_from: str | None = None

    def env_kwargs(self) -> dict:
        """Keyword arguments of DriveEnv for this run: its environment fields (``ENV_FIELDS``), then
        ``env_options``."""
        fields = {keyword: getattr(self, name) for name, keyword in ENV_FIELDS.items()}
        return {**fields, "obs": list(self.obs), **self.env_options}

    def eval_env_kwargs(self) -> dict:
        """DriveEnv keyword arguments for evaluating this run: as for training, except that a
        scenario that gives new targets while training (the town) ends its episodes on arrival."""
        kwargs = self.env_kwargs()
        if SCENARIOS[self.env].config.get("retarget"):
            kwargs["backend_options"] = {**(kwargs.get("backend_options") or {}), "retarget": False}
        if self.eval_maps is not None:
            start, count = parse_maps(self.eval_maps)
            options = {"start_seed": start, "num_scenarios": count}
            kwargs["backend_options"] = {**(kwargs.get("backend_options") or {}), **options}
        return kwargs

    def to_dict(self) -> dict:
        return {**dataclasses.asdict(self), "obs": list(self.obs)}

    def identity(self) -> str:
        """Hash of everything but the step budget and name: what a checkpoint must match."""
        data = {k: v for k, v in self.to_dict().items() if k not in ("steps", "name")}
        if data["n_envs"] == 1:  # runs made before the field existed keep their identity
            del data["n_envs"]
        for optional in ("eval_maps", "init_from"):  # runs made before the fields keep their identity
            if data[optional] is None:
                del data[optional]
        return hashlib.sha256(json.dumps(data, sort_keys=True, default=str).encode()).hexdigest()[:16]

    @property
    def resolved_eval_every(self) -> int:
        return self.eval_every or max(self.steps // 5, 1)

    @property
    def resolved_checkpoint_every(self) -> int:
        return self.checkpoint_every or max(self.steps // 10, 1)


FIELDS = {f.name: f for f in dataclasses.fields(RunConfig)}
# the run's fields that are environment keywords (EnvSpec's), by their EnvSpec name: ``env`` is
# the scenario; ``env_options`` may give the other keywords
ENV_FIELDS = {"env": "scenario", **{name: name for name in FIELDS if name in ENV_KEYWORDS}}
MAX_SEED = 2**31 - 1  # plus evaluation offsets and episode numbers, still below numpy's 2**32 limit
# Budgets no run can reach (benchmarks/results/batch_speed.md: about 190 k steps/s at best).
MAXIMA = {
    "steps": (10**12, "more steps than any machine trains in months (the fastest world steps ~2e5 a second)"),
    "n_envs": (2**16, "more worlds than one process steps (one vector step of 65,536 worlds takes ~1 s)"),
    "eval_episodes": (100_000, "more evaluation episodes than any report uses (the leaderboard's: 100)"),
}
_EXAMPLES = {"int": 0, "str": "", "bool": False, "dict": {}}  # a value of each field type, by its name


def parse_maps(value: str) -> tuple[int, int]:
    """``"START:COUNT"`` → (start, count): integers, start >= 0, count >= 1, and every map seed
    START … START + COUNT − 1 at most ``MAX_SEED``, as a run's seed (a set of 10^14 maps, of which
    an evaluation plays a handful, is a typing slip, not a map set)."""
    start, colon, count = str(value).partition(":")
    try:
        start_seed, number = int(start), int(count)
    except ValueError:
        start_seed, number = -1, 0
    if not colon or start_seed < 0 or number < 1:
        raise UsageError(f"eval_maps must be START:COUNT (start >= 0, count >= 1), got {value!r}")
    if start_seed + number - 1 > MAX_SEED:
        raise UsageError(
            f"eval_maps {value!r} names map seeds up to {start_seed + number - 1}: map seeds, as run seeds, "
            f"are at most {MAX_SEED}"
        )
    return start_seed, number


def _check_type(name: str, value):
    """Coerce/validate one field; the error names the field."""
    if value is None and name in ("name", "eval_maps", "init_from"):
        return None
    if name == "eval_maps":
        parse_maps(value)
        return str(value)
    if name == "obs":
        if isinstance(value, str):
            value = [v.strip() for v in value.split(",") if v.strip()]
        if not isinstance(value, (list, tuple)) or not value:
            raise UsageError("config field 'obs' must be a sensor name or a non-empty list of them")
        return tuple(v if isinstance(v, str) else _sensor_dict_to_spec(v) for v in value)
    if name == "reward" and isinstance(value, (int, float)):  # a YAML weight list read as a number
        return str(value)
    value = like_default(
        value, _EXAMPLES.get(str(FIELDS[name].type).split(" ")[0], ""), f"config field {name!r}"
    )
    if name == "name":
        return check_run_name(value)
    if name == "seed" and not 0 <= value <= MAX_SEED:
        raise UsageError(f"config field 'seed' must be between 0 and {MAX_SEED}, got {value}")
    if name == "env_options":
        check_env_options(value, taken=frozenset(ENV_FIELDS.values()))
    if name in ("steps", "eval_episodes", "n_envs") and value < 1:
        raise UsageError(f"config field {name!r} must be >= 1, got {value}")
    if name in MAXIMA and value > MAXIMA[name][0]:
        limit, why = MAXIMA[name]
        raise UsageError(f"config field {name!r} must be at most {limit:,}, got {value:,}: {why}")
    if name in ("eval_every", "checkpoint_every") and value < 0:
        raise UsageError(f"config field {name!r} must be >= 0, got {value}")
    return value


MAX_NAME_BYTES = 255  # the longest file name of Linux, macOS and Windows file systems
# Unicode categories a run name may not hold: controls, formats (bidirectional, zero-width), line and
# paragraph separators, and surrogates (command-line bytes that were not UTF-8).
UNSEEN_CATEGORIES = ("Cc", "Cf", "Zl", "Zp", "Cs")


def check_run_name(name: str) -> str:
    """``name`` if it is one path component (the run directory inside ``--runs-dir``): not empty,
    not ``.`` or ``..``, without ``/``, ``\\`` or NUL, at most ``MAX_NAME_BYTES`` in UTF-8 and
    without characters of ``UNSEEN_CATEGORIES``, so that every file system holds it and every
    listing shows it as it is."""
    if not name or name in (".", "..") or any(char in name for char in "/\\\0"):
        raise UsageError(f"run name {name!r} must be a single directory name (no '/', not '.' or '..')")
    hidden = next((char for char in name if unicodedata.category(char) in UNSEEN_CATEGORIES), None)
    if hidden is not None:
        raise UsageError(
            f"run name {name!r} must hold only visible characters, not U+{ord(hidden):04X} "
            f"({unicodedata.name(hidden, unicodedata.category(hidden))}): a control, format (bidirectional, "
            "zero-width), line or paragraph separator, or a byte that is not UTF-8"
        )
    size = len(name.encode("utf-8", errors="surrogatepass"))
    if size > MAX_NAME_BYTES:
        raise UsageError(f"run name {name[:20]!r}... is {size} bytes long (at most {MAX_NAME_BYTES} bytes)")
    return name


def _sensor_dict_to_spec(entry) -> str:
    if not isinstance(entry, dict) or "name" not in entry:
        raise UsageError(f"config field 'obs' has an entry that is not a sensor: {entry!r}")
    options = ":".join(f"{k}={v}" for k, v in entry.items() if k != "name")
    return f"{entry['name']}:{options}" if options else str(entry["name"])


def build_config(values: dict) -> RunConfig:
    """A RunConfig from a dict, rejecting unknown fields and wrong types with a one-line error. The
    scenario's options may stand at the top level, as MetaDrive's users write them (``map: OSX``):
    they join ``env_options.backend_options``."""
    if isinstance(values.get("env"), str):  # a gymnasium id (drivelab/Highway-v0) names its scenario
        values = {**values, "env": scenario_name(values["env"])}
    scenario = SCENARIOS.get(values.get("env", RunConfig.env))
    values = _scenario_options_inside(values, scenario)
    unknown = sorted(set(values) - set(FIELDS), key=str)  # a YAML key may be a number
    if unknown:
        raise UsageError(f"unknown config field {unknown[0]!r} (known: {', '.join(FIELDS)})")
    if "algo" not in values:
        raise UsageError("config has no 'algo' (give --algo or algo: in the YAML)")
    if scenario is not None:  # an unknown one is reported when the env is built
        values = {"action": scenario.action_kinds[0], "reward": scenario.default_reward, **values}
    config = RunConfig(**{k: _check_type(k, v) for k, v in values.items()})
    if config.eval_maps is not None and config.env in SCENARIOS and not SCENARIOS[config.env].procedural_maps:
        raise UsageError(f"eval_maps is for procedural maps (blocks); {config.env!r} has one road")
    _check_scenario_options(config)
    return config


def _scenario_options_inside(values: dict, scenario) -> dict:
    """``values`` with the scenario's options given at the top level moved into
    ``env_options.backend_options`` (one given in both places is a UsageError)."""
    declared = {option.name for option in scenario.options} if scenario is not None else set()
    top = {key: values[key] for key in values if key not in FIELDS and key in declared}
    if not top:
        return values
    env_options = values.get("env_options") or {}
    inside = env_options.get("backend_options") if isinstance(env_options, dict) else None
    if not isinstance(env_options, dict) or (inside is not None and not isinstance(inside, dict)):
        return values  # reported by the field's own check
    for key in set(top) & set(inside or {}):
        raise UsageError(f"option {key!r} given twice: at the top level and in env_options.backend_options")
    rest = {key: value for key, value in values.items() if key not in top}
    return {**rest, "env_options": {**env_options, "backend_options": {**(inside or {}), **top}}}


def _check_scenario_options(config: RunConfig) -> None:
    """The run's scenario options (``env_options.backend_options``, and the road and traffic keys
    of a highway-env ``env_options.config``) checked against the scenario's declarations, before
    anything is written; the env checks them again when it is built."""
    scenario = SCENARIOS.get(config.env)
    options = config.env_options.get("backend_options")
    highway_config = config.env_options.get("config")
    if scenario is None or (options is not None and not isinstance(options, dict)):
        return  # an unknown scenario or a malformed mapping is reported when the env is built
    from drivelab.envs.actions import ACTIONS
    from drivelab.envs.highway_config import env_kwargs_from_config
    from drivelab.scenarios.options import check_backend_options

    if isinstance(highway_config, dict):
        translated = env_kwargs_from_config(highway_config, scenario.name)
        options = {**translated.get("backend_options", {}), **(options or {})}
    control = getattr(ACTIONS.get(config.action), "control", "continuous")
    check_backend_options(scenario, options, config.traffic, control)


def check_eval_every(config: RunConfig) -> None:
    """A UsageError when ``eval_every`` is larger than ``steps``: a new run would never evaluate.
    Checked for new runs only, so that an existing run's config.yaml stays readable."""
    if config.eval_every > config.steps:
        raise UsageError(
            f"config field 'eval_every' ({config.eval_every}) is larger than 'steps' ({config.steps}): "
            f"no periodic evaluation would run; give at most {config.steps}, or 0 for five over the run"
        )


def check_steps(config: RunConfig) -> None:
    """A UsageError when ``steps`` is fewer than the algorithm trains in one go
    (``steps_per_update``: a PPO rollout of ``n_steps`` × ``n_envs``), which would train more
    steps than config.yaml says. Checked for new runs, as ``check_eval_every``."""
    fewest, what = steps_per_update(config.algo, config.hyperparams, config.n_envs)
    if config.steps < fewest:
        raise UsageError(
            f"config field 'steps' ({config.steps}) is fewer than {config.algo!r} trains at once, {what} = "
            f"{fewest} steps: give steps >= {fewest}, or fewer worlds (n_envs) or a shorter rollout (n_steps)"
        )


def steps_per_update(algo: str, hyperparams: dict, n_envs: int) -> tuple[int, str]:
    """(the fewest environment steps a run of ``algo`` in ``n_envs`` worlds takes, what they are):
    a whole rollout for an on-policy algorithm, one step of every world for the others."""
    from drivelab.agents.registry import get_algo
    from drivelab.agents.sb3_params import _given_or_default

    spec = get_algo(algo)
    if not spec.on_policy:
        return n_envs, f"one step of each of its {n_envs} worlds"
    if spec.family == "sb3":  # the values build_sb3 gives the model: the shipped default entry's
        from drivelab.hyperparams import shipped_hyperparams

        n_steps = _given_or_default(algo, {**shipped_hyperparams(algo, "default"), **hyperparams}, "n_steps")
    else:
        n_steps = hyperparams.get("n_steps", spec.agent_class().config_class.n_steps)
    n_steps = int(n_steps)
    return n_steps * n_envs, f"one rollout of n_steps {n_steps} x n_envs {n_envs}"


def save_yaml(config: RunConfig, path: Path) -> None:
    path.write_text(dump_yaml(config.to_dict()))
