"""RewardShaper: a weighted sum of reward terms, and the presets that reproduce each source."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from drivelab.errors import UsageError
from drivelab.rewards.terms import TERMS
from drivelab.world.batch import WorldBatch
from drivelab.world.state import WorldState


@dataclass(frozen=True)
class RewardSpec:
    """What a reward is: term weights, an optional affine normalisation and an optional gate.

    :param weights: term name → weight; the reward is Σ weight · term.
    :param normalize: (low, high): the sum is mapped linearly so that low → 0 and high → 1.
    :param gate: a term whose value multiplies the final reward (highway-env's on_road factor).
    """

    weights: dict[str, float]
    normalize: tuple[float, float] | None = None
    gate: str | None = None
    description: str = field(default="", compare=False)


SAFETY_TERMS = (
    "centered", "overspeed", "curve_control", "intersection_heading", "destination_proximity",
    "steering_smoothness", "overtaking", "sidewalk_crash",
)  # fmt: skip

ROACH_TERMS = ("roach_speed", "roach_position", "roach_rotation", "roach_action", "roach_terminal")

PRESETS: dict[str, RewardSpec] = {
    "highway": RewardSpec(
        {"collision": -1.0, "right_lane": 0.1, "high_speed": 0.4},
        normalize=(-1.0, 0.5),
        gate="on_road",
        description="highway-env's own: collision -1, right lane 0.1, high speed 0.4, normalised, x on_road",
    ),
    "highway_fast": RewardSpec(
        # drivelab's training reward for highway at >= 25 m/s (highway's own pays 0.67 a step for
        # crawling at 20 m/s): benchmarks/results/highway_competence.md screened the weights
        {"collision": -10.0, "high_speed": 1.0},
        description="highway's speed target: high speed (0 at 20, 1 at 30 m/s on highway), "
        "collision -10, no constant",
    ),
    "metadrive_course": RewardSpec(
        {"progress_lateral": 2.5, "speed": 0.5, "crash": -5.0, "off_road": -5.0, "arrival": 10.0},
        description="the MetaDrive study: 2.5*progress*(1-|lat|^3) + 0.5*speed (halved in junctions), "
        "crash/off-road -5, arrival +10",
    ),
    "metadrive": RewardSpec(
        # metadrive/envs/metadrive_env.py default_config: driving_reward 1.0, speed_reward 0.1,
        # success_reward 10.0, out_of_road_penalty 5.0, crash_vehicle_penalty 5.0
        {
            "metadrive_progress": 1.0,
            "metadrive_speed": 0.1,
            "metadrive_success": 10.0,
            "metadrive_out_of_road": -5.0,
            "metadrive_crash": -5.0,
        },
        description="MetaDrive's default: 1.0*route progress (m) + 0.1*speed/80 km/h; a terminal "
        "step gets only +10 arrival, -5 out of road or -5 crash (in that order)",
    ),
    "roach": RewardSpec(
        {name: 1.0 for name in ROACH_TERMS},
        description="CARLA-Roach's, as RLAD uses it: speed to a hazard-aware target, route position "
        "and heading, steering changes, terminal penalties",
    ),
    "line_follow": RewardSpec(
        {"line_centring": 1.0, "speed_mps": 1.0, "steering_power": -1.0},
        description="the CARLA study eq. 3: sum over 4 rows of f(line centre) + speed - 1.02^|steering deg|",
    ),
    "lane_follow": RewardSpec(
        {"lane_keeping": 1.0},
        description="the CARLA study eq. 4: f*(lane centre), x2 aligned and straight, /2 aligned, steering",
    ),
    "safety_dqn": RewardSpec(
        {name: 1.0 for name in SAFETY_TERMS},
        description="the MetaDrive study's eight safety terms (centre, overspeed, curves, junctions, ...)",
    ),
}


def parse_reward(spec: str | dict | RewardSpec) -> RewardSpec:
    """Resolve a preset name, ``"term=w,term=w"``, ``"preset,term=w"`` (override) or a dict.

    A weight of 0 drops a term. Unknown presets or terms, and a term given twice, raise UsageError.
    """
    if isinstance(spec, RewardSpec):
        return spec
    if isinstance(spec, dict):
        items = [f"{k}={v}" for k, v in spec.items()]
    else:
        items = [item.strip() for item in str(spec).split(",") if item.strip()]
    if not items:
        raise UsageError("empty reward specification")
    base = RewardSpec({})
    if "=" not in items[0]:
        name = items.pop(0)
        if name not in PRESETS:
            raise UsageError(f"unknown reward preset {name!r} (choose from {', '.join(PRESETS)})")
        base = PRESETS[name]
    weights, given = dict(base.weights), set()
    for item in items:
        name, _, value = item.partition("=")
        name = name.strip()
        if name not in TERMS:
            raise UsageError(f"unknown reward term {name!r} (known: {', '.join(sorted(TERMS))})")
        if name in given:
            raise UsageError(f"reward {spec!r} gives the term {name!r} twice")
        given.add(name)
        try:
            weight = float(value)
        except ValueError:
            raise UsageError(f"reward term {name!r} needs a numeric weight, got {value!r}") from None
        if not math.isfinite(weight):
            raise UsageError(f"reward term {name!r} needs a finite weight, got {value!r}")
        weights[name] = weight
    weights = {k: w for k, w in weights.items() if w != 0.0}
    if not weights:
        raise UsageError("the reward has no term left with a non-zero weight")
    return RewardSpec(weights, base.normalize, base.gate, base.description)


class RewardShaper:
    """Computes the reward of a step for K worlds and every term's weighted contribution."""

    def __init__(self, spec: str | dict | RewardSpec) -> None:
        self.spec = parse_reward(spec)
        self._weighted = [(name, weight, TERMS[name]) for name, weight in self.spec.weights.items()]

    def __call__(self, prev: WorldBatch | WorldState, batch: WorldBatch | WorldState, control) -> tuple:
        """``(rewards (K,), {term: weight · value (K,)})`` for the step prev → batch, ``control``
        being ``(K,)`` meta-actions or ``(K, 2)`` continuous controls. For one world (two
        WorldStates and its control) the same as floats: ``(reward, {term: weight · value})``."""
        if isinstance(batch, WorldState):
            control = None if control is None else np.asarray(control)[None]
            rewards, contributions = self(WorldBatch.stack([prev]), WorldBatch.stack([batch]), control)
            return float(rewards[0]), {name: float(value[0]) for name, value in contributions.items()}
        contributions, rewards = {}, np.zeros(batch.num_worlds)
        for name, weight, fn in self._weighted:  # summed in the spec's order, as one world's sum was
            value = contributions[name] = weight * np.asarray(fn(prev, batch, control), dtype=float)
            np.add(rewards, value, out=rewards)
        if self.spec.normalize is not None:
            low, high = self.spec.normalize
            rewards = (rewards - low) / (high - low)
        if self.spec.gate is not None:
            rewards = rewards * np.asarray(TERMS[self.spec.gate](prev, batch, control), dtype=float)
        return rewards, contributions
