"""The tracker end to end: generated sequences, real sequences, presets, bad input."""

from __future__ import annotations

import numpy as np
import pytest

from autotrack import AutoTrack, BoxError, CvAutoTrack, InputError, TrackerParams, preset
from autotrack.evaluation.metrics import center_errors, overlaps
from autotrack.tracker import dcf
from tests.sequences import moving_target_sequence


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


def _variation_from_maps(current, previous) -> np.ndarray:
    """Eq. 2 from two reported (centred) response maps, as the release computes it: each map
    circularly shifted by minus the floor of its own sub-pixel peak displacement, then
    |R_t - R_t-1| / |R_t-1| elementwise, reported centred."""

    def aligned(result):
        response = np.fft.ifftshift(result.response_map).astype(np.float64)
        disp_row, disp_col, _ = dcf.newton_peak(response, 5)
        return np.roll(response, (-int(np.floor(disp_row)), -int(np.floor(disp_col))), (0, 1))

    now, before = aligned(current), aligned(previous)
    return np.fft.fftshift(np.abs(now - before) / np.abs(before))


def test_result_carries_the_filter_signals(moving_sequence):
    params = TrackerParams()
    tracker = AutoTrack(params)
    first = tracker.init(moving_sequence.frames[0], moving_sequence.boxes[0])
    assert first.response_map is None and first.local_variation is None
    assert np.isnan(first.peak_score) and first.theta_ref == 0.0
    results = [first] + [tracker.update(frame) for frame in moving_sequence.frames[1:14]]
    second = results[1]
    # Frame 2: nothing to compare with yet, theta = zeta.
    assert second.local_variation is None and np.isnan(second.global_variation)
    assert second.theta_ref == params.zeta and second.theta == params.zeta
    grid = tracker.grid_size
    trained = aberrant = 0
    for previous, result in zip(results[1:], results[2:], strict=False):
        assert result.response_map.shape == grid and result.response_map.dtype == np.float32
        # Local variation (eq. 2) recomputed from the two reported response maps.
        expected = _variation_from_maps(result, previous)
        np.testing.assert_allclose(result.local_variation, expected, rtol=1e-4, atol=1e-6)
        # Global variation: MATLAB's norm(Pi) (largest singular value), scaled by 1e-4.
        eta = np.linalg.norm(expected, 2) * 1e-4
        assert result.global_variation == pytest.approx(eta, rel=1e-4)
        # Aberrance stop and theta_ref (eq. 4).
        assert result.aberrant == (result.global_variation >= params.phi)
        if result.aberrant:
            aberrant += 1
            assert result.theta_ref == params.zeta and np.isnan(result.theta)
        else:
            trained += 1
            eta = result.global_variation
            assert result.theta_ref == pytest.approx(
                params.zeta / (1.0 + np.log(params.nu * eta + 1.0)), rel=1e-12
            )
            # Release theta update: theta_ref minus half a squared filter difference, tiny.
            assert 0.0 <= result.theta_ref - result.theta < 1e-4
        # The peak score is the sub-pixel peak of the reported map: at least its maximum.
        assert result.peak_score >= float(result.response_map.max()) - 1e-6
        _, _, score = dcf.newton_peak(np.fft.ifftshift(result.response_map).astype(float), 5)
        assert result.peak_score == pytest.approx(score, rel=1e-5)
        # The map covers the search box, centred on the previous position; the box moved by
        # the peak's offset from the map centre (cells of cell_size * scale pixels).
        x, y, w, h = result.search_box
        assert w == h
        assert np.abs(np.array([x + w / 2, y + h / 2]) - previous.center).max() <= 1.0
        peak = (
            np.array(np.unravel_index(np.argmax(result.response_map), grid)) - np.array(grid) // 2
        )
        cell_px = params.cell_size * w / tracker.window_size[0]
        moved = np.array(result.center) - np.array(previous.center)
        np.testing.assert_allclose(moved[::-1], peak * cell_px, atol=cell_px)
    assert trained >= 5 and aberrant >= 1  # both branches were checked


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
    # The target is strongly red and yellow: swapping R and B changes its colour feature.
    rgb = moving_sequence.frames[:10]
    bgr = [frame[:, :, ::-1].copy() for frame in rgb]
    box = tuple(moving_sequence.boxes[0])
    reference = AutoTrack()
    expected = [reference.init(rgb[0], box)] + [reference.update(frame) for frame in rgb[1:]]
    swapped = AutoTrack()
    unconverted = [swapped.init(bgr[0], box)] + [swapped.update(frame) for frame in bgr[1:]]
    peaks = [r.peak_score for r in expected[1:]]
    # Sanity: feeding BGR as if it were RGB is observably different.
    assert [r.peak_score for r in unconverted[1:]] != pytest.approx(peaks, rel=1e-3)

    tracker = CvAutoTrack()
    tracker.init(bgr[0], box)
    for index, frame in enumerate(bgr[1:], start=1):
        ok, got = tracker.update(frame)
        assert isinstance(ok, bool) and len(got) == 4
        # Box for box (and signal for signal) what AutoTrack gives on the RGB frames.
        assert got == expected[index].box
        assert ok == (not expected[index].aberrant)
        assert tracker.tracker.last_result.peak_score == pytest.approx(peaks[index - 1], rel=1e-6)
    # Grey frames pass through unchanged.
    grey = [frame.mean(axis=2).astype(np.uint8) for frame in rgb[:4]]
    plain, adapted = AutoTrack(), CvAutoTrack()
    plain.init(grey[0], box)
    adapted.init(grey[0], box)
    for frame in grey[1:]:
        assert adapted.update(frame)[1] == plain.update(frame).box


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


