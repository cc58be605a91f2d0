"""Switches beyond `autotrack+`: the aspect-ratio filter and the constant-velocity prediction."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from autotrack import AutoTrack, preset
from autotrack.errors import InputError
from autotrack.evaluation.metrics import center_errors, overlaps
from autotrack.params import PRESETS, TrackerParams
from autotrack.tracker.plus.aspect import aspect_sizes
from tests.sequences import accelerating_target_sequence, moving_target_sequence


def _boxes(params: TrackerParams, frames: list[np.ndarray], box) -> np.ndarray:
    tracker = AutoTrack(params)
    boxes = [tracker.init(frames[0], box).box]
    boxes += [tracker.update(frame).box for frame in frames[1:]]
    return np.array(boxes)


# -- aspect filter ----------------------------------------------------------------------------


def test_aspect_samples_keep_the_area_and_scale_the_ratio():
    ratios = np.array([0.5, 1.0, 2.0])
    sizes = aspect_sizes(np.array([60.0, 40.0]), ratios)  # rows, cols
    areas = sizes[:, 0] * sizes[:, 1]
    assert np.all(np.abs(areas - 2400) <= 0.02 * 2400)
    np.testing.assert_allclose(
        (sizes[:, 1] / sizes[:, 0]) / (40 / 60), ratios, rtol=0.03
    )  # width / height moves by each ratio


def test_aspect_filter_follows_a_target_that_stretches_to_twice_its_width():
    sequence = moving_target_sequence(final_scale=1.0, final_aspect=2.0, target_size=48)
    start = sequence.boxes[0]
    fixed = _boxes(preset("autotrack+"), sequence.frames, start)
    stretched = _boxes(replace(preset("autotrack+"), num_aspects=17), sequence.frames, start)
    truth_end = sequence.boxes[-1, 2] / sequence.boxes[-1, 3]
    assert fixed[-1, 2] / fixed[-1, 3] == pytest.approx(1.0, abs=0.05)  # the release's shape
    assert stretched[-1, 2] / stretched[-1, 3] == pytest.approx(truth_end, rel=0.15)
    assert np.mean(overlaps(fixed, sequence.boxes)[-10:]) < 0.7
    assert np.mean(overlaps(stretched, sequence.boxes)[-10:]) > 0.85
    assert center_errors(stretched, sequence.boxes).max() < 4.0


def test_aspect_filter_keeps_the_shape_of_a_target_that_does_not_stretch():
    sequence = moving_target_sequence()  # grows to 1.3x, square throughout
    boxes = _boxes(
        replace(preset("autotrack+"), num_aspects=17), sequence.frames, sequence.boxes[0]
    )
    ratios = boxes[:, 2] / boxes[:, 3]
    assert np.all(np.abs(np.log(ratios)) < np.log(1.1))
    assert np.median(overlaps(boxes, sequence.boxes)) > 0.85


# -- constant-velocity prediction ----------------------------------------------------------------


def test_velocity_prediction_keeps_a_target_faster_than_the_search_region():
    sequence = accelerating_target_sequence()  # up to 90 px per frame
    no_redetection = replace(preset("autotrack+"), redetect_span=0.0)
    tracker = AutoTrack(no_redetection)
    tracker.init(sequence.frames[0], sequence.boxes[0])
    half_search = tracker.window_size[0] * tracker.scale / 2
    assert np.max(np.diff(sequence.boxes[:, 0])) > half_search  # out of the ordinary reach
    still = _boxes(no_redetection, sequence.frames, sequence.boxes[0])
    predicted = _boxes(
        replace(no_redetection, velocity_weight=1.0), sequence.frames, sequence.boxes[0]
    )
    assert center_errors(still, sequence.boxes)[-1] > 100.0  # left behind
    assert center_errors(predicted, sequence.boxes).max() < 3.0


# -- switches -----------------------------------------------------------------------------------


def test_new_switches_are_off_in_the_faithful_presets_and_count_as_beyond_the_release():
    for name in ("autotrack", "strcf", "strcf+asr", "strcf+atr"):
        assert PRESETS[name].num_aspects == 0 and PRESETS[name].velocity_weight == 0.0
    assert replace(PRESETS["autotrack"], num_aspects=17).beyond_release
    assert replace(PRESETS["autotrack"], velocity_weight=1.0).name == "autotrack+"


@pytest.mark.parametrize("change", [{"num_aspects": -1}, {"velocity_weight": -0.5}])
def test_negative_aspect_count_or_velocity_weight_is_refused(change):
    with pytest.raises(InputError, match="num_aspects and velocity_weight"):
        TrackerParams(**change)
