"""Speculative child updates (`MultiTracker.speculate`): the children start on the next frame
before it is asked for; the matching `update` collects their answers, and every other call
first puts their trackers back. Every call pattern gives the results of no speculation, bit for
bit, in the tracker and through the pipeline (poses, re-acquisitions, edits, unreadable
frames)."""

from __future__ import annotations

import json
import shutil
from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np
import pytest

from autotrack.errors import InputError
from autotrack.io.frames import open_frames
from autotrack.localization.reacquire import ReacquireParams
from autotrack.localization.scene import load_scene
from autotrack.params import preset
from autotrack.pipeline import Pipeline, localize_sequence
from autotrack.pipeline.targets import FrameOutcome
from autotrack.synthetic.scenarios import Occluder, ScenarioSpec, render_scenario
from autotrack.synthetic.trajectories import RenderSettings, SequenceSpec
from autotrack.tracker.parallel.multi import MultiTracker
from autotrack.tracker.parallel.target_process import WorkerPool
from tests import test_multi
from tests.test_target_process import assert_identical

landmarks_sequence = test_multi.landmarks_sequence  # 12 frames, 640x360, landmarks A-D


@pytest.fixture(scope="module")
def occluded_sequence(tmp_path_factory) -> Path:
    """A board passes in front of landmark C: it is left out of the poses and, once the board
    has gone, re-acquired at frame 29 (its tracker restarts after that frame's pose)."""
    spec = ScenarioSpec(
        "occlusion",
        SequenceSpec("occlusion", "circle", 40, 100, RenderSettings(640, 360), period_s=40.0),
        occluders=(Occluder("C", 2.0, speed_m_s=0.3),),
    )
    return render_scenario(tmp_path_factory.mktemp("speculation") / "occlusion", spec)


@pytest.fixture
def counted(monkeypatch) -> dict[str, int]:
    """Counts the speculations started and undone by every MultiTracker."""
    counts = {"started": 0, "undone": 0}
    speculate, cancel = MultiTracker._speculate, MultiTracker._cancel_speculation

    def counted_speculate(self, next_frame):
        started = speculate(self, next_frame)
        counts["started"] += started
        return started

    def counted_cancel(self):
        counts["undone"] += self._speculation is not None
        cancel(self)

    monkeypatch.setattr(MultiTracker, "_speculate", counted_speculate)
    monkeypatch.setattr(MultiTracker, "_cancel_speculation", counted_cancel)
    return counts


def edits(frames, boxes) -> list[tuple[int | None, Callable[[MultiTracker], object]]]:
    """A session taking every path out of a speculation, as (frame to speculate on before the
    step or None, step): targets A, B, C at first (B in the child), the child's B reset, D
    added to the child, an update with another frame than the one speculated, A removed, an
    invalid frame."""
    first = {k: boxes[k] for k in ("A", "B", "C")}
    moved = (boxes["B"][0] + 3.0, boxes["B"][1] + 3.0, boxes["B"][2], boxes["B"][3])
    return [
        (None, lambda t: t.init(frames[0], first)),
        (1, lambda t: t.update(frames[1])),
        (2, lambda t: t.update(frames[2].copy())),  # equal values, another array
        (3, lambda t: t.reset_target("B", frames[2], moved)),  # undone
        (3, lambda t: t.update(frames[3])),
        (4, lambda t: t.add_target("D", frames[3], boxes["D"])),  # undone
        (4, lambda t: t.update(frames[4])),
        (5, lambda t: t.update(frames[6])),  # undone: another frame
        (7, lambda t: t.remove_target("A")),  # undone
        (7, lambda t: t.update(frames[7])),
        (8, lambda t: t.update(np.zeros((4, 4, 3), np.uint8))),  # undone; refused by all
        (8, lambda t: t.update(frames[8])),
        (9, lambda t: t.update(frames[9])),
    ]


def replay(tracker: MultiTracker, steps, frames, speculating: bool) -> list:
    """Each step's answer (or error), speculating before it when `speculating`."""
    answers = []
    for ahead, step in steps:
        if speculating and ahead is not None:
            assert tracker.speculate(frames[ahead])
        try:
            answers.append(step(tracker))
        except InputError as error:
            answers.append(f"{type(error).__name__}: {error}")
    return answers


def assert_same_answers(expected: list, got: list) -> None:
    assert len(got) == len(expected)
    for a, b in zip(expected, got, strict=True):
        if isinstance(a, dict):
            assert_identical(a, b)
        elif a is None or isinstance(a, str):
            assert a == b
        else:  # one TrackResult
            assert_identical({"": a}, {"": b})


