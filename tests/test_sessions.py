"""Sessions: record to MCAP, read back (also cut short), Foxglove schemas, CLI info/export."""

from __future__ import annotations

import base64
import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest
from mcap.reader import make_reader
from mcap.writer import Writer

import autotrack.sessions.metadata
from autotrack.cli import main
from autotrack.errors import SessionError
from autotrack.io.otb_boxes import read_boxes
from autotrack.localization.camera import CameraIntrinsics
from autotrack.localization.scene import Landmark, Scene, save_scene
from autotrack.params import TrackerParams, preset
from autotrack.result import TrackResult
from autotrack.sessions import SessionRecorder, open_session
from autotrack.sessions.encoding import FORMAT_VERSION, dequantise_map, quantise_map
from autotrack.sessions.schemas import SCHEMA_NAMES, schema_document

FPS = 25.0
FRAMES = 40
MAP_SHAPE = (50, 50)


@dataclass(frozen=True)
class _Pose:
    """The attributes of autotrack.result.PoseEstimate the recorder reads."""

    frame_index: int
    valid: bool
    rotation: np.ndarray
    position: np.ndarray
    reprojection_errors: dict[str, float]
    used_landmarks: tuple[str, ...]
    reason: str = ""
    rms_error_px: float = math.nan
    position_std_m: float = math.nan

    def quaternion_xyzw(self) -> np.ndarray:
        if not np.isfinite(self.rotation).all():
            return np.full(4, np.nan)
        angle = math.acos(max(-1.0, min(1.0, (np.trace(self.rotation) - 1.0) / 2.0)))
        return np.array([0.0, 0.0, math.sin(angle / 2.0), math.cos(angle / 2.0)])


def _rotation_z(angle: float) -> np.ndarray:
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _response_map(frame_index: int, phase: float, rng: np.random.Generator) -> np.ndarray:
    """A correlation-like response: a Gaussian peak that drifts, plus clutter."""
    rows, cols = np.mgrid[0 : MAP_SHAPE[0], 0 : MAP_SHAPE[1]].astype(np.float32)
    peak_r = 25 + 4 * math.sin(0.3 * frame_index + phase)
    peak_c = 25 + 4 * math.cos(0.2 * frame_index + phase)
    peak = np.exp(-((rows - peak_r) ** 2 + (cols - peak_c) ** 2) / (2 * 3.0**2))
    return (peak + 0.05 * rng.standard_normal(MAP_SHAPE)).astype(np.float32)


def _results(target_index: int, frames: range, seed: int) -> list[TrackResult]:
    """Hand-built results of one target over `frames`, with real maps and signals."""
    rng = np.random.default_rng(seed)
    results = []
    previous = None
    for k, frame_index in enumerate(frames):
        response = None if k == 0 else _response_map(frame_index, target_index, rng)
        local = None if previous is None or response is None else np.abs(response - previous)
        eta = math.nan if local is None else float(np.linalg.norm(local, 2) / 1e4 * 100)
        box = (
            30.0 + 40 * target_index + 1.37 * k,
            50.0 + 0.61 * k * (target_index + 1),
            24.0 + 0.1 * k,
            31.5,
        )
        results.append(
            TrackResult(
                frame_index=frame_index,
                box=box,
                peak_score=math.nan if response is None else float(response.max()),
                response_map=response,
                local_variation=local,
                global_variation=eta,
                theta_ref=13.0 / (1.0 + 0.1 * k),
                theta=12.5 / (1.0 + 0.1 * k),
                aberrant=bool(k % 7 == 6),
                scale_factor=1.0 + 0.003 * k,
                search_box=(box[0] - 40, box[1] - 40, 104.0, 111.5),
            )
        )
        previous = response
    return results


def _pose(frame_index: int) -> _Pose:
    if frame_index % 6 == 5:
        return _Pose(
            frame_index,
            False,
            np.full((3, 3), np.nan),
            np.full(3, np.nan),
            {"L1": 9.5, "L2": math.nan},
            (),
            reason="reprojection error too large",
        )
    errors = {"L1": 0.4 + 0.01 * frame_index, "L2": 0.7, "L3": 1.1}
    return _Pose(
        frame_index,
        True,
        _rotation_z(0.02 * frame_index),
        np.array([0.1 * frame_index, -2.0, 10.0 + 0.05 * frame_index]),
        errors,
        ("L1", "L2", "L3"),
        rms_error_px=float(np.sqrt(np.mean(np.square(list(errors.values()))))),
        position_std_m=0.02,
    )


def _scene() -> Scene:
    camera = CameraIntrinsics(fx=500.0, fy=500.0, cx=160.0, cy=120.0, width=320, height=240)
    landmarks = (
        Landmark("L1", np.array([0.0, 0.0, 0.0])),
        Landmark("L2", np.array([4.0, 0.0, 0.0])),
        Landmark("L3", np.array([0.0, 3.0, 0.5])),
    )
    return Scene(camera=camera, landmarks=landmarks)


