"""The tracker end to end: generated sequences, real sequences, presets, bad input."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from autotrack import AutoTrack, BoxError, CvAutoTrack, InputError, TrackerParams, preset
from autotrack.evaluation.datasets import load_otb_sequence
from autotrack.evaluation.metrics import center_errors, overlaps, precision_at
from autotrack.io.frames import read_image
from autotrack.io.otb_boxes import read_boxes
from tests.sequences import moving_target_sequence

SHARED = Path(__file__).resolve().parents[1] / ".." / "shared" / "data"
COLOUR_TABLE = SHARED / "color_names" / "cn_norm_32768x10.npy"
needs_shared = pytest.mark.skipif(not SHARED.is_dir(), reason="../shared/data is not present")


def _run(tracker: AutoTrack, frames: list[np.ndarray], init_box) -> list:
    results = [tracker.init(frames[0], init_box)]
    results.extend(tracker.update(frame) for frame in frames[1:])
    return results


@pytest.fixture(scope="module")
def moving_sequence():
    return moving_target_sequence()


def test_tracks_a_moving_scaling_target_within_a_few_pixels(moving_sequence):
    results = _run(AutoTrack(), moving_sequence.frames, moving_sequence.boxes[0])
    boxes = np.array([r.box for r in results])
    errors = center_errors(boxes, moving_sequence.boxes)
    assert errors.max() < 4.0
    # The target grows by 30 %: the scale filter follows it.
    assert results[-1].scale_factor == pytest.approx(1.3, abs=0.08)
    assert np.median(overlaps(boxes, moving_sequence.boxes)) > 0.85


def test_result_carries_the_filter_signals(moving_sequence):
    tracker = AutoTrack()
    first = tracker.init(moving_sequence.frames[0], moving_sequence.boxes[0])
    assert first.response_map is None and first.local_variation is None
    assert np.isnan(first.peak_score)
    second = tracker.update(moving_sequence.frames[1])
    assert second.local_variation is None and np.isnan(second.global_variation)
    assert second.theta_ref == 13.0
    third = tracker.update(moving_sequence.frames[2])
    grid = tracker.grid_size
    assert third.response_map.shape == grid and third.response_map.dtype == np.float32
    assert third.local_variation.shape == grid
    # Centred maps: a nearly static target peaks near the map centre.
    peak = np.unravel_index(np.argmax(third.response_map), grid)
    assert abs(peak[0] - grid[0] // 2) <= 2 and abs(peak[1] - grid[1] // 2) <= 2
    assert third.peak_score == pytest.approx(float(third.response_map.max()), rel=0.05)
    assert 0 < third.theta_ref <= 13.0 and 0 <= third.theta <= third.theta_ref
    x, y, w, h = third.search_box
    assert w == h and w > third.box[2] * 4


def test_full_occlusion_is_aberrant_and_leaves_the_filter_unchanged():
    sequence = moving_target_sequence(num_frames=40, occlusion=(30, 32))
    tracker = AutoTrack()
    tracker.init(sequence.frames[0], sequence.boxes[0])
    for frame in sequence.frames[1:30]:
        tracker.update(frame)
    filter_before = tracker.filter_f.copy()
    occluded = tracker.update(sequence.frames[30])
    assert occluded.aberrant
    assert occluded.global_variation >= tracker.params.phi
    assert np.array_equal(tracker.filter_f, filter_before)
    assert np.isnan(occluded.theta)


def test_strcf_never_stops_learning_and_keeps_theta_fixed(moving_sequence):
    results = _run(
        AutoTrack(preset("strcf")), moving_sequence.frames[:20], moving_sequence.boxes[0]
    )
    assert not any(r.aberrant for r in results)
    assert all(r.theta == 15.0 for r in results[1:])


@pytest.mark.parametrize("name", ["autotrack", "strcf", "strcf+asr", "strcf+atr"])
def test_every_ablation_preset_tracks_the_generated_target(name, moving_sequence):
    frames = moving_sequence.frames[:25]
    results = _run(AutoTrack(preset(name)), frames, moving_sequence.boxes[0])
    errors = center_errors(np.array([r.box for r in results]), moving_sequence.boxes[:25])
    assert errors.max() < 6.0


def test_grey_frames_use_grey_and_fhog_only(moving_sequence):
    grey = [frame.mean(axis=2).astype(np.uint8) for frame in moving_sequence.frames[:15]]
    tracker = AutoTrack()
    results = _run(tracker, grey, moving_sequence.boxes[0])
    assert tracker.grey and tracker.filter_f.shape[0] == 32
    errors = center_errors(np.array([r.box for r in results]), moving_sequence.boxes[:15])
    assert errors.max() < 6.0
    # A colour frame whose channels are equal counts as grey, as in the release.
    equal_channels = np.repeat(grey[0][:, :, None], 3, axis=2)
    tracker.init(equal_channels, moving_sequence.boxes[0])
    assert tracker.grey


def test_target_leaving_the_frame_does_not_crash():
    rng = np.random.default_rng(5)
    frames = [rng.integers(0, 255, (120, 160, 3), dtype=np.uint8) for _ in range(12)]
    tracker = AutoTrack()
    tracker.init(frames[0], (140, 100, 19, 19))  # touching the bottom-right corner
    for frame in frames[1:]:
        result = tracker.update(frame)
        assert np.all(np.isfinite(result.box))


@pytest.mark.parametrize(
    "box",
    [
        (10, 10, 0, 20),
        (10, 10, 20, -3),
        (500, 10, 20, 20),
        (-50, -50, 20, 20),
        (1, 2, 3),
        ("a", 1, 2, 3),
    ],
)
def test_bad_initial_boxes_are_rejected_with_a_clear_error(box):
    frame = np.zeros((100, 120, 3), dtype=np.uint8)
    with pytest.raises(BoxError):
        AutoTrack().init(frame, box)


def test_frames_of_another_size_or_update_before_init_are_rejected():
    tracker = AutoTrack()
    with pytest.raises(InputError):
        tracker.update(np.zeros((50, 50, 3), np.uint8))
    tracker.init(np.zeros((100, 120, 3), np.uint8), (40, 40, 20, 20))
    with pytest.raises(InputError, match="differs"):
        tracker.update(np.zeros((90, 120, 3), np.uint8))


def test_colour_table_preset_needs_a_path():
    with pytest.raises(InputError):
        AutoTrack(TrackerParams(colour_feature="table"))


def test_opencv_call_shape_adapter_takes_bgr(moving_sequence):
    tracker = CvAutoTrack()
    bgr = [frame[:, :, ::-1].copy() for frame in moving_sequence.frames[:10]]
    tracker.init(bgr[0], tuple(moving_sequence.boxes[0]))
    for index, frame in enumerate(bgr[1:], start=1):
        ok, box = tracker.update(frame)
        assert isinstance(ok, bool) and len(box) == 4
        assert center_errors(np.array([box]), moving_sequence.boxes[index : index + 1])[0] < 4


@needs_shared
@pytest.mark.parametrize(
    ("dataset", "name", "release_precision"),
    [
        ("DTB70", "MountainBike6", 1.0),
        ("OTB", "Crossing", 1.0),
        ("UAV123_10fps", "wakeboard7", 1.0),
    ],
)
def test_real_sequence_precision_reaches_the_release(dataset, name, release_precision):
    sequence = load_otb_sequence(SHARED / "sequences" / dataset / name)[0]
    frames = [read_image(path, i) for i, path in enumerate(sequence.frame_paths)]
    tracker = AutoTrack(preset("autotrack", COLOUR_TABLE))
    boxes = np.array([r.box for r in _run(tracker, frames, sequence.init_box)])
    precision = precision_at(center_errors(boxes, sequence.ground_truth), 20.0)
    assert precision >= release_precision - 0.02
    # Frame by frame close to the release's own boxes (run under Octave).
    release = read_boxes(
        SHARED / "reference" / "autotrack_release_octave" / dataset / f"{name}.txt"
    )
    assert np.median(overlaps(boxes, release)) > 0.85


@pytest.mark.parametrize(
    "change",
    [
        {"cell_size": 0},
        {"admm_iterations": 0},
        {"scale_step": 1.0},
        {"colour_feature": "rainbow"},
        {"theta_update": "guess"},
        {"min_image_sample_size": 0.0},
        {"use_grey": False, "use_fhog": False, "colour_feature": "none"},
    ],
)
def test_invalid_parameters_are_refused_with_a_message(change):
    with pytest.raises(InputError, match="invalid tracker parameters"):
        TrackerParams(**change)


@pytest.mark.parametrize("variant", ["release", "paper", "reference"])
def test_every_theta_variant_tracks_and_keeps_theta_below_its_reference(variant, moving_sequence):
    tracker = AutoTrack(TrackerParams(theta_update=variant))
    results = _run(tracker, moving_sequence.frames[:20], moving_sequence.boxes[0])
    trained = [r for r in results[2:] if not r.aberrant]
    assert trained and all(0.0 <= r.theta <= r.theta_ref + 1e-9 for r in trained)
    if variant == "reference":
        assert all(r.theta == pytest.approx(r.theta_ref) for r in trained)
    errors = center_errors(np.array([r.box for r in results]), moving_sequence.boxes[:20])
    assert errors.max() < 6.0
