"""Seed 004's follow-line and follow-lane rewards on hand-built worlds with known answers."""

import dataclasses

import numpy as np
import pytest

from drivelab.rewards import terms
from drivelab.rewards.shapers import RewardShaper
from drivelab.world.state import RoadMap, Route
from tests.rewards.one_world import one
from tests.worlds import world

LINE = np.array([[-50.0, 0.0], [500.0, 0.0]])


def _guided(**ego):
    w = world(**ego)
    return dataclasses.replace(w, road=dataclasses.replace(RoadMap.empty(), guide_lines=(LINE,)))


def test_line_centring_bands():
    assert one(terms.line_centring, None, _guided(), None) == 4 * 15  # the line under the image centre
    assert one(terms.line_centring, None, world(), None) == 4 * -100  # no line in sight
    # 0.8 m to the side: at 3 m ahead the line is 0.8·f/depth px off centre, more than 3·38 of 640
    shifted = one(terms.line_centring, None, _guided(position=np.array([0.0, 0.8])), None)
    assert shifted < 4 * 15 and shifted > 4 * -100


def test_line_follow_preset_sums_terms():
    w = _guided(speed_mps=10.0)
    reward, parts = RewardShaper("line_follow")(w, w, np.array([0.32, 0.2], dtype=np.float32))
    assert parts["speed_mps"] == 10.0
    assert parts["steering_power"] == pytest.approx(-(1.02**9.0), rel=1e-6)  # 0.2 · 45° = 9°
    assert reward == pytest.approx(60 + 10 - 1.02**9.0, rel=1e-6)


def test_lane_keeping_alignment_and_action():
    w = dataclasses.replace(world(), route=Route(LINE, 0.0, np.inf))
    straight, turning = np.array([0.6, 0.0]), np.array([0.35, 0.04])
    assert one(terms.lane_keeping, None, w, straight) == 20.0  # centred (10), aligned and straight: x2
    assert one(terms.lane_keeping, None, w, turning) == 5.0  # aligned but steering: /2
    # heading 15° off: the centre moves more than 80 px (of 1024) off the image centre → f* = −10,
    # while the centre points still run within 6° of the image vertical: doubled for going straight
    skewed = dataclasses.replace(w, ego=dataclasses.replace(w.ego, heading=np.radians(15)))
    assert one(terms.lane_keeping, None, skewed, straight) == -20.0
    behind = dataclasses.replace(
        w, ego=dataclasses.replace(w.ego, heading=np.pi, position=np.array([-60.0, 0]))
    )
    assert one(terms.lane_keeping, None, behind, straight) == -10.0  # the lane out of view