@dataclass
class Recorded:
    """What the round-trip fixture recorded, to compare the file against."""

    path: Path
    results: dict[str, list[TrackResult]]
    poses: list[_Pose]
    scene_path: Path


def _record(directory: Path, **options: Any) -> Recorded:
    """Three targets (t3 drawn at frame 10, deleted at 30), poses, box edits, landmarks."""
    scene_path = directory / "scene.json"
    save_scene(_scene(), scene_path)
    results = {
        "t1": _results(0, range(FRAMES), seed=1),
        "t2": _results(1, range(FRAMES), seed=2),
        "t3": _results(2, range(10, 30), seed=3),
    }
    poses = [_pose(i) for i in range(FRAMES)]
    with SessionRecorder.create(
        directory / "sessions",
        source="generated/three_targets",
        tracker_params=preset("autotrack"),
        scene_path=scene_path,
        fps=FPS,
        **options,
    ) as recorder:
        recorder.log_landmarks(_scene())
        for frame_index in range(FRAMES):
            for target_id, series in results.items():
                first = series[0].frame_index
                if first <= frame_index < first + len(series):
                    result = series[frame_index - first]
                    if frame_index == first:
                        recorder.log_event("box_drawn", frame_index, target_id, result.box)
                    landmark = {"t1": "L1", "t2": "L2"}.get(target_id)
                    recorder.log_target(target_id, result, landmark_id=landmark)
            if frame_index == 30:
                recorder.log_event("box_deleted", 30, "t3")
            recorder.log_pose(poses[frame_index])
            if frame_index == 20:
                recorder.log_event(
                    "box_corrected", 20, "t1", (1.0, 2.0, 3.0, 4.0), previous_box=[5, 6, 7, 8]
                )
        path = recorder.path
    return Recorded(path=path, results=results, poses=poses, scene_path=scene_path)


@pytest.fixture(scope="module")
def recorded(tmp_path_factory: pytest.TempPathFactory) -> Recorded:
    return _record(tmp_path_factory.mktemp("session"))


# --- round trip -------------------------------------------------------------------------------


def test_round_trip_restores_tracks_signals_poses_events(recorded: Recorded) -> None:
    session = open_session(recorded.path)
    assert not session.truncated
    assert session.format_version == FORMAT_VERSION
    assert session.targets == ("t1", "t2", "t3")
    assert session.fps == FPS
    np.testing.assert_array_equal(session.frame_indices, np.arange(FRAMES))
    for target_id, series in recorded.results.items():
        recorded_frames = [r.frame_index for r in series]
        expected_boxes = np.full((FRAMES, 4), np.nan)
        expected_boxes[recorded_frames] = [r.box for r in series]
        np.testing.assert_array_equal(session.tracks[target_id], expected_boxes)
        np.testing.assert_array_equal(
            session.scores[target_id][recorded_frames], [r.peak_score for r in series]
        )
        assert np.isnan(session.scores[target_id][recorded_frames[0]])
        np.testing.assert_array_equal(
            session.aberrant[target_id][recorded_frames], [r.aberrant for r in series]
        )
        for name in ("theta_ref", "theta", "global_variation", "scale_factor"):
            np.testing.assert_array_equal(
                session.signals[target_id][name][recorded_frames],
                [getattr(r, name) for r in series],
            )
    assert session.landmark_ids == {"t1": "L1", "t2": "L2", "t3": None}
    assert session.frame_count == FRAMES
    assert session.tracker_params() == preset("autotrack")
    assert session.metadata["source"] == "generated/three_targets"
    assert session.scene_attachment == recorded.scene_path.read_bytes()
    assert set(session.landmarks) == {"L1", "L2", "L3"}
    np.testing.assert_array_equal(session.landmarks["L3"], [0.0, 3.0, 0.5])


def test_round_trip_restores_camera_poses(recorded: Recorded) -> None:
    poses = open_session(recorded.path).poses
    np.testing.assert_array_equal(poses.frame_indices, np.arange(FRAMES))
    np.testing.assert_array_equal(poses.valid, [p.valid for p in recorded.poses])
    for row, pose in enumerate(recorded.poses):
        if pose.valid:
            np.testing.assert_array_equal(poses.positions[row], pose.position)
            np.testing.assert_array_equal(poses.quaternions_xyzw[row], pose.quaternion_xyzw())
            assert poses.reprojection_errors[row] == pose.reprojection_errors
            assert poses.used_landmarks[row] == pose.used_landmarks
            assert poses.rms_error_px[row] == pose.rms_error_px
        else:
            assert np.isnan(poses.positions[row]).all()
            assert poses.reasons[row] == "reprojection error too large"
            assert poses.reprojection_errors[row]["L1"] == 9.5
            assert np.isnan(poses.reprojection_errors[row]["L2"])
            assert poses.mean_reprojection_error[row] == 9.5


