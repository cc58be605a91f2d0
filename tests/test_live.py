"""Live input: a video file played at its frame rate through the reader thread; a slow consumer
gets the newest frame, and drops, capture times and latency are recorded."""

from __future__ import annotations

import csv
from pathlib import Path

import cv2
import numpy as np
import pytest

from autotrack.cli import main
from autotrack.io.frames import open_frames
from autotrack.io.live import LiveLog, LiveReader, source_argument
from autotrack.io.otb_boxes import read_boxes
from autotrack.io.tum import read_tum
from autotrack.sessions import open_session
from tests.sequences import moving_target_sequence

VIDEO_FPS = 20.0
VIDEO_FRAMES = 30


def _write_video(path: Path, frames: list[np.ndarray], fps: float) -> Path:
    height, width = frames[0].shape[:2]
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), fps, (width, height))
    assert writer.isOpened()
    for frame in frames:
        writer.write(cv2.cvtColor(frame, cv2.COLOR_RGB2BGR))
    writer.release()
    return path


@pytest.fixture(scope="module")
def video(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, np.ndarray]:
    sequence = moving_target_sequence(num_frames=VIDEO_FRAMES)
    path = tmp_path_factory.mktemp("live") / "target.avi"
    return _write_video(path, sequence.frames, VIDEO_FPS), sequence.boxes


def test_slow_consumer_gets_the_newest_frame_and_drops_are_recorded(video) -> None:
    path, _ = video
    with open_frames(path) as decoded:
        expected = [decoded.read(index) for index in range(len(decoded))]
    taken = []
    with LiveReader(path) as reader:
        assert reader.fps == pytest.approx(VIDEO_FPS)
        log = LiveLog(reader)
        for frame in log.frames():
            # A tracker too slow for the source: it finishes only once two newer frames exist.
            reader.wait_until_captured(frame.index + 3)
            taken.append(frame)
            log.result_ready()
    summary = log.summary()
    assert summary.captured == reader.captured == VIDEO_FRAMES
    indices = [frame.index for frame in taken]
    assert [frame.index for frame in summary.processed] == indices
    # After frame a, frames up to a + 2 exist (until the source ends): the next one is newer.
    pairs = zip(indices, indices[1:], strict=False)
    assert all(b >= a + 2 for a, b in pairs if a + 3 <= VIDEO_FRAMES)
    assert indices[0] == 0 and indices[-1] == VIDEO_FRAMES - 1  # first and last are kept
    assert summary.dropped == tuple(sorted(set(range(VIDEO_FRAMES)) - set(indices)))
    assert list(summary.dropped) == reader.dropped
    assert len(summary.dropped) >= (VIDEO_FRAMES - 3) // 2
    for frame in taken:  # each frame handed out is the source's frame of that index
        np.testing.assert_array_equal(frame.image, expected[frame.index])
    times = np.array(summary.capture_times)
    assert np.all(np.diff(times) >= 0)
    # Played at the file's rate: frame i is never captured before i / fps.
    assert np.all(times >= np.arange(VIDEO_FRAMES) / VIDEO_FPS - 1e-3)
    for processed in summary.processed:
        assert processed.capture_time == times[processed.index]
        if processed.index + 2 < VIDEO_FRAMES:  # it waited for two newer frames
            assert processed.latency >= times[processed.index + 2] - times[processed.index]
    assert "30 frames captured" in summary.describe()
    assert f"{len(summary.dropped)} dropped (frames " in summary.describe()


def test_the_first_frame_waits_for_the_consumer_and_later_ones_do_not(video) -> None:
    path, _ = video
    with LiveReader(path) as reader:
        reader.wait_until_captured(4)  # the consumer is late: frames 0-3 have arrived
        first = reader.next_frame()
        reader.wait_until_captured(8)
        second = reader.next_frame()
    assert first.index == 0  # the initial boxes are drawn on it: never dropped
    assert second.index >= 7 and reader.dropped[:3] == [1, 2, 3]
    assert set(range(1, second.index)) <= set(reader.dropped)


def test_track_realtime_reports_every_captured_frame(video, tmp_path, capsys) -> None:
    path, truth = video
    x, y, w, h = truth[0]
    out, log = tmp_path / "boxes.txt", tmp_path / "frames.csv"
    argv = ["track", str(path), "--realtime", "--init", f"{x + 1},{y + 1},{w},{h}", "--quiet"]
    argv += ["--fps", "5"]  # slow enough to keep up on a loaded machine
    assert main([*argv, "--out", str(out), "--frame-log", str(log)]) == 0
    printed = capsys.readouterr().out
    assert (
        f"live: {VIDEO_FRAMES} frames captured" in printed
        and "latency capture -> result" in printed
    )
    with log.open() as handle:
        rows = list(csv.DictReader(handle))
    assert [int(row["frame"]) for row in rows] == list(range(VIDEO_FRAMES))
    processed = np.array([row["processed"] == "1" for row in rows])
    assert processed[0] and processed.sum() >= 2  # the first frame is never dropped
    assert all(float(row["latency_ms"]) > 0 for row in rows if row["processed"] == "1")
    assert all(row["latency_ms"] == "" for row in rows if row["processed"] == "0")
    boxes = read_boxes(out)
    assert len(boxes) == VIDEO_FRAMES
    assert np.array_equal(np.isfinite(boxes).all(axis=1), processed)
    np.testing.assert_allclose(boxes[0], truth[0], atol=1e-3)  # tracking starts on frame 0


