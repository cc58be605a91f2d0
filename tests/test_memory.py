"""Bounded memory on long runs: results keep their maps only inside the pipeline's map window,
older maps are read back by frame from the session file (`SessionMaps`), and the app shows an
old frame's maps as recorded."""

from __future__ import annotations

import gc
import json
import os
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest
from mcap.records import Channel, Chunk, Message
from mcap.stream_reader import StreamReader
from mcap.writer import Writer

from autotrack.cli import main
from autotrack.errors import InputError
from autotrack.params import preset
from autotrack.pipeline import Pipeline, Recording
from autotrack.result import TrackResult
from autotrack.sessions import SessionRecorder, open_session
from autotrack.sessions.encoding import encode_json, frame_time_ns
from autotrack.sessions.limits import chunk_records
from autotrack.sessions.maps import SessionMaps
from autotrack.sessions.messages import target_messages
from autotrack.sessions.schemas import MESSAGE_ENCODING, SCHEMA_ENCODING, schema_bytes
from autotrack.synthetic.drift import DriftingTexture, DriftSettings
from autotrack_studio.config import AppConfig
from autotrack_studio.controller import TabController
from autotrack_studio.memory import release_freed_memory
from autotrack_studio.recordings import RecordingRegistry

DEMO = Path(__file__).resolve().parents[1] / "static" / "demo"
FRAMES = 30


def _run(map_window: int, recording: Recording | None = None, targets: int = 2) -> Pipeline:
    frames = DriftingTexture(DriftSettings(frames=FRAMES, period_frames=24))
    run = Pipeline(frames, preset("autotrack"), recording=recording, map_window=map_window)
    for box in frames.boxes(targets):
        run.add_target(0, box, None)
    return run


@pytest.mark.parametrize("window", [0, 1, 6])
def test_results_outside_the_map_window_keep_boxes_and_signals_but_no_maps(window) -> None:
    with _run(FRAMES) as whole, _run(window) as windowed:
        whole.track_to(FRAMES - 1)
        windowed.track_to(FRAMES - 1)
        for target_id, target in windowed.targets.items():
            kept = whole.targets[target_id]
            # Nothing but the maps changes: the same boxes, signals and scalar results.
            assert {k: r.box for k, r in target.results.items()} == {
                k: r.box for k, r in kept.results.items()
            }
            for name, values in target.signals.items():
                np.testing.assert_array_equal(values, kept.signals[name])
            with_maps = sorted(k for k, r in target.results.items() if r.has_maps)
            assert with_maps == list(range(FRAMES - window, FRAMES)), target_id
            assert target.maps_from == FRAMES - window
            for index in with_maps:
                np.testing.assert_array_equal(
                    target.results[index].response_map, kept.results[index].response_map
                )
            assert all(r.has_maps for k, r in kept.results.items() if k > 0)


def test_a_correction_before_the_window_tracks_the_frames_after_it_with_maps() -> None:
    with _run(4, targets=1) as run:
        run.track_to(20)
        target = run.targets["T1"]
        x, y, w, h = target.results[8].box
        run.place_box("T1", 8, (x + 1.0, y, w, h))
        assert target.maps_from == 8 and target.results[8].has_maps
        run.track_to(10)
        assert sorted(k for k, r in target.results.items() if r.has_maps) == [8, 9, 10]
    with pytest.raises(InputError, match="map window"):
        _run(-1)


def _same_map(read: np.ndarray | None, recorded: np.ndarray | None) -> None:
    assert (read is None) == (recorded is None)
    if read is not None:
        np.testing.assert_array_equal(read, recorded)


def test_maps_are_read_back_by_frame_as_last_recorded(tmp_path) -> None:
    recording = Recording(source="drift", directory=tmp_path)
    with _run(3, recording) as run:
        run.track_to(15)
        x, y, w, h = run.targets["T2"].results[12].box
        run.place_box("T2", 12, (x, y + 1.0, w, h))  # re-tracked: the later records win
        originals = {}
        for index in range(13, FRAMES):
            run.advance(index)
            originals[index] = run.targets["T2"].results[index]
        # While the file is being written: read from what has reached it.
        read = run.recorded_maps("T2", 14)
        step = np.ptp(originals[14].response_map) / 255
        np.testing.assert_allclose(read.response, originals[14].response_map, atol=step)
        path = run.session_path
    maps = SessionMaps(path)
    session = open_session(path, load_maps=True)
    for index in (0, 5, 12, 13, 14, 20, FRAMES - 1):
        got = maps.frame_maps("T2", index)
        _same_map(got.response, session.response_maps["T2"].get(index))
        _same_map(got.local_variation, session.local_variation_maps["T2"].get(index))
    # The corrected frame is a fresh start: no response, no variation, as recorded last.
    corrected = maps.frame_maps("T2", 12)
    assert corrected.response is None and corrected.local_variation is None
    for index in (14, 20):
        expected = np.log10(originals[index].spatial_window)
        got = np.log10(maps.frame_maps("T2", index).spatial_window)
        np.testing.assert_allclose(got, expected, atol=0.5 * np.ptp(expected) / 255 + 1e-5)


