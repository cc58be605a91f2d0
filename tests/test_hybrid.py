"""The hybrid tracker (`autotrack.hybrid`): each branch of the fusion rule on constructed cases,
the re-initialisations on real frames, and the hybrid on real sequences against both trackers."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from autotrack.evaluation.datasets import load_otb_sequence
from autotrack.evaluation.metrics import score_sequence
from autotrack.hybrid import HybridParams, HybridResult, HybridTracker, fuse
from autotrack.hybrid.tracker import (
    BOTH,
    FILTER,
    SIAMESE,
    SiameseReading,
    centres_agree,
    inside_frame,
    inverse_area_weight,
    likelihood_weight,
    mean_box,
    read_siamese,
)
from autotrack.result import TrackResult
from tests.conftest import needs_sequences, shared_sequence_dir

PARAMS = HybridParams()


def _reading(score: float, at_filter: float = 1.0, at_siamese: float = 1.0) -> SiameseReading:
    return SiameseReading(score, at_filter, at_siamese)


def _result(box, aberrant=False, theta=1.0, eta=0.01) -> TrackResult:
    return TrackResult(
        frame_index=5,
        box=box,
        peak_score=0.5,
        response_map=None,
        local_variation=None,
        global_variation=eta,
        theta_ref=1.0,
        theta=theta,
        aberrant=aberrant,
        scale_factor=1.0,
        search_box=(0.0, 0.0, 100.0, 100.0),
    )


PREVIOUS_BOX = (100.0, 100.0, 20.0, 20.0)
PREVIOUS = (PREVIOUS_BOX, PREVIOUS_BOX, PREVIOUS_BOX)  # hybrid, filter, Siamese
NEAR = (102.0, 101.0, 20.0, 20.0)  # the target moved a little
FAR = (160.0, 100.0, 20.0, 20.0)  # a look-alike three box widths away


def test_agreeing_trackers_average_their_boxes_weighted_by_inverse_area():
    siamese = (104.0, 103.0, 16.0, 24.0)
    unweighted = HybridParams(size_weighted=False)
    plain = fuse(_result(NEAR), _result(siamese), _reading(0.9), PREVIOUS, unweighted)
    assert plain.trusted == BOTH
    assert plain.box == pytest.approx((103.0, 102.0, 18.0, 22.0))
    assert not plain.reinit_filter and not plain.place_siamese
    # A Siamese box twice the filter's sides (four times its area) weighs a fifth.
    large = (92.0, 91.0, 40.0, 40.0)
    decision = fuse(_result(NEAR), _result(large), _reading(0.9), PREVIOUS, PARAMS)
    assert decision.trusted == BOTH
    assert decision.box == pytest.approx((0.8 * 102 + 0.2 * 92, 0.8 * 101 + 0.2 * 91, 24.0, 24.0))
    assert inverse_area_weight(NEAR, large) == pytest.approx(0.8)
    assert inverse_area_weight(large, NEAR) == pytest.approx(0.2)
    centred = fuse(
        _result(NEAR), _result(siamese), _reading(0.9), PREVIOUS, HybridParams(average_boxes=False)
    )
    assert centred.box == pytest.approx((104.0, 99.0, 16.0, 24.0))  # filter centre, Siamese shape


def test_each_agreeing_box_also_weighs_the_siamese_probability_at_its_centre():
    siamese = (104.0, 103.0, 16.0, 24.0)
    unweighted = HybridParams(size_weighted=False)
    # The network calls the filter's centre a quarter as likely on the target as its own: with
    # equal size weights the filter gets 0.25 / (0.25 + 1) = 0.2.
    decision = fuse(_result(NEAR), _result(siamese), _reading(0.9, 0.2, 0.8), PREVIOUS, unweighted)
    assert decision.box == pytest.approx(mean_box(NEAR, siamese, 0.2))
    assert likelihood_weight(0.8, 0.5, 0.5) == pytest.approx(0.8)  # equal: the size weights
    assert likelihood_weight(0.8, 0.0, 0.0) == 0.8  # no probability anywhere: the size weights
    assert likelihood_weight(0.5, 0.0, 0.7) == 0.0
    off = replace(unweighted, likelihood_weighted=False)
    plain = fuse(_result(NEAR), _result(siamese), _reading(0.9, 0.2, 0.8), PREVIOUS, off)
    assert plain.box == pytest.approx(mean_box(NEAR, siamese, 0.5))


def test_agreement_is_each_centre_within_the_other_box():
    assert centres_agree((0, 0, 20, 20), (9, 9, 20, 20), 1.0)
    assert not centres_agree((0, 0, 20, 20), (11, 0, 20, 20), 1.0)
    assert centres_agree((0, 0, 20, 20), (11, 0, 20, 20), 2.0)
    # A small box beside a large one: the large one's centre is outside the small one.
    assert not centres_agree((0, 0, 4, 4), (-10, -10, 30, 30), 1.0)


@pytest.mark.parametrize(("aberrant", "theta"), [(True, 1.0), (False, math.nan)])
def test_a_held_filter_gives_way_to_a_sure_siamese_box(aberrant, theta):
    held = _result(FAR, aberrant=aberrant, theta=theta)
    decision = fuse(held, _result(NEAR), _reading(0.8, 0.0), PREVIOUS, PARAMS)
    assert (decision.trusted, decision.box) == (SIAMESE, NEAR)
    assert not decision.reinit_filter and not decision.place_siamese
    restart = fuse(
        held, _result(NEAR), _reading(0.8, 0.0), PREVIOUS, HybridParams(reinit_filter=True)
    )
    assert restart.trusted == SIAMESE and restart.reinit_filter


def test_an_unsure_siamese_box_gives_way_to_the_filter_and_is_moved():
    for siamese, score in ((_result(FAR), 0.3), (_result(FAR, aberrant=True, eta=0.5), 0.9)):
        decision = fuse(_result(NEAR), siamese, _reading(score, 0.0), PREVIOUS, PARAMS)
        assert (decision.trusted, decision.box) == (FILTER, NEAR)
        assert decision.place_siamese and not decision.reinit_filter
    kept = fuse(
        _result(NEAR), _result(FAR), _reading(0.3, 0.0), PREVIOUS, HybridParams(place_siamese=False)
    )
    assert kept.trusted == FILTER and not kept.place_siamese


def test_a_tracker_that_jumped_is_not_credible():
    siamese_jumped = fuse(_result(NEAR), _result(FAR), _reading(0.9, 0.0), PREVIOUS, PARAMS)
    assert (siamese_jumped.trusted, siamese_jumped.box) == (FILTER, NEAR)
    assert siamese_jumped.place_siamese
    filter_jumped = fuse(_result(FAR), _result(NEAR), _reading(0.9, 0.0), PREVIOUS, PARAMS)
    assert (filter_jumped.trusted, filter_jumped.box) == (SIAMESE, NEAR)
    # Without continuity a sure Siamese network and a learning filter are both credible: the
    # filter is trusted, nobody restarts.
    off = fuse(
        _result(FAR), _result(NEAR), _reading(0.9, 0.0), PREVIOUS, HybridParams(continuity=False)
    )
    assert (off.trusted, off.box, off.place_siamese) == (FILTER, FAR, False)


def test_a_filter_box_the_siamese_map_corroborates_is_trusted_held_or_not():
    held = _result(FAR, aberrant=True)
    apart = (PREVIOUS_BOX, (158.0, 100.0, 20.0, 20.0), PREVIOUS_BOX)  # the filter did not jump
    # Without the cross-check a sure, continuous Siamese box beats a held filter (rule 3) ...
    plain = fuse(held, _result(NEAR), _reading(0.9, 0.8), apart, HybridParams(cross_check=False))
    assert (plain.trusted, plain.box) == (SIAMESE, NEAR)
    # ... but the network's own map calls the filter's centre foreground: the filter is trusted
    # and the Siamese track moved onto it.
    checked = fuse(held, _result(NEAR), _reading(0.9, 0.8), apart, PARAMS)
    assert (checked.trusted, checked.box, checked.place_siamese) == (FILTER, FAR, True)
    assert not checked.reinit_filter
    assert (
        fuse(held, _result(NEAR), _reading(0.9, 0.4), apart, PARAMS).trusted == SIAMESE
    )  # background
    # Corroboration does not excuse a jump: the filter came from the previous box, 3 widths off.
    jumped = fuse(held, _result(NEAR), _reading(0.9, 0.8), PREVIOUS, PARAMS)
    assert (jumped.trusted, jumped.box) == (SIAMESE, NEAR)
    # Nor does it override agreement (rule 1).
    assert fuse(_result(NEAR), _result(NEAR), _reading(0.9, 0.8), PREVIOUS, PARAMS).trusted == BOTH


def test_both_or_neither_credible_trusts_the_smaller_jump_from_the_hybrid_box():
    # Both moved continuously from their own last boxes, which were apart: the Siamese box is
    # where the hybrid was.
    apart = (PREVIOUS_BOX, (158.0, 100.0, 20.0, 20.0), PREVIOUS_BOX)
    both = fuse(_result(FAR), _result(NEAR), _reading(0.9, 0.0), apart, PARAMS)
    assert (both.trusted, both.box) == (SIAMESE, NEAR)
    assert not both.reinit_filter and not both.place_siamese
    # A held filter and an unsure Siamese network: neither credible, the filter did not jump.
    neither = fuse(
        _result(NEAR, theta=math.nan), _result(FAR), _reading(0.3, 0.0), PREVIOUS, PARAMS
    )
    assert (neither.trusted, neither.box, neither.place_siamese) == (FILTER, NEAR, False)


def test_inside_frame_clips_a_box_to_the_image():
    assert inside_frame((-5.0, 10.0, 20.0, 20.0), (100, 50)) == (0.0, 10.0, 15.0, 20.0)
    assert inside_frame((98.0, 49.0, 20.0, 20.0), (100, 50)) == (98.0, 48.0, 2.0, 2.0)


def _run(sequence, tracker, count):
    boxes, results = [], []
    with sequence.frames() as frames:
        for index in range(count):
            frame = frames.read(index)
            result = tracker.init(frame, sequence.init_box) if index == 0 else tracker.update(frame)
            boxes.append(result.box)
            results.append(result)
    return np.array(boxes), results


class _StuckFilter:
    """A correlation filter stuck on a box away from the target, held (aberrant) or learning."""

    def __init__(self, box, held: bool) -> None:
        self.box, self.held = box, held

    def update(self, frame_rgb):
        return _result(self.box, aberrant=self.held)


@needs_sequences
def test_the_hybrid_restarts_the_filter_or_moves_the_siamese_track_on_real_frames():
    from autotrack import AutoTrack

    sequence = load_otb_sequence(shared_sequence_dir("DTB70", "Gull1"))[0]
    tracker = HybridTracker()
    _, results = _run(sequence, tracker, 4)
    assert all(isinstance(r, HybridResult) for r in results)
    assert [r.frame_index for r in results] == [0, 1, 2, 3]
    assert results[-1].trusted == BOTH
    own = results[-1].filter_result.box, results[-1].siamese_result.box
    weight = inverse_area_weight(*own)
    assert 0.0 < weight < 1.0 and weight != 0.5
    reading = read_siamese(results[-1].siamese_result, tracker.siamese.peak_cell, own[0])
    assert 0.5 < reading.at_filter < 1.0 and 0.5 < reading.at_siamese <= 1.0
    weight = likelihood_weight(weight, reading.at_filter, reading.at_siamese)
    assert results[-1].box == pytest.approx(mean_box(*own, weight))  # the weighted mean
    with sequence.frames() as frames:
        frame = frames.read(4)
    stuck_box = (5.0, 5.0, 30.0, 30.0)  # the top-left corner, far from the gull
    tracker = HybridTracker(HybridParams(reinit_filter=True, agree_radius=2.0))  # a fast gull
    _run(sequence, tracker, 4)
    tracker.filter = _StuckFilter(stuck_box, held=True)
    result = tracker.update(frame)  # NanoTrack is sure of the gull: it wins, the filter restarts
    assert result.trusted == SIAMESE
    assert result.box == result.siamese_result.box
    assert isinstance(tracker.filter, AutoTrack)
    assert tracker.filter.update(frame).box == pytest.approx(result.box, abs=2.0)

    unsure = HybridTracker(HybridParams(siamese_confident=1.01))  # never sure
    _run(sequence, unsure, 4)
    unsure.filter = _StuckFilter(stuck_box, held=False)
    unsure.filter_box = stuck_box  # it has been stuck there: it did not jump
    result = unsure.update(frame)
    assert (result.trusted, result.box) == (FILTER, stuck_box)
    assert unsure.siamese.position == pytest.approx([20.0, 20.0])  # moved to the filter's box


@needs_sequences
def test_the_siamese_map_corroborates_a_held_filter_on_the_target_on_real_frames():
    sequence = load_otb_sequence(shared_sequence_dir("DTB70", "Gull1"))[0]
    with sequence.frames() as frames:
        frame = frames.read(6)  # the gull flies fast at first: a Siamese box that keeps up
    decisions = {}
    for label, cross_check, on_target in (
        ("on the gull", True, True),
        ("on the gull, no cross-check", False, True),
        ("away from the gull", True, False),
    ):
        tracker = HybridTracker(HybridParams(cross_check=cross_check))
        _run(sequence, tracker, 6)
        x, y, w, h = tracker.siamese_box
        # A held filter with a small box: on the gull, a third of the gull's width beside the
        # Siamese centre (outside the small box: they disagree), or two widths away.
        offset = w / 3.0 if on_target else 2.0 * w
        stuck_box = (x + w / 2.0 + offset - 3.0, y + h / 2.0 - 3.0, 6.0, 6.0)
        tracker.filter = _StuckFilter(stuck_box, held=True)
        tracker.filter_box = stuck_box  # it has been held there: it did not jump
        result = tracker.update(frame)
        assert not centres_agree(stuck_box, result.siamese_result.box, 1.0)
        decisions[label] = result.trusted, result.box == stuck_box
    assert decisions == {
        "on the gull": (FILTER, True),
        "on the gull, no cross-check": (SIAMESE, False),
        "away from the gull": (SIAMESE, False),
    }


SEQUENCES = [("DTB70", "Gull1"), ("DTB70", "Animal1"), ("OTB", "DragonBaby"), ("OTB", "Crossing")]


@needs_sequences
@pytest.mark.slow
def test_the_hybrid_is_not_worse_than_either_tracker_on_the_mean():
    from autotrack import AutoTrack, preset
    from autotrack.nanotrack import NanoTrack

    aucs = {"hybrid": [], "filter": [], "siamese": []}
    for dataset, name in SEQUENCES:
        sequence = load_otb_sequence(shared_sequence_dir(dataset, name))[0]
        makers = {
            "hybrid": HybridTracker,
            "filter": lambda: AutoTrack(preset("autotrack+")),
            "siamese": NanoTrack,
        }
        for label, make in makers.items():
            boxes, _ = _run(sequence, make(), len(sequence))
            aucs[label].append(score_sequence(name, boxes, sequence.ground_truth).auc)
    mean = {label: float(np.mean(values)) for label, values in aucs.items()}
    assert mean["hybrid"] >= max(mean["filter"], mean["siamese"]) - 0.01


def test_make_tracker_builds_every_named_tracker():
    from autotrack import AutoTrack
    from autotrack.errors import InputError
    from autotrack.hybrid.factory import TRACKERS, make_tracker
    from autotrack.nanotrack import NanoTrack

    assert {"autotrack", "autotrack+", "nanotrack", "hybrid"} <= set(TRACKERS)
    assert isinstance(make_tracker("NanoTrack"), NanoTrack)
    assert isinstance(make_tracker(" autotrack+ "), AutoTrack)
    hybrid = make_tracker("hybrid")
    assert isinstance(hybrid, HybridTracker)
    assert hybrid.params.filter_params == HybridParams().filter_params
    with pytest.raises(InputError, match="unknown tracker 'kcf2'"):
        make_tracker("kcf2")


@needs_sequences
def test_the_benchmark_runs_nanotrack_and_the_hybrid_by_name():
    from autotrack.evaluation.peers import TRACKER_NAMES, make_tracker

    assert {"nanotrack", "hybrid", "csrt"} <= set(TRACKER_NAMES)
    sequence = load_otb_sequence(shared_sequence_dir("OTB", "Crossing"))[0]
    for name in ("nanotrack", "hybrid"):
        tracker = make_tracker(name)
        with sequence.frames() as frames:
            boxes = [tracker.init(frames.read(0), sequence.init_box)]
            boxes += [tracker.update(frames.read(index)) for index in (1, 2)]
        assert all(len(box) == 4 and all(isinstance(v, float) for v in box) for box in boxes)
        assert score_sequence("Crossing", np.array(boxes), sequence.ground_truth[:3]).auc > 0.5
