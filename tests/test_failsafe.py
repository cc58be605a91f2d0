"""`autotrack+` fail-safe on the generated aerial scenes (autotrack/synthetic/aerial.py): each
mechanism acts only when its own evidence says the target is lost or changing.

Each scene reproduces a pattern seen on unseen UAV sequences where `autotrack+` did worse than
the faithful preset; before the fixes every test below failed (AUC on the two seeds' mean:
road 0.49 against the faithful 0.80, walkers 0.42 against 0.73, tiny car 0.42 against 0.75;
one-frame jumps of 38-64 px onto another car, a tiny car's box reshaped to 0.65 of its aspect;
in the walker crowd, seeds 5-6, 0.68 against 0.76, the box grown to 1.8-2.2x the target).
"""

from __future__ import annotations

from dataclasses import replace
from types import SimpleNamespace

import numpy as np
import pytest

from autotrack import AutoTrack, preset
from autotrack.errors import InputError
from autotrack.evaluation.metrics import center_errors, score_sequence
from autotrack.io import otb_boxes
from autotrack.io.frames import open_frames
from autotrack.params import TrackerParams
from autotrack.synthetic.aerial import SCENES, aerial_scene, render_aerial
from autotrack.tracker.plus.memory import lookalike_within
from autotrack.tracker.plus.tracker import AutoTrackPlus
from tests.conftest import SEQUENCES, needs_sequences

SEEDS = (1, 2)
CROWD_SEEDS = (5, 6)
"""The walker crowd's seeds: on seeds 1-4 the pattern does not show (seeds 1, 3: the box stays
within 1.31x for both presets) or is not the one fixed here (seeds 2, 4: the neighbour merges with
the target into one peak and the box grows regardless; docs/tracker.md)."""


def _track(params: TrackerParams, sequence) -> np.ndarray:
    tracker = AutoTrack(params)
    boxes = [tracker.init(sequence.frames[0], sequence.boxes[0]).box]
    boxes += [tracker.update(frame).box for frame in sequence.frames[1:]]
    return np.array(boxes)


