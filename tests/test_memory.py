"""Bounded memory on long runs: results keep their maps only inside the pipeline's map window,
older maps are read back by frame from the session file (`SessionMaps`), and the app shows an
old frame's maps as recorded."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from app.config import AppConfig
from app.controller import TabController
from app.recordings import RecordingRegistry
from autotrack.errors import InputError
from autotrack.params import preset
from autotrack.pipeline import Pipeline, Recording
from autotrack.result import TrackResult
from autotrack.sessions import SessionRecorder, open_session
from autotrack.sessions.maps import SessionMaps
from autotrack.synthetic.drift import DriftingTexture, DriftSettings

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
    assert maps.chunks_indexed == 40
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
