"""Seed 004's circuits on the compiled core: the same episodes as the highway-env reference."""

from __future__ import annotations

import numpy as np
import pytest

from drivelab.envs.core import DriveEnv
from drivelab.scenarios import SCENARIOS
from drivelab.sim.core.backend import FastBackend, FastSimulator
from drivelab.sim.reference.highway import HighwayBackend

STEPS = 60


def _compare(name: str, seeds) -> tuple[float, int]:
    """Both backends through the same seeds and random pedal/steering actions: events, lane ids,
    guide lines identical; returns (largest continuous difference, off-road endings seen)."""
    reference = HighwayBackend(SCENARIOS[name], "empty", "continuous")
    fast = FastBackend(SCENARIOS[name], "empty", "continuous")
    worst, endings = 0.0, 0
    for seed in seeds:
        a, b = reference.reset(seed), fast.reset(seed)
        np.testing.assert_array_equal(a.ego.position, b.ego.position)
        assert len(a.road.guide_lines) == len(b.road.guide_lines) == (name == "follow-line")
        for line_a, line_b in zip(a.road.guide_lines, b.road.guide_lines, strict=True):
            np.testing.assert_array_equal(line_a, line_b)
        rng = np.random.default_rng(seed)
        for _ in range(STEPS):
            action = (rng.uniform(-1, 1, 2) * [1.0, 0.15]).astype(np.float32)
            a, b = reference.step(action), fast.step(action)
            assert a.events == b.events
            assert (a.ego.lane_id, a.ego.on_road) == (b.ego.lane_id, b.ego.on_road)
            worst = max(
                worst,
                np.abs(a.ego.position - b.ego.position).max(),
                abs(a.ego.heading - b.ego.heading),
                abs(a.ego.speed_mps - b.ego.speed_mps),
                abs(a.ego.acceleration_mps2 - b.ego.acceleration_mps2),
                abs(a.route.progress_m - b.route.progress_m),
            )
            if a.events.off_road:
                endings += 1
                break
    return worst, endings


@pytest.mark.parametrize("name", ["follow-line", "follow-lane"])
def test_circuit_episodes_match_the_reference(name):
    """Only the ego drives, on straights and arcs: the same arithmetic as highway-env's up to
    libm rounding (the tolerance of tests/sim/test_fast.py's ROUNDING_ATOL); leaving
    the road (and, on follow-lane, the starting lane) ends episodes on both at the same step."""
    worst, endings = _compare(name, range(6))
    assert worst <= 1e-3
    assert endings >= 1  # the random steering leaves the road in some episodes: the rule is exercised


def test_pedal_drag_levels_the_speed_off():
    """Seed 004's throttle 0.35 settles at 30 km/h: acceleration = pedal - drag * speed."""
    fast = FastBackend(SCENARIOS["follow-lane"], "empty", "continuous")
    fast.reset(0)
    throttle = 0.35 * 5.0 / 5.0  # normalised: 5 m/s² at full pedal
    for _ in range(300):
        world = fast.step(np.array([throttle, 0.0], dtype=np.float32))
    assert world.ego.speed_mps == pytest.approx(30 / 3.6, rel=1e-3)


def test_drive_env_picks_the_fast_backend_for_the_circuits():
    env = DriveEnv("follow-line", obs="line", action="seed_line")
    env.reset(seed=0)
    assert type(env.backend) is FastSimulator
    obs, *_ = env.step(0)
    assert env.observation_space.contains(obs)
