"""Several AutoTrack targets on shared frames: same answers as separate trackers, threads or not,
and per-target add / remove / reset."""

from __future__ import annotations

import json

import numpy as np
import pytest

from autotrack.errors import InputError
from autotrack.io.frames import open_frames
from autotrack.params import preset
from autotrack.synthetic.renderer import render_sequence
from autotrack.synthetic.testbed import read_ground_truth_boxes
from autotrack.synthetic.trajectories import RenderSettings, SequenceSpec
from autotrack.tracker.parallel.multi import MultiTracker
from autotrack.tracker.tracker import AutoTrack

FRAMES = 12


@pytest.fixture(scope="session")
def landmarks_sequence(tmp_path_factory):
    """A generated 640x360 sequence with four landmarks: frames, first boxes, per-frame truth."""
    spec = SequenceSpec(
        "multi",
        "lateral_sweep",
        FRAMES,
        seed=21,
        settings=RenderSettings(width=640, height=360),
        period_s=40.0,
    )
    folder = render_sequence(tmp_path_factory.mktemp("multi") / "seq", spec)
    with open_frames(folder) as source:
        frames = [source.read(i) for i in range(len(source))]
    boxes = {k: tuple(v) for k, v in json.loads((folder / "boxes.json").read_text()).items()}
    return frames, boxes, read_ground_truth_boxes(folder)


def run(tracker: MultiTracker, frames, boxes) -> list[dict]:
    results = [tracker.init(frames[0], boxes)]
    results += [tracker.update(frame) for frame in frames[1:]]
    return results


def centre_errors(results, truth, landmark_id) -> np.ndarray:
    boxes = np.array([r[landmark_id].box for r in results])
    expected = truth[landmark_id][: len(boxes)]
    return np.linalg.norm(
        (boxes[:, :2] + boxes[:, 2:] / 2) - (expected[:, :2] + expected[:, 2:] / 2), axis=1
    )


def test_multi_tracker_equals_separate_trackers_and_tracks_every_landmark(landmarks_sequence):
    frames, boxes, truth = landmarks_sequence
    params = preset("autotrack")
    with MultiTracker(params, boxes) as multi:
        combined = run(multi, frames, boxes)
    for landmark_id, box in boxes.items():
        single = AutoTrack(params)
        expected = [single.init(frames[0], box).box] + [single.update(f).box for f in frames[1:]]
        assert [r[landmark_id].box for r in combined] == expected
        errors = centre_errors(combined, truth, landmark_id)
        assert errors.mean() < 2.5 and errors.max() < 6.0
    assert [r["A"].frame_index for r in combined] == list(range(FRAMES))


def test_threads_give_the_same_results(landmarks_sequence):
    frames, boxes, _ = landmarks_sequence
    params = preset("autotrack")
    with (
        MultiTracker(params, boxes, threads=1) as serial,
        MultiTracker(params, boxes, threads=3) as pooled,
    ):
        one = run(serial, frames[:6], boxes)
        three = run(pooled, frames[:6], boxes)
    for a, b in zip(one, three, strict=True):
        assert {k: r.box for k, r in a.items()} == {k: r.box for k, r in b.items()}
        for landmark_id in a:
            np.testing.assert_array_equal(a[landmark_id].peak_score, b[landmark_id].peak_score)


def test_reset_target_restarts_only_that_target(landmarks_sequence):
    frames, boxes, truth = landmarks_sequence
    params = preset("autotrack")
    baseline = run(MultiTracker(params, boxes), frames, boxes)
    tracker = MultiTracker(params, boxes)
    results = run(tracker, frames[:6], boxes)
    wrong = tuple(np.asarray(boxes["C"]) + [25.0, 10.0, 0.0, 0.0])
    reset = tracker.reset_target("C", frames[5], wrong)
    assert reset.frame_index == 5 and reset.box == pytest.approx(wrong, abs=1.0)
    corrected = tuple(truth["C"][5])
    tracker.reset_target("C", frames[5], corrected)
    after = tracker.update(frames[6])
    assert after["C"].frame_index == 6
    assert centre_errors([after], {"C": truth["C"][6:7]}, "C")[0] < 6.0
    for landmark_id in ("A", "B", "D"):
        assert after[landmark_id].box == baseline[6][landmark_id].box
    assert len(results) == 6


def test_add_and_remove_targets(landmarks_sequence):
    frames, boxes, truth = landmarks_sequence
    tracker = MultiTracker(preset("autotrack"))
    tracker.init(frames[0], {"A": boxes["A"], "B": boxes["B"]})
    tracker.update(frames[1])
    added = tracker.add_target("D", frames[1], tuple(truth["D"][1]))
    assert added.frame_index == 1
    tracker.remove_target("A")
    results = tracker.update(frames[2])
    assert tracker.target_ids == ("B", "D") and set(results) == {"B", "D"}
    assert results["D"].frame_index == 2
    assert centre_errors([results], {"D": truth["D"][2:3]}, "D")[0] < 6.0
    with pytest.raises(InputError, match="already exists"):
        tracker.add_target("B", frames[2], boxes["B"])
    with pytest.raises(InputError, match="no target 'A'"):
        tracker.remove_target("A")


def test_misuse_is_reported_clearly(landmarks_sequence):
    frames, boxes, _ = landmarks_sequence
    tracker = MultiTracker(preset("autotrack"), ["A", "B", "C"])
    with pytest.raises(InputError, match="before update"):
        tracker.update(frames[0])
    with pytest.raises(InputError, match="missing C; unexpected D"):
        tracker.init(frames[0], {"A": boxes["A"], "B": boxes["B"], "D": boxes["D"]})
    with pytest.raises(InputError, match="at least 1"):
        MultiTracker(preset("autotrack"), threads=0)
