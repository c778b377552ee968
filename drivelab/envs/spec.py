"""EnvSpec: what one driving environment is, built once from the user's keywords and shared by
``DriveEnv``, ``VectorDriveEnv`` and a training run's config."""

from __future__ import annotations

import dataclasses
import difflib
from dataclasses import dataclass
from typing import Any

from drivelab.envs.actions import ActionAdapter
from drivelab.envs.highway_config import env_kwargs_from_config
from drivelab.errors import UsageError
from drivelab.scenarios import get_scenario


@dataclass(frozen=True)
class EnvSpec:
    """The keywords of a driving environment (``drivelab.make``, ``gymnasium.make``, ``DriveEnv``,
    ``VectorDriveEnv``), resolved and checked once by :meth:`build`.

    :param scenario: a name of ``drivelab.scenarios.SCENARIOS`` (highway, merge, roundabout,
        intersection, racetrack, town, follow-line, follow-lane, blocks) or its gymnasium id.
    :param obs: a sensor spec (``"lidar"``, ``"lidar:beams=120:stack=3"``), a comma list, or a
        list of specs (default ``kinematics``). One sensor gives its Box; several give a Dict keyed
        by sensor name.
    :param action: an action kind (``drivelab.envs.actions.ACTIONS``) or an ActionAdapter; default
        the scenario's first (``meta`` on the highway scenarios, ``seed_line`` on follow-line, …),
        as ``drivelab train`` picks it.
    :param reward: a preset, ``"term=w,…"``, ``"preset,term=w"`` or a dict of weights; default the
        scenario's preset (``roach`` in the town, ``line_follow`` on follow-line, …).
    :param traffic: "empty", "regular" or "dense".
    :param backend: "auto" (the compiled core where it runs the scenario, else highway), "fast"
        (drivelab's compiled port of highway-env's traffic model: step for step the same episodes,
        many times faster, see benchmarks/results/backend_speed.md) or "highway" (highway-env
        itself, the reference).
    :param duration_s: episode time limit; default the scenario's (in the town with fixed routes,
        the route's NoCrash limit; a given duration caps it).
    :param offroad_terminal: end the episode when the ego leaves the road (default true).
    :param action_options: keyword options of the action adapter (e.g. ``steer_levels``).
    :param backend_options: the scenario's options (``Scenario.options``: road, traffic and
        timing keys, highway-env's and MetaDrive's names); an unknown key, a bad value or a
        contradiction is a UsageError. They may also be given at the top level, as MetaDrive's
        users write them: ``drivelab.make("blocks", map="OSX", num_scenarios=100)``.
    """

    scenario: str = "highway"
    obs: str | list | tuple = "kinematics"
    action: str | ActionAdapter | None = None
    reward: str | dict | None = None
    traffic: str = "regular"
    backend: str = "auto"
    duration_s: float | None = None
    offroad_terminal: bool = True
    action_options: dict | None = None
    backend_options: dict | None = None

    @classmethod
    def build(cls, config: dict | None = None, **keywords: Any) -> EnvSpec:
        """The spec of ``keywords`` (None: the default). ``config``, a highway-env config dict as its
        users write it (``envs/highway_config.py``), is translated first; keywords given beside it
        win. A keyword that is none of the spec's fields but one of the scenario's options joins
        ``backend_options``."""
        keywords = {key: value for key, value in keywords.items() if value is not None}
        scenario = get_scenario(keywords.get("scenario", cls.scenario))
        names = {f.name for f in dataclasses.fields(cls)}
        options = {key: keywords.pop(key) for key in list(keywords) if key not in names}
        declared = {option.name for option in scenario.options}
        for key in options:
            if key not in declared:
                known = sorted(names | declared | {"config"})
                close = difflib.get_close_matches(key, known, n=1)
                hint = f"did you mean {close[0]!r}?" if close else f"known: {', '.join(known)}"
                raise UsageError(f"unknown environment keyword {key!r} ({hint})")
        if options:
            given = keywords.get("backend_options")
            if given is not None and not isinstance(given, dict):
                raise UsageError(f"backend_options must be a mapping of options, got {given!r}")
            for key in set(options) & set(given or {}):
                raise UsageError(f"option {key!r} given twice: at the top level and in backend_options")
            keywords["backend_options"] = {**(given or {}), **options}
        if config is not None:
            given = {key: value for key, value in keywords.items() if key != "scenario"}
            keywords = {**keywords, **env_kwargs_from_config(config, scenario.name, **given)}
        spec = cls(**{**keywords, "scenario": scenario.name})
        spec.check()
        return spec

    def check(self) -> None:
        """The types and ranges of the option keywords, as one-line UsageErrors (the scenario, the
        sensors, the action and the reward are checked by the parts they build)."""
        duration_s = self.duration_s
        if duration_s is not None and (
            isinstance(duration_s, bool)
            or not isinstance(duration_s, (int, float))
            or not 0 < duration_s < float("inf")
        ):
            raise UsageError(f"duration_s must be a number of seconds > 0, got {duration_s!r}")
        if not isinstance(self.offroad_terminal, bool):
            raise UsageError(f"offroad_terminal must be true or false, got {self.offroad_terminal!r}")
        for name in ("action_options", "backend_options"):
            value = getattr(self, name)
            if value is not None and not isinstance(value, dict):
                raise UsageError(f"{name} must be a mapping of options, got {value!r}")

    def keywords(self) -> dict[str, Any]:
        """The spec as keyword arguments (``DriveEnv(**spec.keywords())`` builds it again)."""
        return {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}


ENV_KEYWORDS = tuple(f.name for f in dataclasses.fields(EnvSpec))


def check_env_options(options: dict, taken: set[str] | frozenset[str] = frozenset()) -> None:
    """A training run's ``env_options``: spec keywords (and ``config``) other than those the run's
    own fields give (``taken``); an unknown key is a UsageError naming the known ones (values are
    checked when the spec is built)."""
    known = tuple(name for name in (*ENV_KEYWORDS, "config") if name not in taken)
    for key in options:
        if key not in known:
            raise UsageError(f"unknown env_options key {key!r} (known: {', '.join(known)})")
