"""``drivelab.load``: a run directory or a shipped agent as a model with SB3's ``predict`` that
drives as ``drivelab evaluate`` and ``drivelab enjoy`` measured it."""

import numpy as np
import pytest

import drivelab
from drivelab.errors import UsageError
from drivelab.training import run as run_module
from drivelab.training import zoo
from drivelab.training.evaluate import aggregate, evaluate_run, run_episodes
from tests.training.tiny_runs import met_observations, tiny_config

pytestmark = pytest.mark.usefixtures("one_torch_thread")


def _drive(model, episodes: int) -> dict:
    """The metrics of ``model`` driving the fixed evaluation episodes of its environment."""
    policy = lambda obs: model.predict(obs)[0]  # noqa: E731
    return aggregate(run_episodes(policy, model.make_env(), episodes)[0])


def test_load_a_run_drives_as_drivelab_evaluate_measured_it(tmp_path):
    run_dir = run_module.train(tiny_config(), tmp_path)
    model = drivelab.load(run_dir)
    assert (model.algo, model.num_timesteps, model.run_dir, model.name) == ("ppo", 128, run_dir, None)
    assert model.config.steps == 128 and model.config.traffic == "empty"
    report = evaluate_run(run_dir, episodes=2)
    driven = _drive(model, 2)
    assert driven == {key: report[key] for key in driven}
    single = [model.predict(obs)[0] for obs in met_observations(model.make_env(), 12)]
    batch, state = model.predict(np.stack(met_observations(model.make_env(), 12)))
    assert state is None and batch.shape == (12,)
    assert batch.tolist() == [int(action) for action in single]
    assert all(model.action_space.contains(action) for action in single)


def test_load_a_zoo_name_drives_as_drivelab_enjoy(tmp_path):
    agent = {a.name: a for a in zoo.shipped_agents()}["highway-ppo"]
    model = drivelab.load("highway-ppo")
    assert model.name == "highway-ppo" and model.run_dir == agent.path
    assert (model.algo, model.config.env) == (agent.card["algo"], agent.card["env"])
    assert model.num_timesteps == agent.card["training"]["steps"]
    enjoyed, driven = zoo.enjoy("highway-ppo", episodes=1), _drive(model, 1)
    assert driven == {key: enjoyed[key] for key in driven}
    assert "highway-ppo" in repr(model)


@pytest.mark.parametrize("name", ["blocks-ppo", "follow-line-qlearning"])
def test_a_batch_of_observations_gives_each_ones_action_for_drivelabs_own_agents(name):
    """SB3 models take batches themselves; drivelab's own agents act on one observation, so
    ``predict`` acts on each of a batch: a Dict, a vector and a discrete-state observation."""
    model = drivelab.load(name)
    observations = met_observations(model.make_env(), 6)
    single = [model.predict(obs)[0] for obs in observations]
    if isinstance(observations[0], dict):
        batch = {key: np.stack([obs[key] for obs in observations]) for key in observations[0]}
    else:
        batch = np.stack([np.asarray(obs) for obs in observations])
    actions, state = model.predict(batch)
    assert state is None and len(actions) == len(observations)
    np.testing.assert_array_equal(actions, np.stack(single))
    assert all(
        model.action_space.contains(np.asarray(action, dtype=model.action_space.dtype)) for action in single
    )


def test_load_of_something_else_is_one_line(tmp_path):
    with pytest.raises(UsageError, match="does not exist .`drivelab zoo` lists: .*highway-ppo"):
        drivelab.load(tmp_path / "missing")
    (tmp_path / "folder").mkdir()
    with pytest.raises(UsageError, match="not a drivelab run directory"):
        drivelab.load(tmp_path / "folder")
