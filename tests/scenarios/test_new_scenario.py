"""Adding a scenario is adding one folder and one registry line (docs/architecture.md, "Adding a
scenario"): the page's toy scenario written as a package in a temporary folder, with its preset, its road
described as blocks and its spawn hook, registered by one entry in ``SCENARIOS``, is driven by
``drivelab.make`` and ``VectorDriveEnv`` on the compiled core like any shipped scenario."""

from __future__ import annotations

import importlib
import sys
from pathlib import Path

import numpy as np
import pytest

import drivelab
from drivelab.envs.vector import VectorDriveEnv
from drivelab.errors import UsageError
from drivelab.scenarios import SCENARIOS, options_table

ARCHITECTURE = Path(__file__).resolve().parents[2] / "docs" / "architecture.md"


def documented_oval() -> str:
    """The example folder's ``__init__.py``: the python block of architecture.md's "Adding a
    scenario" (the test runs what the page shows)."""
    section = ARCHITECTURE.read_text(encoding="utf-8").split("## Adding a scenario", 1)[1]
    return section.split("```python\n", 1)[1].split("```", 1)[0]


@pytest.fixture
def oval(tmp_path, monkeypatch):
    folder = tmp_path / "toy_scenarios" / "oval"
    folder.mkdir(parents=True)
    (folder.parent / "__init__.py").write_text("")
    (folder / "__init__.py").write_text(documented_oval())
    monkeypatch.syspath_prepend(str(tmp_path))
    module = importlib.import_module("toy_scenarios.oval")
    monkeypatch.setitem(SCENARIOS, "oval", module.SCENARIO)  # the registry line
    yield module.SCENARIO
    for name in ("toy_scenarios.oval", "toy_scenarios"):
        sys.modules.pop(name, None)


def test_a_new_folder_and_registry_line_make_a_scenario(oval):
    env = drivelab.make("oval", obs="kinematics", action="meta", reward="highway")
    obs, info = env.reset(seed=3)
    assert obs.shape == env.observation_space.shape
    assert type(env.unwrapped.vector.simulator).__name__ == "FastSimulator"  # the default simulator
    world = env.unwrapped.vector.batch
    assert int(world.vehicle_valid[0].sum()) == 3  # the three cars besides the ego
    start, speeds = world.ego[0].position.copy(), []
    for _ in range(15):  # IDLE at 4 m/s: the meta ego follows its lane around the oval behind the cars
        obs, reward, terminated, truncated, info = env.step(1)
        assert np.isfinite(reward) and obs.shape == env.observation_space.shape
        assert not (terminated or truncated or info["crashed"] or info["off_road"])
        speeds.append(info["speed_mps"])
    assert np.allclose(speeds, 4.0, atol=0.05)
    assert np.linalg.norm(env.unwrapped.vector.batch.ego[0].position - start) > 10.0  # round a bend
    env.close()


def test_toy_scenario_options_and_batched_worlds_equal_single_worlds(oval):
    names = [row["name"] for row in options_table("oval")]
    assert {"cars", "speed_limit", "simulation_frequency", "policy_frequency"} <= set(names)
    with pytest.raises(UsageError, match="cars"):
        drivelab.make("oval", backend_options={"cars": -1})
    batched = VectorDriveEnv(3, "oval", obs="kinematics", action="meta", traffic="regular")
    obs, _ = batched.reset(seed=[5, 6, 7])
    singles = [drivelab.make("oval", obs="kinematics", action="meta", traffic="regular") for _ in range(3)]
    firsts = [env.reset(seed=s)[0] for env, s in zip(singles, [5, 6, 7], strict=True)]
    np.testing.assert_array_equal(obs, np.stack(firsts))
    for step in range(12):  # IDLE, SLOWER and lane changes behind the slower cars: no episode ends
        actions = np.array([1, 4 if step % 3 else 1, 0 if step == 2 else 2 if step == 6 else 1])
        obs, rewards, terminated, truncated, _ = batched.step(actions)
        one = [env.step(int(a)) for env, a in zip(singles, actions, strict=True)]
        np.testing.assert_array_equal(obs, np.stack([o[0] for o in one]))
        np.testing.assert_array_equal(rewards, [o[1] for o in one])
        assert not (terminated.any() or truncated.any())
