"""The pipeline (frames -> targets -> pose -> recording) on the embedded demo."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from autotrack.errors import InputError
from autotrack.io.frames import InMemoryFrames, open_frames
from autotrack.localization.localizer import LocalizerParams
from autotrack.localization.scene import load_scene
from autotrack.params import preset
from autotrack.pipeline import Pipeline, Recording, localize_sequence
from autotrack.sessions import open_session
from autotrack.tracker.tracker import AutoTrack

DEMO = Path(__file__).resolve().parents[1] / "static" / "demo"
BOXES = {k: tuple(v) for k, v in json.loads((DEMO / "boxes.json").read_text()).items()}


@pytest.fixture(scope="module")
def scene():
    return load_scene(DEMO / "scene.json")


def _pipeline(scene, tmp_path: Path, preset_name: str = "autotrack") -> Pipeline:
    recording = Recording(source=str(DEMO), directory=tmp_path, scene_path=DEMO / "scene.json")
    return Pipeline(open_frames(DEMO), preset(preset_name), scene=scene, recording=recording)


def test_one_target_gives_the_boxes_of_the_bare_tracker() -> None:
    frames = open_frames(DEMO)
    tracker = AutoTrack(preset("autotrack"))
    expected = [tracker.init(frames.read(0), BOXES["A"]).box]
    expected += [tracker.update(frames.read(k)).box for k in range(1, 8)]
    with Pipeline(
        InMemoryFrames([frames.read(k) for k in range(8)], "demo"), preset("autotrack")
    ) as run:
        target = run.add_target(0, BOXES["A"])
        outcomes = list(run.run())
    assert target == "T1"
    assert [o.frame_index for o in outcomes] == list(range(8))
    assert [o.tracks[target].box for o in outcomes] == expected
    assert all(o.pose is None for o in outcomes)
    assert np.all(run.frame_seconds > 0)  # every frame timed, the first one's init included


def test_targets_are_numbered_whoever_adds_them_and_carry_their_landmark(scene, tmp_path) -> None:
    with _pipeline(scene, tmp_path) as run:
        ids = run.add_targets(0, {"C": BOXES["C"], "A": BOXES["A"]})
        third = run.add_target(0, BOXES["B"])  # the first free landmark
        run.track_to(2)
        path = run.session_path
    assert ids == ["T1", "T2"] and third == "T3"
    assert {t.id: t.landmark_id for t in run.targets.values()} == {"T1": "C", "T2": "A", "T3": "B"}
    assert open_session(path).landmark_ids == {"T1": "C", "T2": "A", "T3": "B"}


def test_a_deleted_targets_id_is_reused_and_its_old_results_leave_the_recording(
    scene, tmp_path
) -> None:
    from autotrack.cli.session import session_summary

    with _pipeline(scene, tmp_path) as run:
        run.add_targets(0, {"A": BOXES["A"], "B": BOXES["B"], "C": BOXES["C"]})
        run.track_to(3)
        run.delete_target("T2", 3)
        deleted = open_session(_flushed(run))
        assert "T2" in deleted.deleted_targets
        assert set(session_summary(deleted)["targets"]) == set(deleted.exported_targets)
        assert session_summary(deleted)["deleted_targets"] == ["T2"]
        again = run.add_target(3, BOXES["D"], "D")
        run.track_to(5)
        path = run.session_path
    assert again == "T2" and sorted(run.targets) == ["T1", "T2", "T3"]
    session = open_session(path)
    boxes = session.tracks["T2"]
    assert not np.isfinite(boxes[:3]).any()  # the deleted T2's frames hold no box
    assert np.isfinite(boxes[3:6]).all() and session.landmark_ids["T2"] == "D"
    assert not session.deleted_targets and session_summary(session)["deleted_targets"] == []


def _flushed(run: Pipeline) -> Path:
    run.flush()
    return run.session_path


def test_a_correction_re_tracks_only_that_target_and_the_recording_agrees(scene, tmp_path):
    with _pipeline(scene, tmp_path) as run:
        run.add_targets(0, BOXES)
        run.track_to(12)
        untouched = {k: r.box for k, r in run.targets["T1"].results.items()}
        x, y, w, h = run.targets["T2"].results[5].box
        run.place_box("T2", 5, (x + 2.0, y - 1.0, w, h))
        assert max(run.targets["T2"].results) == 5
        assert 6 not in run.poses and 5 in run.poses  # later poses wait for T2 to catch up
        run.track_to(12)
        run.delete_target("T4", 12)
        path = run.session_path
        held = {t.id: dict(t.results) for t in run.targets.values()}
        poses = dict(run.poses)
    assert {k: r.box for k, r in held["T1"].items()} == untouched
    session = open_session(path)
    recorded = session.recorded_targets()
    assert set(recorded) == {"T1", "T2", "T3"}  # T4 was deleted
    for target_id, results in held.items():
        assert {k: r.box for k, r in recorded[target_id].results.items()} == {
            k: r.box for k, r in results.items()
        }
    read_back = session.pose_estimates()
    for frame_index, pose in poses.items():
        assert read_back[frame_index].valid == pose.valid
        np.testing.assert_allclose(read_back[frame_index].position, pose.position, atol=1e-9)
    assert [e.kind for e in session.events][-2:] == ["box_corrected", "box_deleted"]


def test_resume_continues_with_the_recorded_tracker_parameters(scene, tmp_path) -> None:
    with _pipeline(scene, tmp_path / "first", preset_name="strcf") as run:
        run.add_targets(0, BOXES)
        run.track_to(6)
        first = run.session_path
        last_boxes = {t.id: t.results[6].box for t in run.targets.values()}
        pose_at_resume = run.poses[6]
    session = open_session(first)
    recording = Recording(source=str(DEMO), directory=tmp_path / "second")
    with Pipeline.resume(session, open_frames(DEMO), scene=scene, recording=recording) as resumed:
        assert resumed.params == preset("strcf")
        assert resumed.resume_frame == 6
        assert {t.id: t.results[6].box for t in resumed.targets.values()} == last_boxes
        assert sorted(resumed.poses) == list(range(7))
        np.testing.assert_array_equal(resumed.poses[6].position, pose_at_resume.position)
        resumed.track_to(9)
        second = resumed.session_path
    again = open_session(second)
    assert again.metadata["resumed_from"] == str(first)
    assert int(again.frame_indices[-1]) == 9


def test_resume_keeps_the_recorded_pose_of_the_resume_frame(scene, tmp_path) -> None:
    with _pipeline(scene, tmp_path / "first") as run:
        run.add_targets(0, BOXES)
        run.track_to(4)
        first = run.session_path
        recorded = run.poses[4]
    assert recorded.valid and recorded.rms_error_px > 1e-3
    # A localiser this strict rejects every pose: re-solving the resume frame (the restarts do)
    # would replace the pose the session showed there with an invalid one.
    strict = LocalizerParams(max_rms_error_px=1e-6, max_landmark_error_px=1e-6)
    recording = Recording(source=str(DEMO), directory=tmp_path / "second")
    with Pipeline.resume(
        open_session(first),
        open_frames(DEMO),
        scene=scene,
        localizer_params=strict,
        recording=recording,
    ) as resumed:
        assert resumed.resume_frame == 4
        kept = resumed.poses[4]
        assert kept.valid and kept.reprojection_errors == recorded.reprojection_errors
        np.testing.assert_array_equal(kept.position, recorded.position)
        resumed.track_to(5)
        assert not resumed.poses[5].valid  # the strict localiser solves the frames after it
        second = resumed.session_path
    assert open_session(second).pose_estimates()[4].valid


def test_localize_sequence_finds_listed_boxes_landmarks(scene) -> None:
    frames = [open_frames(DEMO).read(k) for k in range(3)]
    listed = [BOXES[k] for k in ("D", "B", "A", "C")]
    outcomes = list(localize_sequence(frames, scene, listed, preset("autotrack")))
    assert set(outcomes[0].landmark_tracks) == {"A", "B", "C", "D"}
    for landmark, track in outcomes[0].landmark_tracks.items():
        np.testing.assert_allclose(track.box, BOXES[landmark], atol=2.0)  # init rounds to pixels
        assert outcomes[0].image_points[landmark] == track.center
    assert all(o.pose.valid for o in outcomes)


def test_edits_are_checked_before_anything_changes(scene, tmp_path) -> None:
    with _pipeline(scene, tmp_path) as run:
        run.add_target(0, BOXES["A"], landmark_id="A")
        with pytest.raises(InputError, match="already tracked by T1"):
            run.add_target(0, BOXES["B"], landmark_id="A")
        with pytest.raises(InputError, match="unknown landmark 'Z'"):
            run.add_target(0, BOXES["B"], landmark_id="Z")
        with pytest.raises(InputError, match="outside 0..59"):
            run.add_target(60, BOXES["B"])
        with pytest.raises(InputError, match="no target 'T9'"):
            run.place_box("T9", 0, BOXES["B"])
        # A refused box names what it was drawn for.
        with pytest.raises(InputError, match=r"^landmark B: box \(5000.0, 10.0, 20.0, 20.0\) lies"):
            run.add_targets(0, {"B": (5000, 10, 20, 20)})
        with pytest.raises(InputError, match=r"^T1: box \(10.0, 10.0, 0.0, 5.0\) has zero size"):
            run.place_box("T1", 0, (10, 10, 0, 5))
        with pytest.raises(InputError, match=r"^box \(-900.0, 10.0, 20.0, 20.0\) lies"):
            run.add_target(0, (-900, 10, 20, 20), landmark_id=None)
        assert list(run.targets) == ["T1"]
        assert math.isfinite(run.frame_seconds[0])


def test_every_result_carries_its_frame_of_the_sequence_after_restarts(scene, tmp_path) -> None:
    """A tracker restarted mid-run counts its frames from its restart, a group started later
    from its first frame: the results (kept and recorded) carry the sequence's frame index."""
    with _pipeline(scene, tmp_path) as run:
        run.add_targets(0, {"A": BOXES["A"], "B": BOXES["B"]})
        run.track_to(4)
        run.place_box("T1", 4, BOXES["A"])  # a new tracker inside the group at frame 4
        run.add_target(2, BOXES["C"], "C")  # a group of its own from frame 2
        run.track_to(8)
        firsts = {"T1": 0, "T2": 0, "T3": 2}
        for target_id, first in firsts.items():
            results = run.targets[target_id].results
            assert [results[k].frame_index for k in range(first, 9)] == list(range(first, 9))
        session = open_session(_flushed(run))
    assert np.isfinite(session.tracks["T3"][2:9]).all()
    assert not np.isfinite(session.tracks["T3"][:2]).any()