def test_events_and_last_boxes_follow_the_user_edits(recorded: Recorded) -> None:
    session = open_session(recorded.path)
    kinds = [(e.kind, e.frame_index, e.target_id) for e in session.events]
    assert kinds == [
        ("box_drawn", 0, "t1"),
        ("box_drawn", 0, "t2"),
        ("box_drawn", 10, "t3"),
        ("box_corrected", 20, "t1"),
        ("box_deleted", 30, "t3"),
    ]
    corrected = session.events[3]
    assert corrected.box == (1.0, 2.0, 3.0, 4.0)
    assert corrected.extra == {"previous_box": [5, 6, 7, 8]}
    assert corrected.wall_time > 1.6e9
    state = session.last_boxes
    assert set(state) == {"t1", "t2"}  # t3 was deleted
    assert state["t1"] == (FRAMES - 1, recorded.results["t1"][-1].box)
    assert state["t2"] == (FRAMES - 1, recorded.results["t2"][-1].box)


def test_maps_are_recorded_quantised_and_dequantise_within_one_step(recorded: Recorded) -> None:
    session = open_session(recorded.path, load_maps=True)
    for target_id, series in recorded.results.items():
        for result in series:
            for stored, original in (
                (session.response_maps[target_id], result.response_map),
                (session.local_variation_maps[target_id], result.local_variation),
            ):
                if original is None:
                    assert result.frame_index not in stored
                    continue
                step = float(original.max() - original.min()) / 255.0
                restored = stored[result.frame_index]
                assert restored.shape == original.shape
                assert np.abs(restored - original).max() <= 0.5 * step + 1e-6
    assert open_session(recorded.path).response_maps == {}


def test_quantise_map_keeps_the_range_and_handles_constant_maps() -> None:
    values = np.array([[-2.0, 0.0], [1.0, 3.0]], dtype=np.float32)
    quantised, lo, hi = quantise_map(values)
    assert (lo, hi) == (-2.0, 3.0)
    np.testing.assert_array_equal(quantised, [[0, 102], [153, 255]])
    np.testing.assert_allclose(dequantise_map(quantised, lo, hi), values, atol=5.0 / 510)
    constant, lo, hi = quantise_map(np.full((3, 3), 0.25))
    assert lo == hi == 0.25 and not constant.any()
    np.testing.assert_array_equal(dequantise_map(constant, lo, hi), np.full((3, 3), 0.25))


def test_real_tracker_run_round_trips(tmp_path: Path) -> None:
    from autotrack.tracker.tracker import AutoTrack

    frames, boxes = _generated_sequence(12)
    params = TrackerParams()
    trackers = {"a": AutoTrack(params), "b": AutoTrack(params)}
    expected: dict[str, list[TrackResult]] = {"a": [], "b": []}
    with SessionRecorder(
        tmp_path / "real.mcap", source="generated", tracker_params=params, fps=30.0
    ) as recorder:
        for frame_index, frame in enumerate(frames):
            for target_id, target in trackers.items():
                if frame_index == 0:
                    result = target.init(frame, boxes[target_id])
                else:
                    result = target.update(frame)
                expected[target_id].append(result)
                recorder.log_target(target_id, result)
    session = open_session(tmp_path / "real.mcap", load_maps=True)
    for target_id, results in expected.items():
        np.testing.assert_array_equal(session.tracks[target_id], [r.box for r in results])
        np.testing.assert_array_equal(session.aberrant[target_id], [r.aberrant for r in results])
        last = results[-1]
        step = float(last.response_map.max() - last.response_map.min()) / 255.0
        restored = session.response_maps[target_id][len(frames) - 1]
        assert np.abs(restored - last.response_map).max() <= 0.5 * step + 1e-6


def _generated_sequence(count: int) -> tuple[list[np.ndarray], dict[str, tuple]]:
    """Two textured squares drifting over a textured background (RGB uint8 frames)."""
    rng = np.random.default_rng(7)
    background = cv2.GaussianBlur(rng.integers(0, 255, (240, 320, 3), dtype=np.uint8), (7, 7), 2)
    patches = {
        "a": rng.integers(0, 255, (32, 32, 3), dtype=np.uint8),
        "b": rng.integers(0, 255, (28, 36, 3), dtype=np.uint8),
    }
    starts = {"a": (60, 80), "b": (180, 120)}
    frames = []
    for k in range(count):
        frame = background.copy()
        for target_id, patch in patches.items():
            x, y = starts[target_id][0] + 2 * k, starts[target_id][1] + k
            frame[y : y + patch.shape[0], x : x + patch.shape[1]] = patch
        frames.append(frame)
    boxes = {
        target_id: (
            float(starts[target_id][0]),
            float(starts[target_id][1]),
            patch.shape[1],
            patch.shape[0],
        )
        for target_id, patch in patches.items()
    }
    return frames, boxes