def test_localize_realtime_writes_poses_at_the_capture_times(tmp_path, capsys) -> None:
    from autotrack.synthetic.renderer import render_sequence
    from autotrack.synthetic.trajectories import RenderSettings, SequenceSpec

    spec = SequenceSpec("s", "circle", 10, 0, RenderSettings(width=640, height=360), period_s=45.0)
    folder = render_sequence(tmp_path / "synthetic", spec)
    with open_frames(folder / "img") as frames:
        video = _write_video(tmp_path / "flight.avi", list(frames), 10.0)
    poses, log = tmp_path / "poses.tum", tmp_path / "frames.csv"
    argv = ["localize", str(video), "--realtime", "--quiet", "--out", str(poses), "--fps", "4"]
    argv += ["--scene", str(folder / "scene.json"), "--init", str(folder / "boxes.json")]
    argv += ["--gt", str(folder / "poses_gt.tum"), "--session", str(tmp_path / "live.mcap")]
    assert main([*argv, "--frame-log", str(log), "--tracks", str(tmp_path / "t.csv")]) == 0
    printed = capsys.readouterr().out
    assert "live: 10 frames captured" in printed
    with log.open() as handle:
        rows = [row for row in csv.DictReader(handle) if row["processed"] == "1"]
    stamps, positions, _ = read_tum(poses)
    assert len(stamps) >= 1
    # Against the ground truth, frames are matched by capture index: every valid pose counts.
    table_row = printed.splitlines()[
        printed.splitlines().index("valid frames more than 20 cm off: 0") - 1
    ]
    assert table_row.split()[-2:] == [str(len(stamps)), str(10 - len(stamps))]
    capture_times = {round(float(row["capture_time_s"]), 6) for row in rows}
    assert {round(float(s), 6) for s in stamps} <= capture_times
    with (tmp_path / "t.csv").open() as handle:
        tracks = list(csv.DictReader(handle))
    assert [int(row["frame"]) for row in tracks] == [int(row["frame"]) for row in rows]
    # The session holds the processed frames' images (a live source cannot be replayed).
    session = open_session(tmp_path / "live.mcap")
    assert session.image_count == len(rows) and session.recorded_live
    recorded = np.flatnonzero(np.isfinite(next(iter(session.tracks.values()))).all(axis=1))
    assert recorded.tolist() == [int(row["frame"]) for row in rows]
    # Frames are numbered by capture index: each valid pose is near that frame's true pose.
    _, truth, _ = read_tum(folder / "poses_gt.tum")
    valid = [row for row in tracks if row["valid"] == "1"]
    assert len(valid) == len(stamps)
    for row, position in zip(valid, positions, strict=True):
        assert np.linalg.norm(position - truth[int(row["frame"])]) < 0.3


def test_live_sources_need_realtime_and_bad_sources_are_one_line(video, tmp_path, capsys) -> None:
    assert source_argument("rtsp://cam.local:554/stream") == "rtsp://cam.local:554/stream"
    assert source_argument("clip.mp4") == Path("clip.mp4")
    assert main(["track", "0", "--init", "1,1,5,5"]) == 2
    assert (
        capsys.readouterr().err.strip()
        == "autotrack: error: camera 0 is live input: add --realtime"
    )
    assert main(["track", "http://127.0.0.1:9/x.mjpg", "--init", "1,1,5,5"]) == 2
    assert "http://127.0.0.1:9/x.mjpg is live input: add --realtime" in capsys.readouterr().err
    missing = tmp_path / "missing.avi"
    assert main(["track", str(missing), "--realtime", "--init", "1,1,5,5"]) == 2
    assert f"no such video file: {missing}" in capsys.readouterr().err
    path, _ = video
    assert main(["track", str(path), "--frame-log", str(tmp_path / "f.csv")]) == 2
    assert "--frame-log records live runs: add --realtime" in capsys.readouterr().err
    assert main(["track", str(path), "--realtime"]) == 2
    assert "give the initial box with --init" in capsys.readouterr().err
    # A box outside the video's frames, in the 1-based convention the user typed.
    assert main(["track", str(path), "--realtime", "--init", "900,10,20,20", "--quiet"]) == 2
    assert "--init 900,10,20,20 (1-based x,y,w,h) lies outside" in capsys.readouterr().err
