import numpy as np
import pytest

from drivelab.errors import UsageError
from drivelab.rewards.shapers import PRESETS, RewardShaper, parse_reward
from drivelab.scenarios import SCENARIOS
from drivelab.sim.reference.highway import HighwayBackend
from drivelab.world.state import Events
from tests.worlds import world


def test_parse_preset_with_override_and_drop():
    spec = parse_reward("metadrive_course,crash=-10,arrival=0")
    assert spec.weights["crash"] == -10
    assert "arrival" not in spec.weights
    assert spec.weights["progress_lateral"] == 2.5


def test_parse_custom_terms_and_dict():
    assert parse_reward("speed=1,crash=-2").weights == {"speed": 1.0, "crash": -2.0}
    assert parse_reward({"speed": 0.5}).weights == {"speed": 0.5}


@pytest.mark.parametrize(
    "spec, message",
    [
        ("nope", "unknown reward preset"),
        ("speed=fast", "numeric weight"),
        ("speed=nan", "finite weight"),
        ({"crash": float("inf")}, "finite weight"),
        ("warp=1", "unknown reward term"),
        ("speed=0", "no term left"),
        ("", "empty"),
    ],
)
def test_parse_errors(spec, message):
    with pytest.raises(UsageError, match=message):
        parse_reward(spec)


def test_shaper_reports_weighted_terms_that_sum_to_reward():
    shaper = RewardShaper("metadrive_course")
    prev, now = world(progress_m=0.0), world(progress_m=10.0, speed_mps=14.0, events=Events(collided=True))
    reward, contributions = shaper(prev, now, None)
    assert contributions == {
        "progress_lateral": pytest.approx(25.0),
        "speed": pytest.approx(0.25),
        "crash": -5.0,
        "off_road": -0.0,
        "arrival": 0.0,
    }
    assert reward == pytest.approx(sum(contributions.values()))


def test_safety_preset_has_the_eight_terms():
    assert len(PRESETS["safety_dqn"].weights) == 8


def test_highway_preset_reproduces_highway_envs_own_reward():
    backend = HighwayBackend(SCENARIOS["highway"], "regular", "meta")
    shaper = RewardShaper("highway")
    prev = backend.reset(seed=5)
    compared = 0
    for action in [3, 3, 0, 1, 2, 2, 4, 1, 3, 3] * 3:
        now = backend.step(action)
        ours, _ = shaper(prev, now, action)
        assert ours == pytest.approx(backend.env._reward(action), abs=1e-9)
        compared += 1
        prev = now
        if now.events.collided:
            break
    assert compared >= 3
    assert np.isfinite(ours)


def test_highway_fast_preset_pays_speed_only_above_20_and_charges_collisions():
    shaper = RewardShaper("highway_fast")
    calm = world(speed_mps=20.0)
    assert shaper(calm, calm, 1) == (0.0, {"collision": -0.0, "high_speed": 0.0})
    fast = world(speed_mps=30.0)
    assert shaper(calm, fast, 3)[0] == 1.0
    reward, contributions = shaper(calm, world(speed_mps=25.0, events=Events(collided=True)), 1)
    assert contributions == {"collision": -10.0, "high_speed": 0.5}
    assert reward == -9.5
    # no normalisation and no gate: a crawling step is worth nothing, a crash always costs 10
    assert PRESETS["highway_fast"].normalize is None and PRESETS["highway_fast"].gate is None
