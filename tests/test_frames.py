"""Frame sources: image folders, benchmark sequence folders, videos, and their errors."""

from __future__ import annotations

import contextlib
import os
import sys
import threading
from pathlib import Path

import cv2
import numpy as np
import pytest

from autotrack.errors import InputError
from autotrack.io import frames
from autotrack.io.frames import FrameCache, ImageSequence, VideoFrames, open_frames
from tests.conftest import shared_sequence_dir


def _write_frames(folder: Path, count: int, size_wh=(32, 24)) -> list[np.ndarray]:
    """Colour PNGs whose BGR pixel value encodes the frame index."""
    folder.mkdir(parents=True, exist_ok=True)
    frames = []
    for index in range(count):
        frame = np.zeros((size_wh[1], size_wh[0], 3), np.uint8)
        frame[..., 0] = 200  # blue in OpenCV's BGR order
        frame[..., 2] = 10 * index  # red
        cv2.imwrite(str(folder / f"{index + 1:04d}.png"), frame)
        frames.append(frame)
    return frames


def test_image_folder_reads_rgb_in_sorted_order(tmp_path):
    written = _write_frames(tmp_path / "seq", 5)
    (tmp_path / "seq" / "notes.txt").write_text("not a frame")
    source = open_frames(tmp_path / "seq")
    assert isinstance(source, ImageSequence)
    assert len(source) == 5 and source.name == "seq" and source.fps is None
    assert source.frame_size == (32, 24)
    rgb = source.read(3)
    assert rgb.dtype == np.uint8 and rgb.shape == (24, 32, 3)
    assert tuple(rgb[0, 0]) == (30, 0, 200)  # R, G, B
    np.testing.assert_array_equal(source.read_bgr(3), written[3])
    np.testing.assert_array_equal(source.read(-1), source.read(4))
    assert [int(frame[0, 0, 0]) for frame in source] == [0, 10, 20, 30, 40]
    with pytest.raises(IndexError):
        source.read(5)


def test_grey_images_stay_two_dimensional(tmp_path):
    folder = tmp_path / "grey"
    folder.mkdir()
    cv2.imwrite(str(folder / "a.png"), np.full((10, 12), 77, np.uint8))
    frame = open_frames(folder).read(0)
    assert frame.shape == (10, 12) and int(frame[0, 0]) == 77


def test_benchmark_sequence_folder_uses_img_and_its_own_name(tmp_path):
    _write_frames(tmp_path / "Bird" / "img", 3)
    (tmp_path / "Bird" / "groundtruth_rect.txt").write_text("1,1,5,5\n" * 3)
    source = open_frames(tmp_path / "Bird")
    assert source.name == "Bird" and len(source) == 3


def test_missing_path_is_an_input_error(tmp_path):
    with pytest.raises(InputError, match="no such file or folder"):
        open_frames(tmp_path / "nowhere")


def test_empty_folder_is_an_input_error(tmp_path):
    (tmp_path / "empty").mkdir()
    with pytest.raises(InputError, match="no image files"):
        open_frames(tmp_path / "empty")


def test_corrupt_frame_names_its_index_and_file(tmp_path):
    _write_frames(tmp_path / "seq", 5)
    corrupt = tmp_path / "seq" / "0003.png"
    corrupt.write_bytes(b"\x89PNG this is not an image")
    source = open_frames(tmp_path / "seq")
    source.read(1)
    with pytest.raises(InputError) as error:
        source.read(2)
    message = str(error.value)
    assert "frame 2 (0-based; frame 3 counting from 1)" in message
    assert str(corrupt) in message


def test_unopenable_video_is_an_input_error(tmp_path):
    video = tmp_path / "broken.mp4"
    video.write_bytes(b"definitely not a video" * 20)
    with pytest.raises(InputError, match="cannot open video"):
        open_frames(video)


def test_video_random_access_forward_and_backward(tmp_path):
    path = tmp_path / "clip.avi"
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 12.0, (64, 48))
    assert writer.isOpened()
    for index in range(40):
        writer.write(np.full((48, 64, 3), 6 * index, np.uint8))
    writer.release()

    source = open_frames(path)
    assert isinstance(source, VideoFrames)
    assert len(source) == 40 and source.fps == pytest.approx(12.0)
    assert source.frame_size == (64, 48)

    def level(index: int) -> float:
        return float(source.read(index).mean())

    # Forward, a short step back (cache), a long jump back (re-decode from the start).
    for index in (0, 10, 39, 35, 2, 20):
        assert level(index) == pytest.approx(6 * index, abs=3), index
    source.close()


def test_single_image_file_is_a_one_frame_source(tmp_path):
    _write_frames(tmp_path, 1)
    source = open_frames(tmp_path / "0001.png")
    assert len(source) == 1 and source.read(0).shape == (24, 32, 3)


def test_real_benchmark_sequence():
    folder = shared_sequence_dir("OTB", "Crossing")
    source = open_frames(folder)
    assert len(source) == 120
    assert source.frame_size == (360, 240)
    assert source.read(119).shape == (240, 360, 3)