def test_speculating_children_give_the_results_of_one_process(landmarks_sequence, counted):
    frames, boxes, _ = landmarks_sequence
    params = preset("autotrack")
    asked = []
    with MultiTracker(params, boxes) as alone:
        expected = [alone.init(frames[0], boxes)]
        for k in range(1, len(frames)):
            expected.append(alone.update(frames[k], lambda k=k: asked.append(k)))
    assert asked == []  # no child: the next frame is not even read
    with MultiTracker(params, boxes, processes=2) as spread:
        got = [spread.init(frames[0], boxes)]
        for k in range(1, len(frames)):
            assert spread.speculate(frames[k])
            got.append(spread.update(frames[k]))
    for a, b in zip(expected, got, strict=True):
        assert_identical(a, b)
    assert counted == {"started": len(frames) - 1, "undone": 0}  # every one consumed


def test_an_update_given_the_next_frame_starts_the_children_on_it(landmarks_sequence, counted):
    frames, boxes, _ = landmarks_sequence
    params = preset("autotrack")
    small = np.zeros((8, 8, 3), np.uint8)  # refused by every tracker

    def unreadable() -> np.ndarray:
        raise InputError("frame 5: cannot read")

    def session(tracker: MultiTracker, ahead: bool) -> list:
        def next_of(frame) -> Callable[[], np.ndarray] | None:
            return (frame if callable(frame) else lambda: frame) if ahead else None

        steps = [(None, lambda t: t.init(frames[0], boxes))]
        steps += [
            (None, lambda t, k=k: t.update(frames[k], next_of(frames[k + 1]))) for k in (1, 2)
        ]
        steps += [
            (None, lambda t: t.update(frames[3], next_of(small))),  # the child's update fails
            (None, lambda t: t.update(small, next_of(frames[4]))),  # consumed: raises here
            (None, lambda t: t.update(frames[4], next_of(unreadable))),  # none started
            (None, lambda t: t.update(frames[5], next_of(frames[6]))),
            (None, lambda t: t.update(frames[6])),
        ]
        return replay(tracker, steps, frames, speculating=False)

    with MultiTracker(params, processes=2) as plain:
        expected = session(plain, ahead=False)
    with MultiTracker(params, processes=2) as ahead:
        got = session(ahead, ahead=True)
    assert_same_answers(expected, got)
    assert "frame size 8x8" in expected[4]
    # On frames 2, 3, the small one, 4 (started before this process's targets fail on the
    # small frame, and consumed by the next update) and 6; not on the frame that cannot be
    # read.
    assert counted == {"started": 5, "undone": 0}


def test_every_call_that_undoes_a_speculation_gives_the_results_without_one(
    landmarks_sequence, counted
):
    frames, boxes, _ = landmarks_sequence
    params = preset("autotrack")
    steps = edits(frames, boxes)
    with MultiTracker(params, processes=2) as plain:
        expected = replay(plain, steps, frames, speculating=False)
    assert counted == {"started": 0, "undone": 0}
    with WorkerPool() as pool:
        tracker = MultiTracker(params, processes=2, worker_pool=pool)
        got = replay(tracker, steps, frames, speculating=True)
        child = tracker._children[0]
        assert tracker.speculate(frames[10])
        tracker.close()  # with a speculation outstanding: undone, the child given back
        assert pool.idle == 1
        # Before each step after init, and before the close: undone by the reset, the add,
        # the update with frame 6, the removal, the invalid frame and the close.
        assert counted == {"started": len(steps), "undone": 6}
        assert isinstance(expected[10], str) and "frame size 4x4" in expected[10]
        assert_same_answers(expected, got)
        with MultiTracker(params, processes=2, worker_pool=pool) as again:
            answers = replay(again, steps, frames, speculating=True)
            assert again._children[0] is child  # the child given back tracks as a fresh one
        assert_same_answers(expected, answers)


def test_a_speculative_error_is_dropped_unless_its_frame_is_asked_for(landmarks_sequence):
    frames, boxes, _ = landmarks_sequence
    small = np.zeros((8, 8, 3), np.uint8)  # refused by the child's trackers
    with MultiTracker(preset("autotrack"), boxes, processes=2) as tracker:
        tracker.init(frames[0], boxes)
        assert tracker.speculate(small)
        dropped = tracker.update(frames[1])
        assert tracker.speculate(small)
        with pytest.raises(InputError, match="frame size 8x8 differs") as raised:
            tracker.update(small)
        after_error = tracker.update(frames[2])
    with MultiTracker(preset("autotrack"), boxes, processes=2) as plain:
        plain.init(frames[0], boxes)
        assert_identical(plain.update(frames[1]), dropped)
        with pytest.raises(InputError) as expected:
            plain.update(small)
        assert str(raised.value) == str(expected.value)
        assert_identical(plain.update(frames[2]), after_error)


