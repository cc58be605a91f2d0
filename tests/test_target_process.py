"""Targets spread over child processes (`MultiTracker(processes=N)`): bit for bit the results of
one process, per-target add / remove / reset wherever the target lives, errors that name their
cause, children that stop with the tracker."""

from __future__ import annotations

import json

import numpy as np
import pytest

from autotrack.errors import InputError
from autotrack.io.frames import open_frames
from autotrack.localization.scene import load_scene
from autotrack.params import preset
from autotrack.pipeline import localize_sequence
from autotrack.tracker.multi import MultiTracker
from autotrack.tracker.target_process import WorkerError, stop_idle_processes
from tests import test_localize, test_multi
from tests.test_multi import run

# the generated sequences of the multi-target and localisation tests (session fixtures)
landmarks_sequence = test_multi.landmarks_sequence
short_sequence = test_localize.short_sequence

MAPS = ("response_map", "local_variation", "spatial_window")


def assert_identical(expected: dict, got: dict) -> None:
    assert list(got) == list(expected)
    for target_id, result in expected.items():
        other = got[target_id]
        assert other.box == result.box and other.frame_index == result.frame_index
        assert np.array_equal(other.peak_score, result.peak_score, equal_nan=True)
        for name in MAPS:
            a, b = getattr(result, name), getattr(other, name)
            assert (a is None and b is None) or np.array_equal(a, b), (target_id, name)


def test_child_processes_give_the_results_of_one_process_bit_for_bit(landmarks_sequence):
    frames, boxes, _ = landmarks_sequence
    params = preset("autotrack")
    with MultiTracker(params, boxes) as alone, MultiTracker(params, boxes, processes=3) as spread:
        expected = run(alone, frames, boxes)
        got = run(spread, frames, boxes)
        owners = list(spread._owners.values())
    assert sorted(owners) == [0, 0, 1, 2]  # two targets here, one in each child
    for a, b in zip(expected, got, strict=True):
        assert_identical(a, b)


def test_add_remove_and_reset_reach_the_process_holding_the_target(landmarks_sequence):
    frames, boxes, truth = landmarks_sequence
    params = preset("autotrack")
    corrected = tuple(truth["C"][4])
    answers = []
    for processes in (1, 2):
        with MultiTracker(params, processes=processes) as tracker:
            steps = [tracker.init(frames[0], {"A": boxes["A"], "B": boxes["B"]})]
            steps += [tracker.update(frame) for frame in frames[1:4]]
            steps.append({"C": tracker.add_target("C", frames[3], tuple(truth["C"][3]))})
            steps.append(tracker.update(frames[4]))
            steps.append({"C": tracker.reset_target("C", frames[4], corrected)})
            tracker.remove_target("A")
            steps += [tracker.update(frame) for frame in frames[5:8]]
            assert tracker.target_ids == ("B", "C")
            if processes == 2:
                assert tracker._owners == {"B": 1, "C": 0}
            answers.append(steps)
    for a, b in zip(*answers, strict=True):
        assert_identical(a, b)


def test_a_childs_input_error_reaches_the_caller_and_the_tracker_goes_on(landmarks_sequence):
    frames, boxes, _ = landmarks_sequence
    with MultiTracker(preset("autotrack"), processes=2) as tracker:
        tracker.init(frames[0], {"A": boxes["A"]})
        with pytest.raises(InputError, match="outside the"):
            tracker.add_target("B", frames[0], (5000.0, 5000.0, 20.0, 20.0))  # a child's
        assert tracker.target_ids == ("A",)
        tracker.add_target("B", frames[0], boxes["B"])
        assert set(tracker.update(frames[1])) == {"A", "B"}


def test_a_lost_child_is_named_and_closed_trackers_lend_their_children(landmarks_sequence):
    frames, boxes, _ = landmarks_sequence
    tracker = MultiTracker(preset("autotrack"), processes=2)
    tracker.init(frames[0], boxes)
    child = tracker._children[0]._process
    child.kill()
    child.wait()
    with pytest.raises(WorkerError, match=f"tracking process {child.pid}"):
        tracker.update(frames[1])
    tracker.close()
    with MultiTracker(preset("autotrack"), processes=2) as first:
        first.init(frames[0], boxes)
        lent = first._children[0]
    assert lent.pid != child.pid  # the dead child was not given back
    with MultiTracker(preset("autotrack"), processes=2) as second:
        assert second._children[0] is lent  # started once, reused
        assert set(second.init(frames[0], boxes)) == set(boxes)
    stop_idle_processes()
    assert not lent.alive()
    with pytest.raises(InputError, match="processes must be at least 1"):
        MultiTracker(preset("autotrack"), processes=0)


def test_localisation_with_two_processes_gives_the_same_poses(short_sequence):
    scene = load_scene(short_sequence / "scene.json")
    boxes = json.loads((short_sequence / "boxes.json").read_text())
    with open_frames(short_sequence) as source:
        frames = [source.read(index) for index in range(8)]
    runs = [
        list(localize_sequence(frames, scene, boxes, preset("autotrack"), processes=processes))
        for processes in (1, 2)
    ]
    for one, two in zip(*runs, strict=True):
        assert {k: t.box for k, t in one.tracks.items()} == {
            k: t.box for k, t in two.tracks.items()
        }
        assert one.pose.valid and np.array_equal(one.pose.position, two.pose.position)
