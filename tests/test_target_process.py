"""Targets spread over child processes (`MultiTracker(processes=N)`): bit for bit the results of
one process, per-target add / remove / reset wherever the target lives, errors that name their
cause, children that stop with the tracker."""

from __future__ import annotations

import argparse
import json

import numpy as np
import pytest

from autotrack.errors import InputError
from autotrack.io.frames import open_frames
from autotrack.localization.scene import load_scene
from autotrack.params import preset
from autotrack.pipeline import localize_sequence
from autotrack.tracker.parallel import multi
from autotrack.tracker.parallel.multi import MultiTracker
from autotrack.tracker.parallel.target_process import WorkerError, WorkerPool
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
    pool = WorkerPool()
    tracker = MultiTracker(preset("autotrack"), processes=2, worker_pool=pool)
    tracker.init(frames[0], boxes)
    child = tracker._children[0]._process
    child.kill()
    child.wait()
    with pytest.raises(WorkerError, match=f"tracking process {child.pid}"):
        tracker.update(frames[1])
    tracker.close()
    assert pool.idle == 0  # the dead child was not given back
    with MultiTracker(preset("autotrack"), processes=2, worker_pool=pool) as first:
        first.init(frames[0], boxes)
        lent = first._children[0]
    assert lent.pid != child.pid and pool.idle == 1
    with MultiTracker(preset("autotrack"), processes=2, worker_pool=pool) as second:
        assert set(second.init(frames[0], boxes)) == set(boxes)
        assert second._children[0] is lent  # started once, reused
    pool.close()
    assert not lent.alive() and pool.idle == 0
    with pytest.raises(InputError, match="processes must be at least 1"):
        MultiTracker(preset("autotrack"), processes=0)


def test_a_child_starts_with_its_first_target_and_stops_with_a_tracker_of_its_own(
    landmarks_sequence,
):
    frames, boxes, _ = landmarks_sequence
    first, *others = boxes
    with MultiTracker(preset("autotrack"), processes=2) as tracker:
        tracker.init(frames[0], {first: boxes[first]})
        tracker.update(frames[1])
        assert tracker._children == [None]  # one target: tracked here, no child started
        tracker.add_target(others[0], frames[1], boxes[others[0]])
        child = tracker._children[0]
        assert child is not None and child.alive()
        assert set(tracker.update(frames[2])) == {first, others[0]}
    assert not child.alive()  # the tracker's own pool stopped it


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


@pytest.mark.parametrize(
    ("cores", "targets", "expected"),
    [(2, 4, (1, 2)), (8, 2, (1, 2)), (1, 4, (2, 1)), (2, 1, (1, 1)), (1, 1, (1, 1))],
)
def test_several_targets_on_several_cores_default_to_two_processes(
    monkeypatch, cores, targets, expected
):
    monkeypatch.setattr(multi, "available_cores", lambda: cores)
    assert multi.default_concurrency(targets) == expected
    assert multi.chosen_concurrency(None, None, targets) == expected
    assert multi.chosen_concurrency(3, None, targets) == (3, 1)  # threads chosen: one process
    assert multi.chosen_concurrency(None, 3, targets) == (1, 3)
    assert multi.chosen_concurrency(None, 1, targets) == (2, 1)
    assert multi.chosen_concurrency(2, 2, targets) == (2, 2)


def test_the_app_and_localize_take_the_default(monkeypatch, tmp_path):
    from autotrack.cli.localize import _choose_concurrency
    from autotrack_studio.config import AppConfig

    monkeypatch.setattr(multi, "available_cores", lambda: 2)
    assert AppConfig(sessions_dir=tmp_path).tracker_concurrency == (1, 2)
    assert AppConfig(sessions_dir=tmp_path, tracker_threads=2).tracker_concurrency == (2, 1)
    args = argparse.Namespace(threads=None, processes=None)
    _choose_concurrency(args, 4)
    assert (args.threads, args.processes) == (1, 2)
