"""The app's live mode, driven through the tab's controller without a browser: a video played in
real time through the library's reader, boxes drawn on a frozen frame, a deliberately slow
tracker forcing drops, the live figures, the recording with its frames, and its reopening;
live sources need the server's --allow-live flag and typed sources are checked."""

from __future__ import annotations

import math
import time
from pathlib import Path

import cv2
import numpy as np
import pytest

from autotrack.errors import InputError
from autotrack.io.frames import open_frames
from autotrack.sessions import open_session
from autotrack_studio.config import DEMO_DIR, AppConfig
from autotrack_studio.controller import TabController
from autotrack_studio.live import FROZEN, OFF, PREVIEW, TRACKING, LiveControl
from autotrack_studio.paths import live_source
from autotrack_studio.plots import chart_data, tracked_rows
from autotrack_studio.recordings import RecordingRegistry

VIDEO_FPS = 10.0


def _demo_video(folder: Path) -> Path:
    """The embedded demo's 60 frames as a 10 fps MJPEG video (6 s played in real time)."""
    source = open_frames(DEMO_DIR / "img")
    path = folder / "flight.avi"
    writer = cv2.VideoWriter(
        str(path), cv2.VideoWriter_fourcc(*"MJPG"), VIDEO_FPS, source.frame_size
    )
    for index in range(len(source)):
        writer.write(source.read_bgr(index))
    writer.release()
    source.close()
    return path


def _live_tab(tmp_path: Path, allowed: bool = True) -> tuple[TabController, LiveControl]:
    config = AppConfig(
        sessions_dir=tmp_path / "sessions",
        allowed_roots=(tmp_path / "media",),
        demo_dir=DEMO_DIR,
        tracker_threads=1,
        allow_live=allowed,
    )
    controller = TabController(config, config.browsable_roots(), RecordingRegistry(), 1)
    return controller, LiveControl(controller, config.allow_live)


@pytest.fixture
def media(tmp_path: Path) -> Path:
    folder = tmp_path / "media"
    folder.mkdir()
    _demo_video(folder)
    return folder


