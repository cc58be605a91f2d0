"""OPE metrics against hand-computed cases and the OTB toolkit's formulas."""

from __future__ import annotations

import numpy as np
import pytest

from autotrack.evaluation.metrics import (
    PRECISION_THRESHOLDS,
    SUCCESS_THRESHOLDS,
    auc,
    center_errors,
    overlaps,
    precision_curve,
    score_sequence,
    success_curve,
    summarize,
    summarize_by_attribute,
    summarize_by_dataset,
)

NAN_BOX = [np.nan] * 4


def test_threshold_grids_match_the_toolkits():
    assert PRECISION_THRESHOLDS.tolist() == list(range(51))
    assert len(SUCCESS_THRESHOLDS) == 21
    np.testing.assert_allclose(SUCCESS_THRESHOLDS, np.arange(21) * 0.05, atol=1e-15)


def test_overlaps_hand_computed():
    pred = np.array(
        [
            [0, 0, 10, 10],  # identical
            [0, 0, 10, 10],  # shifted by half: 25 / 175
            [0, 0, 10, 10],  # gt inside pred: 25 / 100
            [0, 0, 10, 10],  # edges touch: 0
            [20, 20, 5, 5],  # disjoint
        ],
        dtype=float,
    )
    gt = np.array(
        [[0, 0, 10, 10], [5, 5, 10, 10], [2, 2, 5, 5], [10, 0, 10, 10], [0, 0, 5, 5]], dtype=float
    )
    np.testing.assert_allclose(overlaps(pred, gt), [1.0, 25 / 175, 0.25, 0.0, 0.0])


def test_overlaps_equal_the_otb_toolkit_inclusive_pixel_formula():
    rng = np.random.default_rng(3)
    pred = np.column_stack([rng.uniform(0, 50, (200, 2)), rng.uniform(1, 40, (200, 2))])
    gt = np.column_stack([rng.uniform(0, 50, (200, 2)), rng.uniform(1, 40, (200, 2))])
    # calcRectInt.m: right = left + w - 1, intersection = max(0, min(right) - max(left) + 1).
    width = np.maximum(
        0,
        np.minimum(pred[:, 0] + pred[:, 2] - 1, gt[:, 0] + gt[:, 2] - 1)
        - np.maximum(pred[:, 0], gt[:, 0])
        + 1,
    )
    height = np.maximum(
        0,
        np.minimum(pred[:, 1] + pred[:, 3] - 1, gt[:, 1] + gt[:, 3] - 1)
        - np.maximum(pred[:, 1], gt[:, 1])
        + 1,
    )
    intersection = width * height
    toolkit = intersection / (pred[:, 2] * pred[:, 3] + gt[:, 2] * gt[:, 3] - intersection)
    np.testing.assert_allclose(overlaps(pred, gt), toolkit, rtol=1e-12)


def test_invalid_ground_truth_is_excluded_and_invalid_prediction_fails():
    pred = np.array([[0, 0, 10, 10], NAN_BOX, [0, 0, 0, 10], [0, 0, 10, 10]], dtype=float)
    gt = np.array([NAN_BOX, [0, 0, 10, 10], [0, 0, 10, 10], [0, 0, 10, -1]], dtype=float)
    ious = overlaps(pred, gt)
    errors = center_errors(pred, gt)
    assert np.isnan(ious[0]) and np.isnan(errors[0])
    assert ious[1] == 0.0 and errors[1] == np.inf
    assert ious[2] == 0.0 and errors[2] == np.inf
    assert np.isnan(ious[3]) and np.isnan(errors[3])


def test_center_errors_hand_computed():
    pred = np.array([[3, 4, 10, 10], [0, 0, 4, 4]], dtype=float)
    gt = np.array([[0, 0, 10, 10], [0, 0, 10, 10]], dtype=float)
    np.testing.assert_allclose(center_errors(pred, gt), [5.0, np.sqrt(18.0)])


def test_precision_curve_counts_errors_at_or_below_threshold():
    errors = np.array([0.0, 5.0, 20.0, 20.5, np.nan, np.inf])
    curve = precision_curve(errors)
    assert curve[0] == pytest.approx(1 / 5)  # error 0 <= 0
    assert curve[5] == pytest.approx(2 / 5)
    assert curve[20] == pytest.approx(3 / 5)  # 20 <= 20, 20.5 is not
    assert curve[21] == pytest.approx(4 / 5)
    assert curve[50] == pytest.approx(4 / 5)  # inf never counts
    assert precision_curve(errors, np.array([20.0]))[0] == pytest.approx(0.6)


def test_success_curve_counts_overlaps_strictly_above_threshold():
    ious = np.array([1.0, 0.5, 0.25, 0.0, np.nan])
    curve = success_curve(ious)
    assert curve[0] == pytest.approx(3 / 4)  # 0 is not > 0
    assert curve[5] == pytest.approx(2 / 4)  # t = 0.25: 0.25 is not > 0.25
    assert curve[10] == pytest.approx(1 / 4)  # t = 0.5
    assert curve[20] == 0.0  # t = 1: nothing is > 1
    # IoU 1 counts at 20 thresholds, 0.5 at 10 (t < 0.5), 0.25 at 5 (t < 0.25).
    assert auc(curve) == pytest.approx(35 / (4 * 21))


def test_perfect_tracking_scores_one_precision_and_twenty_of_21_auc():
    gt = np.array([[10, 10, 20, 30], [12, 11, 20, 30]], dtype=float)
    score = score_sequence("s", gt, gt)
    assert score.precision == 1.0
    assert score.auc == pytest.approx(20 / 21)
    assert score.scored_frames == 2


def test_sequence_without_scored_frames_is_left_out_of_averages():
    gt = np.array([NAN_BOX, NAN_BOX])
    empty = score_sequence("empty", gt, gt)
    assert np.isnan(empty.precision) and empty.scored_frames == 0
    good = score_sequence("good", np.array([[0, 0, 5, 5.0]]), np.array([[0, 0, 5, 5.0]]))
    summary = summarize([empty, good])
    assert summary.sequences == 1
    assert summary.precision == 1.0


def test_summary_weights_sequences_equally_not_frames():
    box = np.array([[0, 0, 10, 10.0]])
    far = np.array([[100, 100, 10, 10.0]])
    short_perfect = score_sequence("a", np.repeat(box, 2, 0), np.repeat(box, 2, 0), {"SV"}, "D1")
    long_failed = score_sequence(
        "b", np.repeat(far, 6, 0), np.repeat(box, 6, 0), {"SV", "OCC"}, "D2"
    )
    summary = summarize([short_perfect, long_failed])
    assert summary.precision == pytest.approx(0.5)  # frame-weighted would be 2/8
    assert summary.auc == pytest.approx((20 / 21) / 2)

    by_attribute = summarize_by_attribute([short_perfect, long_failed])
    assert list(by_attribute) == ["OCC", "SV"]
    assert by_attribute["OCC"].sequences == 1 and by_attribute["OCC"].precision == 0.0
    assert by_attribute["SV"].sequences == 2 and by_attribute["SV"].precision == pytest.approx(0.5)
    by_dataset = summarize_by_dataset([short_perfect, long_failed])
    assert by_dataset["D1"].precision == 1.0 and by_dataset["D2"].precision == 0.0


def test_mismatched_lengths_are_rejected():
    with pytest.raises(ValueError, match="3 predicted boxes for 2"):
        overlaps(np.zeros((3, 4)), np.zeros((2, 4)))