def test_image_frames_converted_in_place_are_the_converted_copies():
    """An image sequence decodes and converts each frame in place (no second frame allocated):
    the same RGB pixels as OpenCV's BGR decode converted into a copy, on real JPEG frames."""
    folder = shared_sequence_dir("OTB", "Crossing")
    with open_frames(folder) as source:
        for index in (0, 1, 60, -1):
            frame = source.read(index)
            bgr = cv2.imread(str(source.paths[index]), cv2.IMREAD_ANYCOLOR)
            np.testing.assert_array_equal(frame, cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB))
            np.testing.assert_array_equal(source.read_bgr(index), bgr)
            assert frame.flags.c_contiguous and frame.flags.owndata


def _playlist_to_outside_video(tmp_path: Path) -> tuple[Path, Path]:
    """An allowed root holding playlists (HLS, concat) that point at a video outside it."""
    outside, root = tmp_path / "outside", tmp_path / "root"
    outside.mkdir()
    root.mkdir()
    secret = outside / "secret.avi"
    writer = cv2.VideoWriter(str(secret), cv2.VideoWriter_fourcc(*"MJPG"), 10, (64, 48))
    for k in range(5):
        writer.write(np.full((48, 64, 3), 40 * k, np.uint8))
    writer.release()
    playlist = (
        "#EXTM3U\n#EXT-X-VERSION:3\n#EXT-X-TARGETDURATION:1\n"
        f"#EXTINF:1.0,\n{secret}\n#EXT-X-ENDLIST\n"
    )
    for name in ("list.m3u8", "list.txt", "list.mp4"):
        (root / name).write_text(playlist)
    (root / "concat.mp4").write_text(f"ffconcat version 1.0\nfile '{secret}'\n")
    return root, secret


@pytest.mark.parametrize("name", ["list.m3u8", "list.txt", "list.mp4", "concat.mp4"])
def test_a_playlist_cannot_open_a_video_outside_its_folder(tmp_path, name):
    root, secret = _playlist_to_outside_video(tmp_path)
    assert len(open_frames(secret)) == 5  # the video itself is readable
    refusal = "cannot open video" if name.endswith(".mp4") else "not a video file"
    with pytest.raises(InputError, match=refusal):
        open_frames(root / name)


def test_ffmpeg_options_alone_stop_a_playlist(tmp_path, monkeypatch):
    """With the extension check out of the way, the FFmpeg options (file protocol, container
    demuxers) still keep an HLS playlist from opening the video it names: OpenCV really
    reads OPENCV_FFMPEG_CAPTURE_OPTIONS here."""
    from autotrack.io import frames

    root, _secret = _playlist_to_outside_video(tmp_path)
    monkeypatch.setattr(frames, "VIDEO_EXTENSIONS", frames.VIDEO_EXTENSIONS | {".m3u8"})
    capture = frames.open_local_video(root / "list.m3u8")
    try:
        assert not capture.isOpened()
    finally:
        capture.release()
    plain = cv2.VideoCapture(str(root / "list.m3u8"), cv2.CAP_FFMPEG)  # what it guards against
    try:
        assert plain.isOpened() and plain.grab()
    finally:
        plain.release()


