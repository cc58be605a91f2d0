"""autotrack+: robust variation, acting ASR, confidence gate, re-detection, thin-target scale."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from autotrack import AutoTrack, preset
from autotrack.evaluation.benchmark import run_task
from autotrack.evaluation.datasets import load_sequences
from autotrack.evaluation.metrics import center_errors, overlaps, score_sequence, summarize
from autotrack.params import PRESETS
from autotrack.tracker import dcf, regularization
from autotrack.tracker.backend import ReferenceBackend
from autotrack.tracker.plus import redetect, robust
from autotrack.tracker.scale import ScaleFilter
from tests.conftest import SEQUENCES, needs_sequences
from tests.sequences import moving_target_sequence


def _peaked_response(grid=(20, 20), sigma=1.5, floor=0.0):
    rows = dcf.centred_frequencies(grid[0])[:, None]
    cols = dcf.centred_frequencies(grid[1])[None, :]
    return (np.exp(-0.5 * (rows**2 + cols**2) / sigma**2) + floor).astype(np.float64)


# -- robust local variation -----------------------------------------------------------------


def test_robust_variation_stays_bounded_where_the_previous_response_is_near_zero():
    previous = _peaked_response()  # ~1e-30 far from the peak
    rng = np.random.default_rng(1)
    current = previous + 0.01 * rng.standard_normal(previous.shape)
    release = regularization.local_variation(current, (0, 0), previous, (0, 0))
    assert np.nanmax(release) > 1e10  # the release's noise over ~0
    floor = 0.1
    robust_map = robust.robust_local_variation(current, (0, 0), previous, (0, 0), floor)
    bound = (np.abs(current).max() + np.abs(previous).max()) / (floor * previous.max())
    assert np.all(np.isfinite(robust_map)) and robust_map.max() <= bound
    # 1 % noise over a floor of 10 % of the peak: at most ~0.4 anywhere.
    assert robust_map.max() < 0.5
    eta = regularization.global_variation(robust_map)
    assert eta < PRESETS["autotrack"].phi  # noise alone no longer stops learning


def test_robust_variation_equals_eq2_where_the_previous_response_is_strong():
    previous = _peaked_response(floor=0.2)  # every cell above 10 % of the peak
    current = np.roll(previous, (2, -3), axis=(0, 1)) * 1.1
    floor = 0.1
    robust_map = robust.robust_local_variation(current, (2, -3), previous, (0, 0), floor)
    release = regularization.local_variation(current, (2, -3), previous, (0, 0))
    np.testing.assert_allclose(robust_map, release, rtol=1e-5)
    np.testing.assert_allclose(robust_map, 0.1, rtol=1e-4)  # aligned peaks: a 10 % change


# -- acting ASR -----------------------------------------------------------------------------


def test_acting_asr_attenuates_each_cell_by_the_stated_factor():
    grid, region_size = (16, 16), (6, 4)
    base = regularization.base_spatial_window(grid, region_size, 1e5, 1e-3)
    region = regularization.target_region(grid, region_size)
    variation = np.zeros(grid, np.float32)
    variation[region] = np.linspace(0.0, 5.0, 24).reshape(6, 4)
    delta, gamma, lam = 0.2, 1.0, 1.0
    window = robust.acting_spatial_window(base, variation, region, delta, gamma, lam)
    cells = grid[0] * grid[1]
    gain = cells / (lam * window.astype(np.float64) ** 2 + gamma * cells)  # eq. 12
    expected = 1.0 / (1.0 + (delta * np.log(variation[region] + 1.0)) ** 2)
    np.testing.assert_allclose(gain[region], expected, rtol=1e-4, atol=1e-6)
    # Outside the target region the support constraint is untouched.
    outside = np.ones(grid, bool)
    outside[region] = False
    assert np.all(window[outside] == base[outside])


def test_acting_asr_changes_the_learnt_filter_where_the_release_asr_does_not():
    rng = np.random.default_rng(3)
    grid, region_size, channels = (24, 24), (8, 8), 4
    features = rng.standard_normal((channels, *grid)).astype(np.float32)
    xf = dcf.to_spectrum(features)
    yf = dcf.to_spectrum(dcf.gaussian_label(grid, 1.5).astype(np.float32))
    settings = dcf.AdmmSettings(4, 1.0, 1.0, 10.0, 1e4)
    base = regularization.base_spatial_window(grid, region_size, 1e5, 1e-3)
    region = regularization.target_region(grid, region_size)
    variation = np.zeros(grid, np.float32)
    variation[region] = 3.0  # a strongly varying target region
    release = regularization.adaptive_spatial_window(base, variation, region, 0.2)
    acting = robust.acting_spatial_window(base, variation, region, 0.2, 1.0, 1.0)

    def train(window):
        g_f, _ = dcf.train_filter(xf, yf, np.zeros_like(xf), window, 0.0, settings)
        return dcf.from_spectrum(g_f, grid)

    unregularised = train(base)
    relative = lambda h: np.linalg.norm(h - unregularised) / np.linalg.norm(unregularised)  # noqa: E731
    assert relative(train(release)) < 1e-3
    assert relative(train(acting)) > 0.05


def test_relative_asr_represses_a_varying_part_and_not_a_uniformly_changing_target():
    grid, region_size = (16, 16), (6, 6)
    base = regularization.base_spatial_window(grid, region_size, 1e5, 1e-3)
    region = regularization.target_region(grid, region_size)
    cells = grid[0] * grid[1]

    def gain(variation, relative):
        window = robust.acting_spatial_window(base, variation, region, 0.2, 1.0, 1.0, relative)
        return (cells / (window.astype(np.float64) ** 2 + cells))[region]  # eq. 12, gamma = 1

    # The whole target changed alike (a turn, a change of light): absolute ASR attenuates every
    # cell, relative ASR none, so the filter learns the new appearance.
    uniform = np.zeros(grid, np.float32)
    uniform[region] = 4.0
    assert gain(uniform, relative=False).max() < 0.93
    np.testing.assert_allclose(gain(uniform, relative=True), 1.0, atol=1e-6)
    # One part varied far more than the rest (a partial occluder): only that part is repressed,
    # by the attenuation of its excess variation over the target's median.
    partial = uniform.copy()
    rows, cols = region
    partial[rows.start : rows.start + 2, cols.start : cols.start + 2] = 40.0
    relative_gain = gain(partial, relative=True)
    excess = np.log(41.0) - np.log(5.0)
    assert relative_gain[:2, :2] == pytest.approx(1.0 / (1.0 + (0.2 * excess) ** 2), rel=1e-4)
    np.testing.assert_allclose(relative_gain[2:, :], 1.0, atol=1e-6)


# -- calibrated confidence -------------------------------------------------------------------


def test_apce_of_a_single_peak_on_a_flat_floor():
    response = np.zeros((4, 5))
    response[1, 2] = 2.0
    # |2 - 0|^2 / mean((R - 0)^2) = 4 / (4 / 20) = 20
    assert robust.apce(response) == pytest.approx(20.0)
    assert robust.apce(np.ones((3, 3))) == 0.0


def test_confidence_is_calibrated_to_the_running_averages():
    confidence = robust.ResponseConfidence(memory=0.5)
    assert confidence.confidence(3.0, 40.0) == 1.0  # no reference yet
    confidence.observe(1.0, 50.0, gate=0.7)
    assert confidence.confidence(0.1, 1.0) == 1.0  # one frame is no calibration (1/memory = 2)
    confidence.observe(3.0, 30.0, gate=0.7)  # calibrated: the mean of the first two frames
    assert confidence.calibrated
    assert confidence.confidence(1.0, 40.0) == pytest.approx(0.5)  # half the usual peak
    assert confidence.confidence(2.0, 10.0) == pytest.approx(0.5)  # a quarter of the APCE
    confidence.observe(4.0, 40.0, gate=0.7)  # a confident frame: plain running average
    assert confidence.peak_reference == pytest.approx(3.0)
    confidence.observe(0.0, 0.0, gate=0.7)  # an occluded frame pulls down by at most 15 %
    assert confidence.peak_reference == pytest.approx(3.0 * (1 - 0.5 * 0.3))
    assert confidence.apce_reference == pytest.approx(40.0 * (1 - 0.5 * 0.51))
    assert confidence.confidence(float("nan"), 1.0) == 0.0


# -- re-detection ------------------------------------------------------------------------------


def test_placement_response_scores_each_placement_like_detection():
    rng = np.random.default_rng(5)
    grid, channels = (10, 12), 3
    filter_spatial = rng.standard_normal((channels, *grid)).astype(np.float32)
    maps = rng.standard_normal((channels, 31, 27)).astype(np.float32)
    response = redetect.placement_response(filter_spatial, maps)
    assert response.shape == (31 - 10 + 1, 27 - 12 + 1)
    for row, col in [(0, 0), (7, 3), (21, 15)]:
        window = maps[:, row : row + grid[0], col : col + grid[1]]
        assert response[row, col] == pytest.approx(float(np.sum(filter_spatial * window)), rel=1e-4)
        # ... which is eq. 16's response at zero shift for that patch.
        detection = dcf.detection_response(
            dcf.to_spectrum(filter_spatial), dcf.to_spectrum(window), grid
        )
        assert response[row, col] == pytest.approx(float(detection[0, 0]), rel=1e-3)


def _run(params, frames, box):
    tracker = AutoTrack(params)
    results = [tracker.init(frames[0], box)]
    filters = [tracker.filter_f.copy()]
    for frame in frames[1:]:
        results.append(tracker.update(frame))
        filters.append(tracker.filter_f.copy())
    return tracker, np.array([r.box for r in results]), filters


def test_gated_filter_does_not_learn_an_occluder_and_recovers_after_it():
    occluded = (25, 30)
    sequence = moving_target_sequence(num_frames=60, occlusion=occluded)
    _, boxes, filters = _run(preset("autotrack+"), sequence.frames, sequence.boxes[0])
    errors = center_errors(boxes, sequence.boxes)
    first, last = occluded
    for index in range(first, last + 1):  # the grey block covers the target: nothing learnt
        np.testing.assert_array_equal(filters[index], filters[first - 1])
    assert errors[: first - 1].max() < 4.0
    assert errors[last + 2 :].max() < 4.0  # found again right after the block leaves
    # The release learns the block and never finds the target again.
    _, release_boxes, _ = _run(preset("autotrack"), sequence.frames, sequence.boxes[0])
    assert np.median(center_errors(release_boxes, sequence.boxes)[last + 2 :]) > 50.0


def test_redetection_finds_a_target_that_jumped_beyond_the_search_region():
    sequence = moving_target_sequence(num_frames=40, size_hw=(360, 480), final_scale=1.0)
    jump_at, jump = 20, (0, 150)  # the camera jumps: 150 px, ~1.2 search regions sideways
    frames = [
        frame if index < jump_at else np.roll(frame, jump, axis=(0, 1))
        for index, frame in enumerate(sequence.frames)
    ]
    truth = sequence.boxes + np.where(np.arange(40)[:, None] >= jump_at, [150, 0, 0, 0], 0)
    gated = replace(preset("autotrack+"), redetect_span=0.0)
    plus = preset("autotrack+")
    for params, should_find in ((plus, True), (gated, False)):
        tracker, boxes, _ = _run(params, frames, sequence.boxes[0])
        search_side = tracker.window_size[0] * tracker.scale
        assert search_side / 2 < 150  # out of the ordinary search region's reach
        late = center_errors(boxes, truth)[jump_at + 3 :]
        assert (np.max(late) < 5.0) if should_find else (np.median(late) > 50.0)


# -- thin-target scale model -------------------------------------------------------------------


def test_scale_model_keeps_four_cells_across_a_thin_target():
    target = np.array([55.0, 13.0])  # rows, cols: a thin upright target
    params = PRESETS["autotrack"]
    backend = ReferenceBackend(params, None, (1, 1))
    release = ScaleFilter(params, target, target, np.array([120.0, 120.0]), (720, 1280), backend)
    assert release.model_size_hw[1] < 16  # area <= 512 px^2 leaves ~3 fHOG cells across
    plus = replace(params, scale_model_min_side=16.0)
    kept = ScaleFilter(plus, target, target, np.array([120.0, 120.0]), (720, 1280), backend)
    assert kept.model_size_hw[1] == 16
    assert kept.model_size_hw[0] / kept.model_size_hw[1] == pytest.approx(55 / 13, rel=0.05)


def test_plus_preset_tracks_the_generated_sequence_like_the_release():
    sequence = moving_target_sequence()
    _, boxes, _ = _run(preset("autotrack+"), sequence.frames, sequence.boxes[0])
    assert center_errors(boxes, sequence.boxes).max() < 4.0
    assert np.median(overlaps(boxes, sequence.boxes)) > 0.85


def test_faithful_preset_has_every_new_switch_off():
    faithful = PRESETS["autotrack"]
    assert not faithful.beyond_release and faithful.name == "autotrack"
    assert PRESETS["autotrack+"].beyond_release and PRESETS["autotrack+"].name == "autotrack+"
    assert math.isclose(PRESETS["autotrack+"].confidence_gate, 0.7)


# The 14 dev sequences of at most 200 frames (about 1,900 frames, under a minute per preset on an
# idle core); the four long ones (Dog1, S1301, Animal3, Yacht2) would double the run.
DEV_SUBSET = (
    "wakeboard7", "MountainBike6", "ball1", "Surfing06", "DragonBaby", "Gull1", "Crossing",
    "Animal1", "wakeboard3", "building5", "MotorRolling", "boat5", "group2_2", "bag",
)  # fmt: skip


@pytest.mark.slow
@needs_sequences
def test_plus_is_not_worse_than_the_faithful_preset_on_the_mean_over_dev_sequences():
    # Means over many sequences, never single ones: the tracker is chaotic under rounding, and
    # autotrack+'s measured gain (+0.015 AUC, +0.011 P@20 on all 18, docs/benchmarks.md) is
    # within that noise across CPUs. So no gain is asserted, only that autotrack+ is not clearly
    # worse: a broken mechanism (a gate that never learns, re-detection that jumps to clutter)
    # costs far more than 0.03 on the mean, the chaos of one machine against another far less.
    sequences = [s for s in load_sequences(SEQUENCES) if s.name in DEV_SUBSET]
    if len(sequences) < 10:
        pytest.skip(f"only {len(sequences)} of the dev subset found under {SEQUENCES}")
    means = {}
    for name in ("autotrack", "autotrack+"):
        scores = [
            score_sequence(s.name, run_task(name, s).boxes, s.ground_truth) for s in sequences
        ]
        means[name] = summarize(scores)
    faithful, plus = means["autotrack"], means["autotrack+"]
    assert plus.auc >= faithful.auc - 0.03, (plus, faithful)
    assert plus.precision >= faithful.precision - 0.03, (plus, faithful)