def test_localization_run_round_trips_through_export(
    tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    """A real localisation run (synthetic test bed): recorded tracks and PoseEstimates come back
    out of `session export` as the pipeline's own boxes and TUM trajectory."""
    from autotrack.io.frames import open_frames
    from autotrack.io.tum import read_tum, write_tum
    from autotrack.localization.scene import load_scene
    from autotrack.pipeline import Recording, localize_sequence
    from autotrack.synthetic.renderer import render_sequence
    from autotrack.synthetic.trajectories import RenderSettings, SequenceSpec

    spec = SequenceSpec("s", "circle", 8, 0, RenderSettings(width=640, height=360), period_s=45.0)
    folder = render_sequence(tmp_path / "synthetic", spec)
    scene = load_scene(folder / "scene.json")
    boxes = json.loads((folder / "boxes.json").read_text())
    frames = open_frames(folder / "img")
    recording = Recording(
        source=str(folder), path=tmp_path / "localize.mcap", scene_path=folder / "scene.json"
    )
    outputs = list(
        localize_sequence(frames, scene, boxes, TrackerParams(), recording=recording, fps=10.0)
    )
    assert any(o.pose.valid for o in outputs)
    out = tmp_path / "export"
    argv = ["session", "export", str(tmp_path / "localize.mcap"), "--tracks", str(out)]
    assert main([*argv, "--poses", str(out / "poses.tum")]) == 0
    capsys.readouterr()
    session = open_session(tmp_path / "localize.mcap")
    target_of = {landmark: target for target, landmark in session.landmark_ids.items()}
    for landmark_id in boxes:
        expected = np.array([o.landmark_tracks[landmark_id].box for o in outputs])
        exported = read_boxes(out / f"{target_of[landmark_id]}_{landmark_id}.txt")
        np.testing.assert_allclose(exported, expected, atol=1e-4)
    valid = [o.pose for o in outputs if o.pose.valid]
    write_tum(
        tmp_path / "direct.tum",
        [p.frame_index / 10.0 for p in valid],
        np.array([p.position for p in valid]),
        np.array([p.quaternion_xyzw() for p in valid]),
    )
    for exported, direct in zip(
        read_tum(out / "poses.tum"), read_tum(tmp_path / "direct.tum"), strict=True
    ):
        np.testing.assert_array_equal(exported, direct)
    assert sorted(session.landmark_ids.values()) == sorted(boxes)
    assert set(session.landmarks) == set(scene.landmark_ids)
    assert session.poses.reasons == tuple(o.pose.reason for o in outputs)


# --- the files are valid MCAP with the Foxglove schemas ---------------------------------------


def _validate(value: Any, schema: dict[str, Any], where: str) -> None:
    """Check `value` against the JSON Schema subset our schemas use."""
    if "oneOf" in schema:
        assert value in [option["const"] for option in schema["oneOf"]], where
        return
    allowed = schema.get("type")
    if allowed is not None:
        kinds = {
            "object": dict,
            "array": list,
            "string": str,
            "boolean": bool,
            "null": type(None),
            "integer": int,
            "number": (int, float),
        }
        types = [allowed] if isinstance(allowed, str) else allowed
        ok = any(
            isinstance(value, kinds[t])
            and not (t in ("integer", "number") and isinstance(value, bool))
            for t in types
        )
        assert ok, f"{where}: {value!r} is not {allowed}"
    if "minimum" in schema and isinstance(value, int | float):
        assert value >= schema["minimum"], where
    if "maximum" in schema and isinstance(value, int | float):
        assert value <= schema["maximum"], where
    if isinstance(value, dict):
        for key in schema.get("required", []):
            assert key in value, f"{where}: missing {key}"
        properties = schema.get("properties", {})
        for key, item in value.items():
            if key in properties:
                _validate(item, properties[key], f"{where}.{key}")
            elif "additionalProperties" in schema:
                _validate(item, schema["additionalProperties"], f"{where}.{key}")
            elif properties:
                raise AssertionError(f"{where}: field {key!r} is not in the schema")
    if isinstance(value, list) and "items" in schema:
        for index, item in enumerate(value):
            _validate(item, schema["items"], f"{where}[{index}]")
    if schema.get("contentEncoding") == "base64":
        base64.b64decode(value, validate=True)


def test_mcap_reader_validates_file_and_channels_use_the_claimed_schemas(
    recorded: Recorded,
) -> None:
    expected = {
        "/targets/t1/box": "foxglove.ImageAnnotations",
        "/targets/t1/signals": "autotrack.TargetSignals",
        "/targets/t1/response": "foxglove.RawImage",
        "/targets/t1/local_variation": "foxglove.RawImage",
        "/camera/pose": "foxglove.PoseInFrame",
        "/tf": "foxglove.FrameTransform",
        "/camera/pose_quality": "autotrack.PoseQuality",
        "/landmarks": "foxglove.SceneUpdate",
        "/events": "autotrack.SessionEvent",
    }
    with open(recorded.path, "rb") as handle:
        reader = make_reader(handle, validate_crcs=True)
        summary = reader.get_summary()
        assert summary is not None and summary.statistics is not None
        topics = {channel.topic: channel for channel in summary.channels.values()}
        for topic, schema_name in expected.items():
            channel = topics[topic]
            schema = summary.schemas[channel.schema_id]
            assert (schema.name, schema.encoding, channel.message_encoding) == (
                schema_name,
                "jsonschema",
                "json",
            )
            assert json.loads(schema.data)["title"] == schema_name
        counts = {topic: 0 for topic in topics}
        for schema, channel, message in reader.iter_messages(log_time_order=False):
            document = json.loads(schema.data)
            _validate(json.loads(message.data), document, channel.topic)
            counts[channel.topic] += 1
        assert counts["/targets/t1/signals"] == FRAMES
        assert counts["/camera/pose"] == sum(p.valid for p in recorded.poses)
        assert summary.statistics.message_count == sum(counts.values())
        assert reader.get_header().library.startswith("autotrack-studio")
        metadata = {record.name: record.metadata for record in reader.iter_metadata()}
        assert metadata["autotrack.session"]["format_version"] == str(FORMAT_VERSION)


def test_foxglove_schemas_are_the_published_ones_unchanged() -> None:
    # Foxglove names its well-known schemas by title; ours carry the autotrack prefix.
    for name in SCHEMA_NAMES:
        document = schema_document(name)
        assert document["title"] == name
        if name.startswith("foxglove."):
            assert document["$comment"] == "Generated by https://github.com/foxglove/foxglove-sdk"


def _validate_every_message(path: Path) -> dict[str, int]:
    """Validate every message of a session against the schema its channel names; returns the
    number of messages per schema."""
    import jsonschema

    counts: dict[str, int] = {}
    with open(path, "rb") as handle:
        for schema, channel, message in make_reader(handle).iter_messages():
            assert (schema.encoding, channel.message_encoding) == ("jsonschema", "json")
            assert json.loads(schema.data) == schema_document(schema.name)
            jsonschema.validate(json.loads(message.data), json.loads(schema.data))
            counts[schema.name] = counts.get(schema.name, 0) + 1
    return counts


def test_every_recorded_message_validates_against_its_published_schema(
    recorded: Recorded, tmp_path: Path
) -> None:
    counts = _validate_every_message(recorded.path)
    frames_path = tmp_path / "frames.mcap"
    with SessionRecorder(frames_path, source="x", tracker_params={}, embed_frames=True) as rec:
        rec.log_frame(0, np.zeros((8, 8, 3), dtype=np.uint8))
    counts.update(_validate_every_message(frames_path))
    assert set(counts) == set(SCHEMA_NAMES)


def test_a_message_off_its_schema_is_caught() -> None:
    import jsonschema

    image = {"timestamp": {"sec": 0, "nsec": 2_000_000_000}, "width": 4}
    with pytest.raises(jsonschema.ValidationError, match="999999999"):
        jsonschema.validate(image, schema_document("foxglove.RawImage"))


def test_poses_go_to_world_camera_transform_and_pose_in_world(recorded: Recorded) -> None:
    with open(recorded.path, "rb") as handle:
        reader = make_reader(handle)
        transforms = [json.loads(m.data) for _, _, m in reader.iter_messages(topics=["/tf"])]
        handle.seek(0)
        pose_messages = [
            (m.log_time, json.loads(m.data))
            for _, _, m in make_reader(handle).iter_messages(topics=["/camera/pose"])
        ]
    assert {(t["parent_frame_id"], t["child_frame_id"]) for t in transforms} == {
        ("world", "camera")
    }
    assert {message["frame_id"] for _, message in pose_messages} == {"world"}
    valid_frames = [p.frame_index for p in recorded.poses if p.valid]
    assert [log_time for log_time, _ in pose_messages] == [
        round(i * 1e9 / FPS) for i in valid_frames
    ]
    assert pose_messages[1][1]["timestamp"] == {"sec": 0, "nsec": 40_000_000}


# --- truncation, corruption, bad input --------------------------------------------------------


def _record_in_small_chunks(path: Path, frames: int = 30) -> None:
    results = {"t1": _results(0, range(frames), 1), "t2": _results(1, range(frames), 2)}
    with SessionRecorder(
        path, source="generated", tracker_params=TrackerParams(), fps=FPS, flush_interval=3600
    ) as recorder:
        for frame_index in range(frames):
            for target_id, series in results.items():
                recorder.log_target(target_id, series[frame_index])
            recorder.log_pose(_pose(frame_index))
            recorder.flush()  # one chunk per frame, as a slow app would write


def test_truncated_file_reads_everything_before_the_cut(tmp_path: Path) -> None:
    full_path = tmp_path / "full.mcap"
    _record_in_small_chunks(full_path)
    full = open_session(full_path)
    data = full_path.read_bytes()
    previous_frames = -1
    for fraction in (0.2, 0.5, 0.8, 0.97):
        cut_path = tmp_path / f"cut_{fraction}.mcap"
        cut_path.write_bytes(data[: int(len(data) * fraction)])
        cut = open_session(cut_path)
        assert cut.truncated
        assert cut.bytes_read <= cut.file_size < len(data)
        frames = len(cut.frame_indices)
        assert frames >= previous_frames
        previous_frames = frames
        for target_id in cut.targets:
            np.testing.assert_array_equal(cut.tracks[target_id], full.tracks[target_id][:frames])
        np.testing.assert_array_equal(
            cut.poses.positions, full.poses.positions[: len(cut.poses.frame_indices)]
        )
    assert 5 < previous_frames <= 30
    # Cut inside the summary: the whole data section is still there.
    summary_cut = tmp_path / "summary_cut.mcap"
    summary_cut.write_bytes(data[:-40])
    cut = open_session(summary_cut)
    assert cut.truncated
    np.testing.assert_array_equal(cut.tracks["t2"], full.tracks["t2"])


def test_corrupted_chunk_is_reported(tmp_path: Path) -> None:
    path = tmp_path / "session.mcap"
    _record_in_small_chunks(path, frames=10)
    with open(path, "rb") as handle:
        chunk = make_reader(handle).get_summary().chunk_indexes[3]
    data = bytearray(path.read_bytes())
    middle = chunk.chunk_start_offset + chunk.chunk_length // 2
    data[middle : middle + 8] = bytes(255 - b for b in data[middle : middle + 8])
    bad = tmp_path / "corrupted.mcap"
    bad.write_bytes(bytes(data))
    with pytest.raises(SessionError, match="is corrupted"):
        open_session(bad)


def test_non_mcap_empty_missing_and_foreign_files_get_clear_errors(tmp_path: Path) -> None:
    text = tmp_path / "notes.mcap"
    text.write_text("frame,x,y,w,h\n1,2,3,4,5\n")
    with pytest.raises(SessionError, match="not an MCAP file"):
        open_session(text)
    empty = tmp_path / "empty.mcap"
    empty.write_bytes(b"")
    with pytest.raises(SessionError, match="empty"):
        open_session(empty)
    with pytest.raises(SessionError, match="does not exist"):
        open_session(tmp_path / "missing.mcap")
    foreign = tmp_path / "foreign.mcap"
    with open(foreign, "wb") as handle:
        writer = Writer(handle)
        writer.start()
        writer.add_metadata("robot", {"name": "r2"})
        writer.finish()
    with pytest.raises(SessionError, match="not an AutoTrack session"):
        open_session(foreign)
    header_only = tmp_path / "header_only.mcap"
    header_only.write_bytes(foreign.read_bytes()[:20])
    with pytest.raises(SessionError, match="cut short before its session metadata"):
        open_session(header_only)


def test_session_from_a_newer_format_version_is_refused(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(autotrack.sessions.metadata, "FORMAT_VERSION", FORMAT_VERSION + 1)
    with SessionRecorder(tmp_path / "new.mcap", source="x", tracker_params={}) as recorder:
        recorder.log_target("t1", _results(0, range(2), 1)[1])
    monkeypatch.undo()
    with pytest.raises(SessionError, match=r"format version 2 .* reads format versions up to 1"):
        open_session(tmp_path / "new.mcap")


def test_existing_session_files_are_never_overwritten(tmp_path: Path) -> None:
    path = tmp_path / "session.mcap"
    path.write_bytes(b"precious")
    with pytest.raises(SessionError, match="never overwritten"):
        SessionRecorder(path, source="x", tracker_params=TrackerParams())
    assert path.read_bytes() == b"precious"
    first = SessionRecorder.create(tmp_path, source="seq", tracker_params={}, name="same")
    second = SessionRecorder.create(tmp_path, source="seq", tracker_params={}, name="same")
    first.close()
    second.close()
    assert first.path != second.path
    assert first.path.exists() and second.path.exists()


def test_recorder_rejects_bad_ids_kinds_and_use_after_close(tmp_path: Path) -> None:
    result = _results(0, range(2), 1)[1]
    recorder = SessionRecorder(tmp_path / "s.mcap", source="x", tracker_params={})
    with pytest.raises(SessionError, match="target id"):
        recorder.log_target("bad/id", result)
    with pytest.raises(SessionError, match="lower_snake_case"):
        recorder.log_event("Box Drawn", 0, "t1")
    with pytest.raises(SessionError, match="cannot record a value"):
        recorder.log_event("box_drawn", 0, "t1", note=object())
    recorder.log_target("t1", result)
    recorder.flush()
    recorder.close()
    recorder.close()
    with pytest.raises(SessionError, match="is closed"):
        recorder.log_target("t1", result)
    assert open_session(tmp_path / "s.mcap").frame_count == 1


def test_embedded_frames_are_jpeg_compressed_images(tmp_path: Path) -> None:
    frames, _ = _generated_sequence(3)
    with SessionRecorder(
        tmp_path / "frames.mcap", source="x", tracker_params={}, embed_frames=True
    ) as recorder:
        for frame_index, frame in enumerate(frames):
            assert recorder.log_frame(frame_index, frame)
    with SessionRecorder(tmp_path / "no_frames.mcap", source="x", tracker_params={}) as recorder:
        assert not recorder.log_frame(0, frames[0])
    assert open_session(tmp_path / "frames.mcap").image_count == 3
    with open(tmp_path / "frames.mcap", "rb") as handle:
        schema, _, message = next(make_reader(handle).iter_messages(topics=["/camera/image"]))
    assert schema.name == "foxglove.CompressedImage"
    payload = json.loads(message.data)
    assert payload["format"] == "jpeg"
    decoded = cv2.imdecode(np.frombuffer(base64.b64decode(payload["data"]), np.uint8), 1)
    decoded_rgb = cv2.cvtColor(decoded, cv2.COLOR_BGR2RGB)
    assert decoded_rgb.shape == frames[0].shape
    assert np.abs(decoded_rgb.astype(int) - frames[0]).mean() < 8


# --- CLI ----------------------------------------------------------------------------------------


def test_cli_info_summarises_the_session(recorded: Recorded, capsys: pytest.CaptureFixture) -> None:
    assert main(["session", "info", str(recorded.path), "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["frames"] == FRAMES
    # as `session export` writes them: the deleted t3 is listed apart, not counted
    assert set(summary["targets"]) == {"t1", "t2"} and summary["deleted_targets"] == ["t3"]
    assert summary["targets"]["t2"]["frames"] > 0
    assert summary["poses"] == {"frames": FRAMES, "valid": sum(p.valid for p in recorded.poses)}
    assert summary["events"] == {"box_drawn": 3, "box_corrected": 1, "box_deleted": 1}
    assert summary["duration_s"] == pytest.approx(FRAMES / FPS)
    assert summary["truncated"] is False
    assert main(["session", "info", str(recorded.path)]) == 0
    text = capsys.readouterr().out
    assert "complete  yes" in text and "targets   2 (1 deleted: t3)" in text
    assert "t3:" not in text


def test_cli_export_round_trips_tracks_csv_and_tum(
    recorded: Recorded, tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    out = tmp_path / "export"
    code = main(
        [
            "session",
            "export",
            str(recorded.path),
            "--tracks",
            str(out / "tracks"),
            "--csv",
            str(out / "all.csv"),
            "--poses",
            str(out / "poses.tum"),
        ]
    )
    assert code == 0
    session = open_session(recorded.path)
    # t3 was deleted by the user at frame 30: exports leave it out.
    assert session.deleted_targets == {"t3"}
    assert not (out / "tracks" / "t3.txt").exists()
    assert sorted(p.name for p in (out / "tracks").iterdir()) == ["t1_L1.txt", "t2_L2.txt"]
    for target_id in session.exported_targets:
        track_file = out / "tracks" / f"{target_id}_{session.landmark_ids[target_id]}.txt"
        lines = track_file.read_text().splitlines()
        first_box = recorded.results[target_id][0].box
        first_frame = recorded.results[target_id][0].frame_index
        x, y, w, h = (float(v) for v in lines[first_frame].split(","))
        assert (x, y, w, h) == pytest.approx(
            (first_box[0] + 1, first_box[1] + 1, *first_box[2:]), abs=1e-4
        )
        boxes = read_boxes(track_file)
        np.testing.assert_allclose(boxes, session.tracks[target_id], atol=1e-4)
    rows = (out / "all.csv").read_text().splitlines()
    assert rows[0] == "frame,target,landmark,x,y,w,h,score,aberrant,trusted"
    kept = [series for target, series in recorded.results.items() if target != "t3"]
    assert len(rows) - 1 == sum(len(series) for series in kept)
    assert not any(row.split(",")[1] == "t3" for row in rows[1:])
    frame, target, landmark, *numbers = rows[1 + 2 * 7 + 1].split(",")  # frame 7, t2
    assert (frame, target, landmark) == ("7", "t2", "L2")
    result = recorded.results["t2"][7]
    assert [float(v) for v in numbers[:4]] == list(result.box)
    assert float(numbers[4]) == result.peak_score and numbers[5] == str(int(result.aberrant))
    assert numbers[6] == ""  # an AutoTrack target: the hybrid's column stays empty
    tum = np.loadtxt(out / "poses.tum", comments="#")
    valid = [p for p in recorded.poses if p.valid]
    assert tum.shape == (len(valid), 8)
    np.testing.assert_allclose(tum[:, 0], [p.frame_index / FPS for p in valid], atol=1e-6)
    np.testing.assert_allclose(tum[:, 1:4], [p.position for p in valid], rtol=1e-8)
    np.testing.assert_allclose(tum[:, 4:], [p.quaternion_xyzw() for p in valid], atol=1e-8)
    capsys.readouterr()
    # Outputs are not replaced without --force.
    assert main(["session", "export", str(recorded.path), "--csv", str(out / "all.csv")]) == 2
    assert "already exists" in capsys.readouterr().err
    assert (
        main(["session", "export", str(recorded.path), "--csv", str(out / "all.csv"), "--force"])
        == 0
    )


def test_cli_reports_bad_files_in_one_line(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    text = tmp_path / "notes.txt"
    text.write_text("hello")
    assert main(["session", "info", str(text)]) == 2
    error = capsys.readouterr().err
    assert error.count("\n") == 1 and "not an MCAP file" in error
    assert main(["session", "export", str(text)]) == 2
    assert "nothing to export" in capsys.readouterr().err


def test_cli_info_says_when_a_session_was_cut_short(
    recorded: Recorded, tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    data = recorded.path.read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: len(data) // 2])
    assert main(["session", "info", str(cut)]) == 0
    assert "complete  NO: cut short" in capsys.readouterr().out


def test_cli_info_says_being_recorded_for_a_file_a_recorder_still_writes(
    tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    import subprocess
    import sys

    from tests.conftest import REPO

    result = _results(0, range(3), 1)[1]
    live = tmp_path / "live.mcap"
    with SessionRecorder(live, source="x", tracker_params={}) as recorder:
        recorder.log_target("t1", result)
        recorder.flush()
        assert open_session(live).being_recorded
        assert main(["session", "info", str(live)]) == 0
        assert "complete  not yet: being recorded" in capsys.readouterr().out
    assert not open_session(live).being_recorded  # closed: complete
    # Another process recording: being recorded while it runs; cut short once it is killed.
    other = tmp_path / "other.mcap"
    script = (
        "import sys; from autotrack.sessions import SessionRecorder\n"
        "r = SessionRecorder(sys.argv[1], source='x', tracker_params={})\n"
        "print('ready', flush=True); sys.stdin.read()\n"
    )
    child = subprocess.Popen(
        [sys.executable, "-c", script, str(other)],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
        cwd=REPO,
    )
    try:
        assert child.stdout.readline().strip() == "ready"
        session = open_session(other)
        assert session.truncated and session.being_recorded
    finally:
        child.kill()
        child.wait(timeout=60)
    session = open_session(other)
    assert session.truncated and not session.being_recorded
    assert main(["session", "info", str(other)]) == 0
    assert "complete  NO: cut short" in capsys.readouterr().out


def test_a_session_whose_header_cannot_be_written_leaves_no_file(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """A full disk while the header is written: no orphan file holding half a header."""
    import errno

    def full_disk(self, *args, **kwargs) -> None:
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(Writer, "start", full_disk)
    with pytest.raises(SessionError, match="No space left"):
        SessionRecorder(tmp_path / "s.mcap", source="x", tracker_params={})
    with pytest.raises(SessionError, match="No space left"):
        SessionRecorder.create(tmp_path, source="seq", tracker_params={})
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("bad_id", ["A\nB", "A\rB", "NUL\x00", "tab\there", "A\u2028B"])
def test_control_characters_in_landmark_ids_are_refused_where_they_enter(
    tmp_path: Path, bad_id: str
) -> None:
    from autotrack.errors import InputError, SceneError
    from autotrack.io.frames import InMemoryFrames
    from autotrack.pipeline import Pipeline, Recording

    with pytest.raises(SceneError, match="control character"):
        Landmark(bad_id, np.array([0.0, 0.0, 0.0]))
    result = _results(0, range(2), 1)[1]
    recorder = SessionRecorder(tmp_path / "s.mcap", source="x", tracker_params={})
    with pytest.raises(SessionError, match="control character"):
        recorder.log_target("t1", result, landmark_id=bad_id)
    with pytest.raises(SessionError, match="control character"):
        recorder.log_event("box_drawn", 0, "t1", landmark_id=bad_id)
    recorder.close()
    # A pipeline refuses such a landmark before its session file is created.
    frames, boxes = _generated_sequence(3)
    scene = Scene(
        CameraIntrinsics(300.0, 300.0, 160.0, 120.0, (), 320, 240),
        (
            Landmark("L1", np.array([0.0, 0.0, 0.0])),
            Landmark("L2", np.array([4.0, 0.0, 0.0])),
            Landmark("L3", np.array([0.0, 3.0, 0.5])),
            Landmark("L4", np.array([1.0, 1.0, 2.0])),
        ),
    )
    sessions = tmp_path / "sessions"
    recording = Recording(source="generated", directory=sessions)
    source = InMemoryFrames(frames, "generated")
    with (
        Pipeline(source, TrackerParams(), scene=scene, recording=recording) as pipeline,
        pytest.raises(InputError, match="unknown landmark"),
    ):
        pipeline.add_targets(0, {bad_id: boxes["a"]})
    assert not sessions.exists() or list(sessions.iterdir()) == []