def test_a_frame_is_read_from_its_own_chunk_not_by_scanning_the_file(tmp_path) -> None:
    rng = np.random.default_rng(3)
    params = preset("autotrack")
    written = {}
    with SessionRecorder(tmp_path / "s.mcap", source="s", tracker_params=params) as recorder:
        for index in range(40):
            values = written[index] = rng.random((9, 9)).astype(np.float32)
            result = TrackResult(
                frame_index=index,
                box=(1.0, 2.0, 3.0, 4.0),
                peak_score=1.0,
                response_map=values,
                local_variation=values * 2,
                global_variation=0.1,
                theta_ref=0.1,
                theta=0.1,
                aberrant=False,
                scale_factor=1.0,
                search_box=(0.0, 0.0, 9.0, 9.0),
                spatial_window=values + 1.0,
            )
            recorder.log_target("T1", result)
            recorder.flush()  # one chunk per frame
    maps = SessionMaps(tmp_path / "s.mcap")
    got = maps.frame_maps("T1", 33)
    assert maps.chunks_decoded <= 2  # the chunk naming the channels, and frame 33's
    values = written[33]
    np.testing.assert_allclose(got.response, values, atol=0.5 * np.ptp(values) / 255 + 1e-6)
    np.testing.assert_allclose(got.local_variation, 2 * values, atol=np.ptp(values) / 255 + 1e-6)
    assert np.abs(np.log10(got.spatial_window) - np.log10(values + 1.0)).max() < 0.3 / 255 + 1e-6


def test_the_app_shows_a_frame_behind_the_window_with_its_recorded_maps(tmp_path) -> None:
    if not (DEMO / "img").is_dir():
        pytest.skip("static/demo is missing (generated by `autotrack synth`, see its README)")
    config = AppConfig(sessions_dir=tmp_path / "sessions", demo_dir=DEMO, tracker_threads=1)
    controller = TabController(config, config.browsable_roots(), RecordingRegistry(), 1)
    controller.open_initial()
    try:
        run = controller.run
        run.map_window = 3
        controller.load_boxes_json()
        controller.seek(6)
        live = controller.snapshot()  # frame 6 with its maps in memory
        controller.seek(14)
        assert all(t.maps_from == 12 for t in run.targets.values())
        controller.seek(6)  # behind the window now
        assert not any(t.results[6].has_maps for t in run.targets.values())
        view = controller.snapshot()
        run.flush()
        session = open_session(run.session_path, load_maps=True)
    finally:
        controller.close()
    assert set(view.drawings) == set(live.drawings) == {"T1", "T2", "T3", "T4"}
    for target_id, drawing in view.drawings.items():
        before = live.drawings[target_id]
        assert drawing.box == before.box and drawing.weights_frame == before.weights_frame
        # The maps shown are the recorded ones, the previous frame's response too ...
        recorded = session.response_maps[target_id]
        np.testing.assert_array_equal(drawing.result.response_map, recorded[6])
        np.testing.assert_array_equal(drawing.previous_response, recorded[5])
        np.testing.assert_array_equal(
            drawing.result.local_variation, session.local_variation_maps[target_id][6]
        )
        # ... which are the maps shown live, to within the recording's mono8 steps.
        for shown, held in (
            (drawing.result.response_map, before.result.response_map),
            (drawing.result.local_variation, before.result.local_variation),
        ):
            np.testing.assert_allclose(shown, held, atol=0.5 * np.ptp(held) / 255 + 1e-6)
        shown, held = np.log10(drawing.weights), np.log10(before.weights)
        np.testing.assert_allclose(shown, held, atol=0.5 * np.ptp(held) / 255 + 1e-5)


def _python_objects() -> tuple[int, int]:
    """(objects the garbage collector tracks, blocks the interpreter has allocated), after a
    collection."""
    gc.collect()
    return len(gc.get_objects()), sys.getallocatedblocks()