def test_a_cut_video_counts_the_frames_it_holds_not_its_header(tmp_path):
    path = tmp_path / "clip.avi"
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 12.0, (64, 48))
    for index in range(40):
        writer.write(np.full((48, 64, 3), 6 * index, np.uint8))
    writer.release()
    whole = path.read_bytes()
    cut = tmp_path / "cut.avi"  # a copy stopped halfway: its header still says 40 frames
    cut.write_bytes(whole[: len(whole) // 2])
    assert int(cv2.VideoCapture(str(cut)).get(cv2.CAP_PROP_FRAME_COUNT)) == 40

    source = open_frames(cut)
    assert 2 < len(source) < 40
    last = source.read(len(source) - 1)  # the last frame counted decodes: playing ends there
    assert float(last.mean()) == pytest.approx(6 * (len(source) - 1), abs=3)
    source.close()


class _ThreadRecordingSequence(ImageSequence):
    """An image sequence that notes which thread read each frame."""

    def __init__(self, paths, name):
        super().__init__(paths, name)
        self.readers: dict[int, str] = {}
        self.threads: dict[int, threading.Thread] = {}

    def read(self, index):
        self.readers[index] = threading.current_thread().name
        self.threads[index] = threading.current_thread()
        return super().read(index)


def test_frame_cache_reads_the_next_image_ahead_in_order(tmp_path):
    """Reading image files in order, each next frame is read on a background thread; the
    frames come back the same and in order; a jump reads on the caller's thread again."""
    written = _write_frames(tmp_path / "seq", 8)
    source = _ThreadRecordingSequence(sorted((tmp_path / "seq").glob("*.png")), "seq")
    cache = FrameCache(source, size=3)
    for index in range(6):
        expected = cv2.cvtColor(written[index], cv2.COLOR_BGR2RGB)
        np.testing.assert_array_equal(cache.read(index), expected)
        # Shared by every caller (and trusted unchanged by a speculating tracker): read only.
        assert not cache.read(index).flags.writeable
    main = threading.current_thread().name
    assert source.readers[0] == source.readers[1] == main
    # The cache's read-ahead threads for the whole run, not one per frame.
    ahead = {source.readers[k] for k in range(2, 6)}
    assert len(ahead) <= frames.READ_AHEAD_THREADS
    assert all(name.startswith("prefetch") for name in ahead)
    np.testing.assert_array_equal(cache.read(0), cv2.cvtColor(written[0], cv2.COLOR_BGR2RGB))
    assert source.readers[0] == main  # the jump back: no longer cached, read here


def test_frame_cache_reads_several_frames_ahead_and_drops_them_on_a_jump(tmp_path):
    written = _write_frames(tmp_path / "seq", 12)
    source = _ThreadRecordingSequence(sorted((tmp_path / "seq").glob("*.png")), "seq")
    depth = frames.READ_AHEAD_FRAMES
    assert depth >= 2
    with contextlib.closing(FrameCache(source, size=2)) as cache:
        cache.read(0)
        cache.read(1)
        for future in list(cache._pending.values()):
            future.result()
        # Frames 2 .. 1 + depth read ahead on the read-ahead thread, none beyond.
        assert sorted(source.readers) == list(range(2 + depth))
        assert all(source.readers[k].startswith("prefetch") for k in range(2, 2 + depth))
        np.testing.assert_array_equal(cache.read(2), cv2.cvtColor(written[2], cv2.COLOR_BGR2RGB))
        for future in list(cache._pending.values()):
            future.result()
        assert source.readers[2 + depth].startswith("prefetch")  # the next one is queued
        jump = 4 + depth
        np.testing.assert_array_equal(
            cache.read(jump), cv2.cvtColor(written[jump], cv2.COLOR_BGR2RGB)
        )
        assert source.readers[jump] == threading.current_thread().name
        assert not cache._pending  # the frames read ahead before the jump are dropped


class _PriorityRecordingSequence(ImageSequence):
    """An image sequence that notes the scheduling niceness of the thread reading each frame."""

    def __init__(self, paths, name):
        super().__init__(paths, name)
        self.niceness: dict[int, int] = {}

    def read(self, index):
        self.niceness[index] = os.getpriority(os.PRIO_PROCESS, threading.get_native_id())
        return super().read(index)


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="per-thread niceness: Linux")
def test_frame_cache_reads_ahead_at_a_low_priority_and_the_caller_keeps_its_own(tmp_path):
    _write_frames(tmp_path / "seq", 4)
    source = _PriorityRecordingSequence(sorted((tmp_path / "seq").glob("*.png")), "seq")
    own = os.getpriority(os.PRIO_PROCESS, threading.get_native_id())
    with contextlib.closing(FrameCache(source, size=2)) as cache:
        for index in range(4):
            cache.read(index)
    assert source.niceness[0] == source.niceness[1] == own  # read by the caller
    assert source.niceness[2] == source.niceness[3] == max(own, frames.READ_AHEAD_NICENESS)
    assert os.getpriority(os.PRIO_PROCESS, threading.get_native_id()) == own


def test_frame_cache_close_stops_its_read_ahead_thread_and_reads_go_on(tmp_path):
    written = _write_frames(tmp_path / "seq", 6)
    source = _ThreadRecordingSequence(sorted((tmp_path / "seq").glob("*.png")), "seq")
    cache = FrameCache(source, size=2)
    for index in range(3):
        cache.read(index)
    cache.close()
    reader = source.threads[3]  # read ahead while the caller had frame 2
    assert reader is not threading.current_thread()
    assert not reader.is_alive()
    for index in (3, 4, 5):  # read again, on the caller's thread from now on
        np.testing.assert_array_equal(
            cache.read(index), cv2.cvtColor(written[index], cv2.COLOR_BGR2RGB)
        )
    assert all(source.threads[k] is threading.current_thread() for k in (3, 4, 5))


def test_frame_cache_reports_a_corrupt_frame_read_ahead_as_the_source_does(tmp_path):
    written = _write_frames(tmp_path / "seq", 6)
    corrupt = tmp_path / "seq" / "0004.png"
    corrupt.write_bytes(b"\x89PNG this is not an image")
    source = _ThreadRecordingSequence(sorted((tmp_path / "seq").glob("*.png")), "seq")
    cache = FrameCache(source, size=3)
    for index in range(3):
        cache.read(index)
    with pytest.raises(InputError) as error:
        cache.read(3)
    assert "frame 3 (0-based; frame 4 counting from 1)" in str(error.value)
    assert str(corrupt) in str(error.value)
    np.testing.assert_array_equal(cache.read(4), cv2.cvtColor(written[4], cv2.COLOR_BGR2RGB))


def test_frame_cache_never_reads_a_video_ahead(tmp_path):
    path = tmp_path / "clip.avi"
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 10, (32, 24))
    for frame in _write_frames(tmp_path / "frames", 4):
        writer.write(frame)
    writer.release()
    with VideoFrames(path) as video:
        cache = FrameCache(video, size=3)
        assert not cache.prefetch
        assert [cache.read(k).shape for k in range(4)] == [(24, 32, 3)] * 4
