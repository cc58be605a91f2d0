"""NanoTrack V2 (`autotrack.nanotrack`): the boxes of cv2.TrackerNano, the ground truth followed
on real frames, the score map's variations by AutoTrack's functions, refusals of bad models."""

from __future__ import annotations

import math
from dataclasses import replace

import cv2
import numpy as np
import pytest

from autotrack.errors import InputError
from autotrack.evaluation.datasets import load_otb_sequence
from autotrack.evaluation.metrics import overlaps
from autotrack.nanotrack import NanoTrack, NanoTrackParams
from autotrack.nanotrack.tracker import (
    BACKBONE,
    HEAD,
    INSTANCE_SIZE,
    SCORE_SIZE,
    TOTAL_STRIDE,
    foreground_at,
)
from autotrack.result import TrackResult
from autotrack.tracker import regularization
from tests.conftest import needs_sequences, shared_sequence_dir

SEQUENCES = [("DTB70", "Gull1"), ("DTB70", "MountainBike6"), ("OTB", "Crossing")]
FRAMES = 20


def _sequence(dataset: str, name: str):
    return load_otb_sequence(shared_sequence_dir(dataset, name))[0]


def _track(sequence, tracker, count: int):
    results = []
    with sequence.frames() as frames:
        for index in range(count):
            frame = frames.read(index)
            start = index == 0
            results.append(
                tracker.init(frame, sequence.init_box) if start else tracker.update(frame)
            )
    return results


@needs_sequences
@pytest.mark.parametrize(("dataset", "name"), SEQUENCES[:2])
def test_boxes_are_those_of_opencv_tracker_nano(dataset, name):
    sequence = _sequence(dataset, name)
    params = cv2.TrackerNano_Params()
    params.backbone, params.neckhead = str(BACKBONE), str(HEAD)
    reference = cv2.TrackerNano_create(params)
    start = tuple(round(v) for v in sequence.init_box)
    ours = NanoTrack()
    with sequence.frames() as frames:
        first = frames.read(0)
        reference.init(cv2.cvtColor(first, cv2.COLOR_RGB2BGR), start)
        ours.init(first, start)
        for index in range(1, 12):
            frame = frames.read(index)
            _, expected = reference.update(cv2.cvtColor(frame, cv2.COLOR_RGB2BGR))
            result = ours.update(frame)
            # cv2.TrackerNano truncates its box to integers; ours keeps the fractions.
            assert np.abs(np.trunc(result.box) - np.array(expected)).max() <= 1.0
            assert result.peak_score == pytest.approx(reference.getTrackingScore(), abs=1e-4)


@needs_sequences
def test_follows_the_ground_truth_over_the_first_frames():
    ious = []
    for dataset, name in SEQUENCES:
        sequence = _sequence(dataset, name)
        boxes = np.array([r.box for r in _track(sequence, NanoTrack(), FRAMES)])
        ious.append(np.nanmean(overlaps(boxes, sequence.ground_truth[:FRAMES])))
    assert np.mean(ious) > 0.5


@needs_sequences
def test_score_map_variations_are_autotracks():
    sequence = _sequence(*SEQUENCES[0])
    tracker = NanoTrack()
    with sequence.frames() as frames:
        first = tracker.init(frames.read(0), sequence.init_box)
        assert first.response_map is None and math.isnan(first.peak_score)
        previous, previous_cell = None, None
        for index in range(1, 6):
            current = tracker.update(frames.read(index))
            cell = np.subtract(tracker.peak_cell, SCORE_SIZE // 2).astype(float)
            assert current.response_map.shape == (SCORE_SIZE, SCORE_SIZE)
            assert 0.0 <= current.peak_score <= 1.0
            if previous is None:
                assert current.local_variation is None  # no previous map yet
            else:
                expected = regularization.local_variation(
                    current.response_map, tuple(cell), previous.response_map, tuple(previous_cell)
                )
                np.testing.assert_array_equal(current.local_variation, expected)
                assert current.global_variation == regularization.global_variation(expected)
                assert current.aberrant == (current.global_variation >= NanoTrackParams().phi)
            previous, previous_cell = current, cell


def test_foreground_at_reads_the_map_through_the_crop_geometry():
    score_map = np.arange(SCORE_SIZE * SCORE_SIZE, dtype=np.float32).reshape(SCORE_SIZE, -1)
    side = 2.0 * INSTANCE_SIZE  # two image pixels per crop pixel
    result = TrackResult(
        frame_index=1,
        box=(0.0, 0.0, 1.0, 1.0),
        peak_score=0.5,
        response_map=score_map,
        local_variation=None,
        global_variation=math.nan,
        theta_ref=math.nan,
        theta=math.nan,
        aberrant=False,
        scale_factor=1.0,
        search_box=(100.0, 40.0, side, side),
    )

    def image_point(row: float, col: float) -> tuple[float, float]:
        crop = [(cell - SCORE_SIZE // 2) * TOTAL_STRIDE + INSTANCE_SIZE // 2 for cell in (col, row)]
        return (100.0 + 2.0 * crop[0], 40.0 + 2.0 * crop[1])

    assert foreground_at(result, image_point(3, 11)) == pytest.approx(score_map[3, 11])
    between = foreground_at(result, image_point(3.5, 11.25))
    assert between == pytest.approx(3.5 * SCORE_SIZE + 11.25, abs=1e-3)  # bilinear
    assert foreground_at(result, image_point(-0.5, 4)) == 0.0  # above the first row of cells
    assert foreground_at(result, image_point(4, SCORE_SIZE - 0.5)) == 0.0
    assert math.isnan(foreground_at(replace(result, response_map=None), (0.0, 0.0)))


@needs_sequences
def test_foreground_at_is_high_on_the_target_and_low_beside_it_on_real_frames():
    sequence = _sequence("OTB", "Crossing")
    results = _track(sequence, NanoTrack(), 6)[1:]
    on_target, beside = [], []
    for index, result in enumerate(results, start=1):
        x, y, w, h = sequence.ground_truth[index]
        on_target.append(foreground_at(result, (x + w / 2.0, y + h / 2.0)))
        beside.append(foreground_at(result, (x + w / 2.0 + 2.0 * w, y + h / 2.0)))  # 2 widths off
    assert min(on_target) > 0.5 > max(beside)


def test_missing_model_is_refused_in_one_line(tmp_path):
    with pytest.raises(InputError, match="NanoTrack model not found") as error:
        NanoTrack(NanoTrackParams(backbone_path=tmp_path / "absent.onnx"))
    assert "\n" not in str(error.value)


def test_corrupt_model_is_refused_in_one_line(tmp_path):
    corrupt = tmp_path / "head.onnx"
    corrupt.write_bytes(HEAD.read_bytes()[:5000])
    with pytest.raises(InputError, match="cannot be loaded") as error:
        NanoTrack(NanoTrackParams(head_path=corrupt))
    assert "\n" not in str(error.value)


def test_update_before_init_and_a_zero_box_are_refused():
    tracker = NanoTrack()
    frame = np.zeros((120, 160, 3), np.uint8)
    with pytest.raises(InputError, match="before init"):
        tracker.update(frame)
    with pytest.raises(InputError, match="no area"):
        tracker.init(frame, (10, 10, 0, 5))