def _theta_after_a_filter_change(variant: str, moving_sequence, element, change: float):
    """theta that a variant's eq. 13 update computes when the filter moved by `change` at one
    element (channel, row, col) of the half spectrum, starting from theta_ref = 10."""
    tracker = AutoTrack(TrackerParams(theta_update=variant))
    tracker.init(moving_sequence.frames[0], moving_sequence.boxes[0])
    for frame in moving_sequence.frames[1:3]:
        tracker.update(frame)
    previous = tracker.filter_f.copy()
    update = tracker._theta_update(10.0, previous)
    moved = previous.copy()
    moved[element] += change
    return update(moved, 1), tracker


def test_theta_variants_differ_as_documented(moving_sequence):
    # 'reference': theta = theta_ref whatever the filter does.
    theta, tracker = _theta_after_a_filter_change("reference", moving_sequence, (0, 0, 0), 1.0)
    assert theta == 10.0
    channels = tracker.filter_f.shape[0]
    rows, cols = tracker.grid_size
    cells = rows * cols
    # 'release': only the element at MATLAB linear index = channel count (1-based) of the
    # (rows, cols, channels) difference counts: row channels-1, col 0, channel 0 here.
    assert channels < rows
    release_element = (0, channels - 1, 0)
    theta, _ = _theta_after_a_filter_change("release", moving_sequence, release_element, 2.0)
    assert theta == pytest.approx(10.0 - 2.0**2 / 2.0)
    theta, _ = _theta_after_a_filter_change("release", moving_sequence, (5, 3, 4), 2.0)
    assert theta == 10.0
    # 'paper': every element, the Frobenius norm of the full spectrum / T (a half-spectrum
    # column other than 0 and Nyquist stands for two full-spectrum columns).
    theta, _ = _theta_after_a_filter_change("paper", moving_sequence, release_element, 2.0)
    assert theta == pytest.approx(10.0 - 2.0**2 / cells / 2.0)
    theta, _ = _theta_after_a_filter_change("paper", moving_sequence, (5, 3, 4), 2.0)
    assert theta == pytest.approx(10.0 - 2.0 * 2.0**2 / cells / 2.0)
    # Clamped at 0.
    theta, _ = _theta_after_a_filter_change("release", moving_sequence, release_element, 100.0)
    assert theta == 0.0


@pytest.mark.parametrize("variant", ["release", "paper", "reference"])
def test_every_theta_variant_tracks_and_keeps_theta_below_its_reference(variant, moving_sequence):
    tracker = AutoTrack(TrackerParams(theta_update=variant))
    results = _run(tracker, moving_sequence.frames[:20], moving_sequence.boxes[0])
    trained = [r for r in results[2:] if not r.aberrant]
    assert trained and all(0.0 <= r.theta <= r.theta_ref + 1e-9 for r in trained)
    if variant == "reference":
        assert all(r.theta == r.theta_ref for r in trained)
    else:
        # The filter changes every frame, so release and paper lower theta below theta_ref.
        assert all(r.theta < r.theta_ref for r in trained)
    errors = center_errors(np.array([r.box for r in results]), moving_sequence.boxes[:20])
    assert errors.max() < 6.0