def _rss_bytes() -> int:
    with open("/proc/self/statm") as handle:
        return int(handle.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")


SOAK_FRAMES = 3000
SOAK_EVERY = 100


@pytest.mark.slow
def test_memory_stays_flat_over_3000_frames_with_four_targets_in_the_app(tmp_path) -> None:
    """The app's controller steps a 3,000-frame sequence with four targets, recording it; RSS,
    sampled every 100 frames, stays flat once the first map windows are full, well below what
    keeping every map would add; an evicted frame still shows its recorded maps; closing the
    tab gives the window's memory back."""
    source = DriftingTexture(DriftSettings(frames=SOAK_FRAMES))
    images = tmp_path / "drift"
    images.mkdir()
    for index in range(SOAK_FRAMES):
        cv2.imwrite(str(images / f"{index + 1:05d}.jpg"), source.read_bgr(index))
    config = AppConfig(sessions_dir=tmp_path / "sessions")  # the served default concurrency
    controller = TabController(config, (tmp_path,), RecordingRegistry(), 1)
    controller.open(images, None)
    run = controller.run
    for box in source.boxes(4):
        controller.place_box(box)
    samples: dict[int, int] = {}
    settled = 2 * run.map_window  # the window full, and the allocator at its working size
    for frame_index in range(1, SOAK_FRAMES):
        controller.step(1)
        if frame_index % 10 == 0:
            controller.snapshot()  # what the display thread is handed
        if frame_index % SOAK_EVERY == 0:
            samples[frame_index] = _rss_bytes()
        if frame_index == settled:
            settled_objects = _python_objects()
    assert run.tracked_until == SOAK_FRAMES - 1
    # Nothing is kept as a Python object per frame: a TrackResult per target and frame would
    # add >= 4 objects and ~60 blocks per frame; the run adds ~4 blocks (measured), no object.
    objects, blocks = (
        now - then for now, then in zip(_python_objects(), settled_objects, strict=True)
    )
    frames = SOAK_FRAMES - 1 - settled
    assert objects < frames / 4 and blocks < 16 * frames, (objects / frames, blocks / frames)
    # What keeping every map would add per frame: the newest results' maps, all targets.
    newest = [t.results[SOAK_FRAMES - 1] for t in run.targets.values()]
    per_frame = sum(
        m.nbytes for r in newest for m in (r.response_map, r.local_variation, r.spatial_window)
    )
    unbounded = per_frame * (SOAK_FRAMES - 1 - settled)
    growth = max(rss for frame, rss in samples.items() if frame >= settled) - samples[settled]
    assert unbounded > 100e6  # the test can tell: every map kept would add this much
    assert growth < unbounded / 10, (growth / 1e6, unbounded / 1e6, samples)

    controller.seek(40)  # far behind the window: its maps come from the recording
    view = controller.snapshot()
    recorded = SessionMaps(run.session_path)
    for target_id, drawing in view.drawings.items():
        maps = recorded.frame_maps(target_id, 40)
        np.testing.assert_array_equal(drawing.result.response_map, maps.response)
        np.testing.assert_array_equal(drawing.result.local_variation, maps.local_variation)
    window_bytes = per_frame * run.map_window
    del run, view, newest, drawing
    before = _rss_bytes()
    controller.close()
    assert release_freed_memory()
    assert before - _rss_bytes() > window_bytes / 2, (before / 1e6, _rss_bytes() / 1e6)


def _write_tiny_session(path: Path, messages: list, close_chunk_before: str) -> None:
    """(log time, topic, payload) messages, each channel registered before its first one (as
    the recorder does), one chunk per log time; the chunk open when `close_chunk_before`'s
    channel is registered is closed right after that Channel record, before its message."""
    channels: dict[str, int] = {}
    with open(path, "wb") as handle:
        writer = Writer(handle)
        writer.start()
        last_time = None
        for time_ns, topic, payload in messages:
            if time_ns != last_time:
                writer.flush()
                last_time = time_ns
            if topic.name not in channels:
                schema = schema_bytes(topic.schema)
                schema_id = writer.register_schema(topic.schema, SCHEMA_ENCODING, schema)
                channels[topic.name] = writer.register_channel(
                    topic.name, MESSAGE_ENCODING, schema_id
                )
                if topic.name == close_chunk_before:
                    writer.flush()
            writer.add_message(channels[topic.name], time_ns, encode_json(payload), 0)
        writer.finish()


def _channel_before_its_message(path: Path, topic_name: str) -> bool:
    """Whether the file's Channel record for `topic_name` closes a chunk, before its message,
    whose other messages are on channels of earlier chunks."""
    chunks: list[list] = []
    with open(path, "rb") as handle:
        for record in StreamReader(handle, emit_chunks=True).records:
            if isinstance(record, Chunk):
                chunks.append(chunk_records(record))
    for index, records in enumerate(chunks):
        channels = [r for r in records if isinstance(r, Channel)]
        ids = {r.id for r in channels if r.topic == topic_name}
        if ids and not any(isinstance(r, Message) and r.channel_id in ids for r in records):
            return len(channels) == 1 and index + 1 < len(chunks)
    return False


def test_a_channel_recorded_in_the_chunk_before_its_first_message_is_found(tmp_path) -> None:
    """mcap closes a chunk that a Channel record filled, before the channel's first message:
    the index looks for the channel in the chunk before too (once), and reads the maps."""
    values = np.linspace(0.0, 1.0, 36, dtype=np.float32).reshape(6, 6)
    box, search = (1.0, 2.0, 3.0, 4.0), (0.0, 0.0, 6.0, 6.0)
    messages = []
    for frame_index in range(12):  # maps on frame 11 only: their channel comes last
        response = values if frame_index == 11 else None
        result = TrackResult(
            frame_index, box, 1.0, response, None, 0.1, 0.1, 0.1, False, 1.0, search
        )
        time_ns = frame_time_ns(frame_index, 10.0)
        batch = target_messages(
            time_ns, "T1", result, landmark_id=None, record_maps=True, rgba=(1.0, 0.0, 0.0, 1.0)
        )
        messages += [(time_ns, topic, payload) for topic, payload in batch]
    path = tmp_path / "tiny.mcap"
    _write_tiny_session(path, messages, "/targets/T1/response")
    assert _channel_before_its_message(path, "/targets/T1/response")
    maps = SessionMaps(path)
    got = maps.frame_maps("T1", 11)
    np.testing.assert_allclose(got.response, values, atol=0.5 / 255 + 1e-6)
    assert got.local_variation is None and got.spatial_window is None


def test_localize_and_track_keep_no_maps(tmp_path, monkeypatch) -> None:
    """`autotrack localize` and `track` report boxes and poses only: their pipelines keep no
    map of any frame, the last one included."""
    if not (DEMO / "img").is_dir():
        pytest.skip("static/demo is missing (generated by `autotrack synth`, see its README)")
    import autotrack.pipeline.localize as localize_module

    made: list[Pipeline] = []

    class Watched(Pipeline):
        def __init__(self, *args, **kwargs) -> None:
            super().__init__(*args, **kwargs)
            made.append(self)

    monkeypatch.setattr(localize_module, "Pipeline", Watched)
    monkeypatch.setattr("autotrack.pipeline.Pipeline", Watched)
    frames = tmp_path / "short"
    frames.mkdir()
    for path in sorted((DEMO / "img").iterdir())[:12]:
        (frames / path.name).write_bytes(path.read_bytes())
    for name in ("scene.json", "boxes.json"):
        (frames / name).write_bytes((DEMO / name).read_bytes())
    assert main(["localize", str(frames), "--quiet"]) == 0
    box = ",".join(str(v + 1 if i < 2 else v) for i, v in enumerate(_demo_box()))
    assert main(["track", str(frames), "--init", box, "--quiet"]) == 0
    assert len(made) == 2
    for run in made:
        results = [r for t in run.targets.values() for r in t.results.values()]
        assert len(results) >= 12 and not any(r.has_maps for r in results)


def _demo_box() -> tuple[float, ...]:
    return tuple(json.loads((DEMO / "boxes.json").read_text())["A"])


ARENA_PROBE = """
import ctypes, ctypes.util, sys, threading
import numpy as np
from autotrack_studio.memory import limit_malloc_arenas

if sys.argv[1] == "capped":
    assert limit_malloc_arenas(2)
start = threading.Barrier(8)

def allocate():
    start.wait()
    blocks = [np.ones(1000) for _ in range(200)]  # 8 kB each: glibc's heap, not mmap
    del blocks

threads = [threading.Thread(target=allocate) for _ in range(8)]
for thread in threads:
    thread.start()
for thread in threads:
    thread.join()
libc = ctypes.CDLL(ctypes.util.find_library("c"))
libc.open_memstream.restype = ctypes.c_void_p
libc.malloc_info.argtypes = [ctypes.c_int, ctypes.c_void_p]
libc.fclose.argtypes = [ctypes.c_void_p]
text, size = ctypes.c_char_p(), ctypes.c_size_t()
stream = libc.open_memstream(ctypes.byref(text), ctypes.byref(size))
libc.malloc_info(0, stream)
libc.fclose(stream)
print(text.value.decode().count("<heap nr="))
"""


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="glibc's malloc arenas")
def test_the_servers_arena_cap_keeps_its_threads_on_two_heaps() -> None:
    """Eight threads allocating at once each get a heap of their own under glibc's default;
    after `limit_malloc_arenas(2)` (what `autotrack app` calls before its server starts) they
    share two, so freed pages are not scattered over a heap per thread (issue 42's churn)."""
    env = {key: value for key, value in os.environ.items() if key != "MALLOC_ARENA_MAX"}

    def heaps(mode: str) -> int:
        probe = [sys.executable, "-c", ARENA_PROBE, mode]
        return int(subprocess.run(probe, env=env, capture_output=True, check=True).stdout)

    assert heaps("capped") <= 2
    assert heaps("default") > 2