def _jumps(boxes: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """Per frame, how far the box centre moved beyond the true centre's own motion (px)."""
    centres = boxes[:, :2] + boxes[:, 2:] / 2
    true_centres = truth[:, :2] + truth[:, 2:] / 2
    return np.hypot(*np.diff(centres - true_centres, axis=0).T)


@pytest.fixture(scope="module", params=SCENES)
def scene_runs(request):
    """(scene name, [(sequence, faithful boxes, autotrack+ boxes) per seed])."""
    runs = []
    for seed in CROWD_SEEDS if request.param == "walker_crowd" else SEEDS:
        sequence = render_aerial(aerial_scene(request.param, seed))
        runs.append(
            (
                sequence,
                _track(preset("autotrack"), sequence),
                _track(preset("autotrack+"), sequence),
            )
        )
    return request.param, runs


def test_plus_is_not_worse_than_the_faithful_preset_on_a_failure_pattern(scene_runs):
    name, runs = scene_runs
    faithful = np.mean([score_sequence(name, f, s.boxes).auc for s, f, _ in runs])
    plus = np.mean([score_sequence(name, p, s.boxes).auc for s, _, p in runs])
    assert plus >= faithful - 0.05, (name, plus, faithful)


def test_plus_never_jumps_a_target_length_in_one_frame_nor_ends_off_it(scene_runs):
    # Re-detection, a turn or the memory moving a confident track onto a look-alike shows as
    # a jump of the box against the truth; the faithful preset's largest is 6 px (the tiny
    # car under a tree crown).
    # The memory taking a neighbour in the walker group is a slide of 9-13 px, not a jump:
    # it shows as a track that ends on another walker, a target width or more off.
    name, runs = scene_runs
    for sequence, _, plus in runs:
        length, width = float(np.max(sequence.boxes[0, 2:])), float(np.min(sequence.boxes[0, 2:]))
        assert _jumps(plus, sequence.boxes).max() < length, name
        assert center_errors(plus, sequence.boxes)[-10:].max() < width, name


def test_plus_keeps_the_box_size_and_shape_of_the_target(scene_runs):
    name, runs = scene_runs
    for sequence, _, plus in runs:
        area = plus[:, 2] * plus[:, 3] / (sequence.boxes[:, 2] * sequence.boxes[:, 3])
        aspect = (plus[:, 2] / plus[:, 3]) / (sequence.boxes[:, 2] / sequence.boxes[:, 3])
        assert np.all((area > 1 / 1.5) & (area < 1.5)), name
        assert np.all((aspect > 0.8) & (aspect < 1.25)), name


def _area_ratios(boxes: np.ndarray, truth: np.ndarray) -> np.ndarray:
    return boxes[:, 2] * boxes[:, 3] / (truth[:, 2] * truth[:, 3])


def test_the_scale_does_not_grow_over_a_lookalike_in_a_crowd():
    # A walker entering a crowd, one walker passing over it: without the guard the box of
    # `autotrack+` grows to ~2x the target and stays there; the faithful preset's stays < 1.5x.
    sequence = render_aerial(aerial_scene("walker_crowd", 6))
    plus = preset("autotrack+")
    faithful = _area_ratios(_track(preset("autotrack"), sequence), sequence.boxes)
    unguarded = _area_ratios(_track(replace(plus, lookalike_reach=0.0), sequence), sequence.boxes)
    guarded = _area_ratios(_track(plus, sequence), sequence.boxes)
    assert faithful.max() < 1.5
    assert unguarded.max() > 1.8 and np.median(unguarded[-20:]) > 1.6
    assert guarded.max() < 1.4 and np.median(guarded[-20:]) < 1.3


def _gull_boxes(monkeypatch, sighted_frames: set[int] | None) -> np.ndarray:
    """autotrack+ over Gull1's first 20 frames; `sighted_frames`: the frames (0-based) on which
    the scale guard's look-alike test, where it runs, sees a look-alike (None: the guard off)."""
    folder = SEQUENCES / "DTB70" / "Gull1"
    truth = otb_boxes.read_boxes(folder / "groundtruth_rect.txt")
    with open_frames(folder) as source:
        frames = [source.read(index) for index in range(20)]

    def sighting(tracker, *args) -> bool:
        return tracker.frame_number - 1 in sighted_frames

    plus = preset("autotrack+")
    if sighted_frames is None:
        plus = replace(plus, lookalike_reach=0.0)
    else:
        monkeypatch.setattr(AutoTrackPlus, "_absorbs_lookalike", sighting)
    return _track(plus, SimpleNamespace(frames=frames, boxes=truth))


@needs_sequences
def test_a_lookalike_seen_on_one_frame_only_does_not_hold_the_scale(monkeypatch):
    # On Gull1 the scale filter asks to grow on frame 11 (the real look-alike test sees the
    # gull's own second peak on frames 10 and 11 and holds it). A look-alike must persist: seen
    # on frame 11 alone it holds nothing; seen on 10 and 11 it holds that growth.
    unguarded = _gull_boxes(monkeypatch, None)
    np.testing.assert_array_equal(_gull_boxes(monkeypatch, {11}), unguarded)
    held = _gull_boxes(monkeypatch, {10, 11})
    assert np.array_equal(held[:11], unguarded[:11])
    assert held[11, 2] * held[11, 3] < unguarded[11, 2] * unguarded[11, 3]


def test_a_lookalike_counts_within_the_reach_on_both_axes_and_not_the_target_itself():
    shape = (40, 40)
    target = (0.4, -0.3)  # the target's peak (0, 0), refined
    reach = np.array([6.0, 2.5])  # (rows, cols) in cells
    assert not lookalike_within([(0, 0)], target, shape, reach)  # the target alone
    assert lookalike_within([(0, 0), (-4, 0)], target, shape, reach)  # a walker over it
    assert lookalike_within([(0, 0), (35, 1)], target, shape, reach)  # wrapped: (-5, 1)
    assert not lookalike_within([(0, 0), (-4, 3)], target, shape, reach)  # beside the box
    assert not lookalike_within([(0, 0), (7, 0)], target, shape, reach)  # beyond its end


def test_re_detection_waits_for_a_loss_and_a_turn_for_a_target_large_enough_to_show_one():
    sequence = render_aerial(aerial_scene("road_lookalikes", 1))
    plus = preset("autotrack+")
    hasty = replace(plus, redetect_patience=1)  # re-detection on the first frame below the gate
    assert _jumps(_track(hasty, sequence), sequence.boxes).max() > 24.0  # onto another car
    assert _jumps(_track(plus, sequence), sequence.boxes).max() < 24.0
    tiny = AutoTrack(plus)
    tiny_sequence = render_aerial(aerial_scene("tiny_vehicle", 1))
    tiny.init(tiny_sequence.frames[0], tiny_sequence.boxes[0])
    assert not tiny._turns_resolved()  # 11 px: a 10 degree turn moves its ends by < 1 px
    large = AutoTrack(plus)
    large.init(tiny_sequence.frames[0], (100.0, 100.0, 40.0, 20.0))
    assert large._turns_resolved()


def test_aerial_scenes_are_seeded_and_bad_names_refused():
    first = render_aerial(replace(aerial_scene("tiny_vehicle", 3), frames=3))
    again = render_aerial(replace(aerial_scene("tiny_vehicle", 3), frames=3))
    np.testing.assert_array_equal(first.frames[2], again.frames[2])
    assert first.frames[0].shape == (240, 320, 3) and first.boxes.shape == (3, 4)
    np.testing.assert_allclose(first.boxes[0, 2:], (11, 8))
    with pytest.raises(InputError, match="unknown aerial scene"):
        aerial_scene("highway")
    with pytest.raises(InputError, match="at least 2 frames"):
        render_aerial(replace(aerial_scene("tiny_vehicle"), frames=1))
