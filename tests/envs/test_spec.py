"""EnvSpec: one environment spec built once from the user's keywords and shared by DriveEnv,
VectorDriveEnv and a run's config; MetaDrive's scenario options at the top level of ``make`` and
of a run's YAML."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import drivelab
from drivelab.config import ENV_FIELDS, FIELDS, build_config
from drivelab.envs.spec import ENV_KEYWORDS, EnvSpec
from drivelab.envs.vector import VectorDriveEnv
from drivelab.errors import UsageError

MAPS = {"map": "OSX", "num_scenarios": 3, "start_seed": 0, "traffic_density": 0.1}


def test_metadrive_keys_at_the_top_level_equal_backend_options():
    top = drivelab.make("blocks", obs="lidar", action="continuous", **MAPS)
    nested = drivelab.make("blocks", obs="lidar", action="continuous", backend_options=MAPS)
    assert top.vector.env_spec == nested.vector.env_spec
    assert top.vector.env_spec.backend_options == MAPS
    first, second = top.reset(seed=4)[0], nested.reset(seed=4)[0]
    np.testing.assert_array_equal(first, second)
    action = np.array([0.5, 0.0], dtype=np.float32)
    for _ in range(5):
        np.testing.assert_array_equal(top.step(action)[0], nested.step(action)[0])


def test_the_spec_resolves_once_and_refuses_what_it_does_not_know():
    spec = EnvSpec.build(scenario="drivelab/Highway-v0", obs="lidar", lanes_count=3)
    assert spec.scenario == "highway" and spec.backend_options == {"lanes_count": 3}
    assert spec.offroad_terminal is True and spec.keywords()["obs"] == "lidar"
    assert EnvSpec.build() == EnvSpec()  # the defaults
    with pytest.raises(UsageError, match="keyword 'lane_count' \\(did you mean 'lanes_count'"):
        EnvSpec.build(scenario="highway", lane_count=3)
    with pytest.raises(UsageError, match="'map' given twice"):
        EnvSpec.build(scenario="blocks", map="OSX", backend_options={"map": "SSS"})
    with pytest.raises(UsageError, match="duration_s must be a number of seconds > 0"):
        EnvSpec.build(duration_s=-1)
    with pytest.raises(dataclasses.FrozenInstanceError):
        spec.obs = "topdown"


def test_one_spec_builds_the_same_worlds_batched_and_alone():
    spec = EnvSpec.build(scenario="merge", obs="kinematics", traffic="dense", duration_s=8)
    batched = VectorDriveEnv(2, env_spec=spec)
    alone = drivelab.make("merge", env_spec=spec)
    assert batched.env_spec is spec and alone.vector.env_spec is spec and alone.duration_s == 8
    np.testing.assert_array_equal(batched.reset(seed=[3, 9])[0][0], alone.reset(seed=3)[0])
    with pytest.raises(UsageError, match="keywords or its spec, not both"):
        VectorDriveEnv(2, env_spec=spec, obs="lidar")


def test_a_runs_fields_are_the_specs_keywords_by_name():
    """RunConfig builds its env from the fields the spec shares with it (``env`` is the scenario);
    ``env_options`` may give every other spec keyword, and no field twice."""
    assert set(ENV_FIELDS.values()) <= set(ENV_KEYWORDS) and ENV_FIELDS["env"] == "scenario"
    assert {"obs", "action", "reward", "traffic", "backend"} <= set(ENV_FIELDS) <= set(FIELDS)
    config = build_config({"algo": "ppo", "env": "blocks", "map": "OSX", "num_scenarios": 2})
    assert config.env_options == {"backend_options": {"map": "OSX", "num_scenarios": 2}}
    spec = EnvSpec.build(**config.env_kwargs())
    assert spec.scenario == "blocks" and spec.backend_options["map"] == "OSX"
    with pytest.raises(UsageError, match="unknown env_options key 'obs'"):
        build_config({"algo": "ppo", "env_options": {"obs": "lidar"}})
    with pytest.raises(UsageError, match="given twice"):
        inside = {"backend_options": {"map": "S"}}
        build_config({"algo": "ppo", "env": "blocks", "map": "OSX", "env_options": inside})
    with pytest.raises(UsageError, match="unknown config field 'map'"):  # not an option of the highway
        build_config({"algo": "ppo", "env": "highway", "map": "OSX"})