def test_a_video_played_live_is_tracked_on_its_newest_frames_recorded_and_reopened(
    tmp_path: Path, media: Path
) -> None:
    from autotrack.tracker.parallel.warmup import warm_up

    warm_up()  # as the server does at start: no kernel compiling inside the live run
    controller, live = _live_tab(tmp_path)
    live.open_source("flight.avi", str(DEMO_DIR / "scene.json"))
    assert live.state == PREVIEW and controller.run is None
    live.step()  # the preview shows the newest frame
    preview = live.snapshot()
    assert preview is not None and preview.frame.shape == (540, 960, 3) and not preview.drawings
    live.freeze()
    frozen = live.newest.index
    assert live.state == FROZEN and controller.cursor == frozen
    live.load_boxes_json()  # the demo's boxes.json beside the scene, on the frozen frame
    run = controller.run
    assert set(run.results_at(frozen)) == {"T1", "T2", "T3", "T4"}
    reader = live.reader
    track_next = run.advance

    def slow_advance(frame_index: int) -> None:
        """A tracker that finishes a frame only once two newer ones were captured."""
        reader.wait_until_captured(frame_index + 3, timeout=60.0)
        track_next(frame_index)

    run.advance = slow_advance
    live.start()
    assert live.state == TRACKING
    live_started = live.started[0]
    boxes: dict[int, dict[str, tuple[float, ...]]] = {}
    figures = None
    while live.state == TRACKING:
        live.step()
        if live.state == TRACKING:
            boxes[controller.cursor] = {
                k: r.box for k, r in run.results_at(controller.cursor).items()
            }
            figures = live.figures()
            status = live.snapshot().status
            assert status.startswith("● live: capture") and "dropped" in status
            processed = list(live.log.processed)
            capture_times = list(reader.capture_times)
    assert live.state == OFF
    assert "ended" in controller.message and "recorded to" in controller.message

    # Drops and latencies are reported: the slow tracker leaves at least one frame out
    # between two processed ones, and each latency covers its wait for two newer frames.
    indices = [frame.index for frame in processed if frame.index > live_started]
    waited = [
        (a, b) for a, b in zip(indices, indices[1:], strict=False) if a + 3 <= len(capture_times)
    ]
    assert len(waited) >= 3 and all(b - a >= 2 for a, b in waited)  # (not at the video's end)
    assert figures is not None and figures.dropped > 0 and figures.processed == len(indices)
    in_flight = figures.captured - figures.processed - figures.dropped
    assert 0 <= in_flight <= 2  # the newest frame(s), not taken yet
    assert math.isfinite(figures.latency_ms) and figures.latency_ms > 0
    for frame in processed:
        if frame.index > frozen and frame.index + 2 < len(capture_times):
            assert frame.latency >= capture_times[frame.index + 2] - frame.capture_time

    # The recording holds the processed frames (with their images) and their boxes.
    path = next((tmp_path / "sessions").glob("*.mcap"))
    session = open_session(path)
    recorded = [frozen, *boxes]
    assert session.image_count == len(recorded)
    for frame_index, by_target in boxes.items():
        for target_id, box in by_target.items():
            np.testing.assert_allclose(session.tracks[target_id][frame_index], box, atol=1e-3)
    dropped = sorted(set(range(frozen, max(boxes))) - set(recorded))
    assert dropped and np.isnan(session.tracks["T1"][dropped]).all()

    # Stop reopened it to look through: seeking shows the recorded frames and boxes.
    review = controller.run
    assert review is not run and review.session_path is None  # no new file
    assert review.frames.recorded_indices == tuple(recorded)
    some = indices[len(indices) // 2]
    controller.seek(some)
    view = controller.snapshot()
    assert set(view.drawings) == set(boxes[some])
    np.testing.assert_allclose(view.drawings["T2"].box, boxes[some]["T2"], atol=1e-3)
    # Its charts give the dropped frames no row, so a target's line joins the tracked frames
    # (as nulls, they broke it into fragments too short to see).
    history, count = view.history, view.history.last_frame + 1
    rows = tracked_rows(history, count, some)
    assert set(recorded) <= set(rows) and set(dropped).isdisjoint(rows)
    x, peaks, _line = chart_data(count, [history.signals["T1"]["peak_score"]], some, (0, 1), rows)
    assert None not in [value for frame, value in zip(x, peaks, strict=True) if frame > frozen + 1]
    controller.seek(dropped[-1])
    assert not controller.snapshot().drawings
    name, content = controller.export("mcap")  # the downloads are the live recording's
    assert name == path.name and content[:8] == path.read_bytes()[:8]
    # ... and so does reopening it from the Session list.
    controller.sessions.refresh()
    controller.sessions.reopen(path.name)
    assert controller.run.frames.recorded_indices == tuple(recorded)
    assert len(list((tmp_path / "sessions").glob("*.mcap"))) == 1
    controller.close()


def test_live_sources_need_the_allow_live_flag(tmp_path: Path, media: Path) -> None:
    from autotrack_studio.cli import add_parser

    _controller, live = _live_tab(tmp_path, allowed=False)
    with pytest.raises(InputError, match="restart it with `autotrack app --allow-live`"):
        live.open_source("flight.avi")
    assert live.state == OFF and live.reader is None
    assert AppConfig().allow_live is False
    import argparse

    parser = argparse.ArgumentParser()
    add_parser(parser.add_subparsers())
    assert parser.parse_args(["app"]).allow_live is False
    assert parser.parse_args(["app", "--allow-live"]).allow_live is True


def test_typed_live_sources_are_checked(tmp_path: Path, media: Path) -> None:
    roots = (media.resolve(),)
    assert live_source(" 0 ", roots) == Path("0")
    assert live_source("rtsp://cam.local:8554/live", roots) == "rtsp://cam.local:8554/live"
    assert live_source("flight.avi", roots) == (media / "flight.avi").resolve()
    refused = {
        "file:///etc/passwd": "file:// streams are not allowed",
        "udp://0.0.0.0:5000": "udp:// streams are not allowed",
        "http:///nohost": "not a stream URL",
        "rtsp://cam/a b": "not a stream URL",
        "99": "out of range",
        "/etc/hostname": "no such file or folder among those this server may open",
        "../flight.avi": "no such file or folder among those this server may open",
        ".": "is a folder",
        "": "type a camera index",
    }
    for text, message in refused.items():
        with pytest.raises(InputError, match=message):
            live_source(text, roots)


def test_a_source_that_cannot_be_opened_says_so_and_opens_nothing(
    tmp_path: Path, media: Path
) -> None:
    (media / "broken.avi").write_bytes(b"not a video at all" * 100)
    controller, live = _live_tab(tmp_path)
    controller.open_initial()  # the demo
    opened = controller.run
    with pytest.raises(InputError, match="cannot open .*broken.avi"):
        live.open_source("broken.avi")
    assert live.state == OFF and live.reader is None
    assert controller.run is opened and controller.run.frame_count == 60  # still open
    controller.close()


class _MjpegStream:
    """An IP camera on 127.0.0.1: the demo's frames as an HTTP MJPEG stream at 10 fps (the
    first frame held for 2 s, time to freeze it), then the connection dropped mid-flight."""

    def __init__(self, frames: int = 45) -> None:
        import threading
        from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer

        source = open_frames(DEMO_DIR / "img")
        order = [0] * 20 + list(range(frames - 20))
        jpegs = [cv2.imencode(".jpg", source.read_bgr(i))[1].tobytes() for i in order]
        source.close()

        class Camera(BaseHTTPRequestHandler):
            def do_GET(self) -> None:
                self.send_response(200)
                self.send_header("Content-Type", "multipart/x-mixed-replace; boundary=frame")
                self.end_headers()
                for jpeg in jpegs:
                    part = b"--frame\r\nContent-Type: image/jpeg\r\nContent-Length: %d\r\n\r\n"
                    self.wfile.write(part % len(jpeg) + jpeg + b"\r\n")
                    self.wfile.flush()
                    time.sleep(1.0 / VIDEO_FPS)
                self.close_connection = True  # the camera goes away

            def log_message(self, *args: object) -> None:
                pass

        self.server = ThreadingHTTPServer(("127.0.0.1", 0), Camera)
        self.thread = threading.Thread(target=self.server.serve_forever, daemon=True)
        self.thread.start()
        self.url = f"http://127.0.0.1:{self.server.server_address[1]}/stream.mjpg"

    def close(self) -> None:
        self.server.shutdown()
        self.server.server_close()


def test_a_stream_that_disconnects_mid_run_says_so_and_keeps_the_recording(
    tmp_path: Path, media: Path
) -> None:
    from autotrack.tracker.parallel.warmup import warm_up

    warm_up()
    camera = _MjpegStream()
    try:
        controller, live = _live_tab(tmp_path)
        live.open_source(camera.url, str(DEMO_DIR / "scene.json"))
        live.freeze()
        live.load_boxes_json()
        live.start()
        tracked = 0
        while live.state == TRACKING:
            live.step()
            tracked += live.state == TRACKING
    finally:
        camera.close()
    assert tracked >= 3
    assert controller.message.startswith(f"{camera.url} stopped sending (ended or lost)")
    path = next((tmp_path / "sessions").glob("*.mcap"))
    assert f"recorded to {path.name}" in controller.message
    session = open_session(path)
    assert session.source == camera.url and session.image_count == tracked + 1
    assert controller.run.frames.recorded_indices[-1] == controller.cursor


def test_the_live_source_is_shown_relative_to_its_allowed_folder(
    tmp_path: Path, media: Path
) -> None:
    controller, live = _live_tab(tmp_path)
    live.open_source(str(media / "flight.avi"))  # typed as an absolute path
    shown = [controller.message, live.snapshot().status]
    live.freeze()
    shown += [controller.message, live.snapshot().status]
    live.stop()
    shown.append(controller.message)
    for text in shown:
        assert str(tmp_path) not in text, text
    assert "Live: media/flight.avi." in shown[0] and "**media/flight.avi**" in shown[1]
    assert "**media/flight.avi**" in shown[3]
    controller.close()


def test_live_boxes_json_refuses_to_stack_on_drawn_targets(tmp_path: Path, media: Path) -> None:
    """As on a file: boxes.json adds a target per landmark, so once a box is drawn on the
    frozen frame it is refused with the same message and adds nothing."""
    controller, live = _live_tab(tmp_path)
    live.open_source("flight.avi", str(DEMO_DIR / "scene.json"))
    live.step()
    live.freeze()
    controller.place_box((100.0, 100.0, 40.0, 40.0))
    assert list(controller.run.targets) == ["T1"]
    with pytest.raises(InputError, match="delete the 1 drawn first"):
        live.load_boxes_json()
    assert list(controller.run.targets) == ["T1"]
    assert live.state == FROZEN
    live.halt()
    controller.close()


def test_a_live_run_tracks_with_the_tracker_chosen_before_it_froze(
    tmp_path: Path, media: Path
) -> None:
    from autotrack.hybrid.factory import make_tracker

    controller, live = _live_tab(tmp_path)
    controller.choose_preset("nanotrack")
    live.open_source("flight.avi", str(DEMO_DIR / "scene.json"))
    live.freeze()
    live.load_boxes_json()
    run = controller.run
    assert run.tracker_name == controller.preset_name == "nanotrack"
    frozen = live.newest.index
    started = run.results_at(frozen)["T1"]
    by_hand = make_tracker("nanotrack").init(run.frame(frozen), started.box)
    assert started.search_box == by_hand.search_box  # NanoTrack's own search region
    live.stop()
    controller.close()
