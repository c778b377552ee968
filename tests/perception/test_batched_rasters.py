"""Batched raster sensors (topdown, birdeye, camera, line, lane) against the one-world path.

On random worlds of K = 8 independent episodes that start at different steps, one sensor observing
all K worlds per call (reset under the mask of the worlds that just started) gives exactly the
observations of K sensors each observing its own world (reset when its world starts): uint8
images and discrete states compared exactly.
"""

import numpy as np
import pytest

from drivelab.perception.birdeye import render_birdeye
from drivelab.perception.sensors import make_sensor
from drivelab.perception.topdown import LanePolygons
from drivelab.world.batch import WorldBatch
from tests.batch_worlds import world_sequences

NUM_WORLDS, STEPS = 8, 7  # world k restarts every 3 + k % 4 steps: at steps 0, 3, 4, 5, 6

CASES = [
    ("highway", "topdown"),
    ("town", "topdown:lights=true"),
    ("highway", "birdeye"),
    ("town", "camera"),
    ("follow-line", "line"),
    ("follow-lane", "lane:detector=classical"),
    ("follow-lane", "lane"),  # the CNN: one forward pass over K frames (4 steps: it is the slow one)
]


def _batched_and_single(scenario: str, spec: str):
    """Per step, the (K, …) observations of one batched sensor and of K one-world sensors."""
    sequence = world_sequences(scenario, num_worlds=NUM_WORLDS, steps=STEPS)
    sequence = sequence[:4] if spec == "lane" else sequence
    batched, singles = make_sensor(spec), [make_sensor(spec) for _ in range(NUM_WORLDS)]
    out = batched.empty(NUM_WORLDS)
    results = []
    for t, (worlds, started) in enumerate(sequence):
        batch = WorldBatch.stack(list(worlds))
        rngs = [np.random.default_rng(k) for k in range(NUM_WORLDS)]
        batched.reset(batch, rngs, None if t == 0 else started)
        for k in np.flatnonzero(started):
            singles[k].reset(worlds[k], np.random.default_rng(int(k)))
        batched.observe(batch, out)
        single = np.stack(
            [np.asarray(sensor.observe(world)) for sensor, world in zip(singles, worlds, strict=True)]
        )
        results.append((batch, out.copy(), single, batched, singles))
    return results


@pytest.mark.parametrize(("scenario", "spec"), CASES)
def test_batched_equals_single_world(scenario, spec):
    results = _batched_and_single(scenario, spec)
    sequence = world_sequences(scenario, num_worlds=NUM_WORLDS, steps=STEPS)
    assert sequence[3][1].any() and not sequence[3][1].all()  # some worlds restart mid-batch
    for _, out, single, batched, singles in results:
        assert out.shape == (NUM_WORLDS, *batched.space.shape) and out.dtype == batched.space.dtype
        np.testing.assert_array_equal(out, single)
        if hasattr(batched, "centres"):  # line / lane: the row centres found, (K, 4)
            expected = np.concatenate([sensor.centres for sensor in singles])
            np.testing.assert_array_equal(batched.centres, expected)
    # something to compare: every channel of topdown drawn at some step, states not all "lost"
    if batched.name == "topdown":
        assert all(any(r[1][:, c].any() for r in results) for c in range(batched.space.shape[0]))
    elif out.ndim == 1:
        assert any((r[1] != batched.space.n - 1).any() for r in results)


def test_render_birdeye_of_one_world_equals_the_batched_image():
    batch, out, _, _, _ = _batched_and_single("highway", "birdeye")[-1]
    for k in (0, 5):
        np.testing.assert_array_equal(render_birdeye(batch[k], (128, 128), 3.0), out[k])


def test_road_geometry_is_derived_once_per_map():
    batch, *_ = _batched_and_single("highway", "topdown")[-1]
    road = batch.road_of(0)
    polygons = road.derived_cache[LanePolygons]
    assert isinstance(polygons, LanePolygons) and polygons.counts.sum() == sum(map(len, road.lane_polygons))
    assert road.derived(LanePolygons, LanePolygons) is polygons


def test_topdown_history_restarts_with_its_world():
    sensor = make_sensor("topdown")
    sequence = world_sequences("highway", num_worlds=NUM_WORLDS, steps=STEPS)
    for t, (worlds, started) in enumerate(sequence[:4]):
        batch = WorldBatch.stack(list(worlds))
        sensor.reset(
            batch, [np.random.default_rng(k) for k in range(NUM_WORLDS)], None if t == 0 else started
        )
        image = sensor.observe(batch)
    # step 3: world 0 (period 3) just restarted, world 1 (period 4) has 3 past positions
    assert sensor.past_count.tolist()[:2] == [1, 4]
    assert not image[0, 2].any()  # no past dots on a first frame
    np.testing.assert_array_equal(image[0, 3], image[0, 4])  # previous traffic = traffic now