def localize(folder: Path, processes: int) -> Iterator[FrameOutcome]:
    """`localize_sequence` on a rendered sequence, with re-acquisition."""
    scene = load_scene(folder / "scene.json")
    boxes = json.loads((folder / "boxes.json").read_text())
    with open_frames(folder) as source:
        yield from localize_sequence(
            source,
            scene,
            boxes,
            preset("autotrack"),
            processes=processes,
            reacquire_params=ReacquireParams(),
        )


def test_localisation_with_a_reacquisition_gives_the_poses_of_one_process(
    occluded_sequence, counted
):
    expected = list(localize(occluded_sequence, processes=1))
    got = list(localize(occluded_sequence, processes=2))
    reacquired = [o.frame_index for o in expected if o.events]
    assert reacquired == [29]  # C is restarted after frame 29's pose
    assert [o.events for o in got] == [o.events for o in expected]
    for one, two in zip(expected, got, strict=True):
        assert_identical(one.tracks, two.tracks)
        assert one.pose.valid == two.pose.valid
        assert np.array_equal(one.pose.position, two.pose.position)
        assert np.array_equal(one.pose.rotation, two.pose.rotation)
    # Speculated on every frame after the first but the last; the restart undid frame 30's.
    assert counted == {"started": len(expected) - 2, "undone": 1}


def edited_run(folder: Path, processes: int) -> tuple[dict, dict]:
    """Advance frame by frame to frame 9 with edits on the way (a child's target corrected, a
    fifth target, no landmark's, deleted, a track_to stopped early): every target's results,
    and the poses."""
    boxes = json.loads((folder / "boxes.json").read_text())
    scene = load_scene(folder / "scene.json")
    with (
        open_frames(folder) as source,
        Pipeline(source, preset("autotrack"), scene=scene, tracker_processes=processes) as pipeline,
    ):
        ids = pipeline.add_targets(0, boxes)
        ids.append(pipeline.add_target(0, (300.0, 150.0, 40.0, 40.0), landmark_id=None))
        for k in range(1, 5):
            pipeline.advance(k, horizon=9)
        x, y, w, h = pipeline.targets[ids[1]].results[4].box
        pipeline.place_box(ids[1], 4, (x + 2.0, y + 2.0, w, h))  # T2: the child's
        pipeline.advance(5, horizon=9)
        pipeline.delete_target(ids[4], 5)
        pipeline.track_to(9, should_stop=lambda: pipeline.tracked_until >= 7)
        pipeline.track_to(9)
        return {k: dict(t.results) for k, t in pipeline.targets.items()}, dict(pipeline.poses)


def test_pipeline_edits_between_frames_give_the_results_of_one_process(occluded_sequence, counted):
    expected, expected_poses = edited_run(occluded_sequence, processes=1)
    got, poses = edited_run(occluded_sequence, processes=2)
    assert sorted(poses) == sorted(expected_poses) == list(range(5, 10))  # re-solved from 5
    for index, pose in expected_poses.items():
        assert pose.valid and np.array_equal(pose.position, poses[index].position)
    assert list(got) == list(expected)
    for target_id, results in expected.items():
        assert sorted(got[target_id]) == sorted(results)
        for index, result in results.items():
            assert_identical({target_id: result}, {target_id: got[target_id][index]})
    # On frames 2-5 and 6-8; undone by the correction and the deletion (the early stop left
    # frame 8's for the next track_to).
    assert counted == {"started": 8, "undone": 2}


def test_a_frame_that_cannot_be_read_is_not_speculated_on(occluded_sequence, tmp_path, counted):
    folder = tmp_path / "broken"
    shutil.copytree(occluded_sequence, folder)
    images = sorted((folder / "img").iterdir())
    images[6].write_bytes(b"not an image")
    for processes in (1, 2):
        outcomes = []
        with pytest.raises(InputError, match=images[6].name):
            for outcome in localize(folder, processes):
                outcomes.append(outcome.frame_index)
        assert outcomes == list(range(6))  # frame 5 is yielded, frame 6 raises as it is read
    assert counted["started"] == 4  # on frames 2-5; frame 6 could not be read after frame 5


def test_a_writeable_frame_rewritten_in_place_is_tracked_as_it_is_now(landmarks_sequence, counted):
    """A caller that speculates on its writeable buffer, then writes another frame into that
    same buffer (a decoder reusing its output), gets the new frame tracked: a writeable array
    is compared by its values, never taken for the speculated frame by its identity."""
    frames, boxes, _ = landmarks_sequence
    params = preset("autotrack")
    with MultiTracker(params, boxes) as alone:
        alone.init(frames[0], boxes)
        expected = alone.update(frames[2])
    buffer = np.array(frames[1])
    with MultiTracker(params, boxes, processes=2) as spread:
        spread.init(frames[0], boxes)
        assert spread.speculate(buffer)
        buffer[...] = frames[2]
        assert_identical(expected, spread.update(buffer))
    assert counted == {"started": 1, "undone": 1}
