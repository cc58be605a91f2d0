"""The viser app without a browser: paths, uploads, canvas mapping, and a tab driven through its
widgets (load the demo, draw boxes by rect-select events, play, correct, export, reopen).

The per-tab controller, the worker, the exports, the client channel and the CLI are tested
directly in test_app_controller.py."""

from __future__ import annotations

import io
import json
import socket
import stat
import time
import zipfile
from pathlib import Path

import cv2
import numpy as np
import pytest
import viser

from autotrack.errors import InputError
from autotrack.result import TrackResult
from autotrack_studio.canvas import (
    TargetDrawing,
    colour_map,
    draw_overlays,
    fit_letterbox,
    letterbox_image,
    peak_position,
)
from autotrack_studio.config import AppConfig
from autotrack_studio.panels import CANVAS_3D
from autotrack_studio.paths import (
    UploadLimits,
    extract_image_zip,
    find_sequences,
    resolve_user_path,
    store_upload,
)

REPO = Path(__file__).resolve().parents[1]
SHARED_SEQUENCES = REPO / ".." / "shared" / "data" / "sequences"


def _jpeg(seed: int, size: tuple[int, int] = (48, 32)) -> bytes:
    rng = np.random.default_rng(seed)
    image = rng.integers(0, 255, (size[1], size[0], 3), dtype=np.uint8)
    ok, encoded = cv2.imencode(".jpg", image)
    assert ok
    return encoded.tobytes()


def _zip(members: dict[str, bytes], symlinks: tuple[str, ...] = ()) -> bytes:
    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w") as archive:
        for name, content in members.items():
            archive.writestr(name, content)
        for name in symlinks:
            info = zipfile.ZipInfo(name)
            info.external_attr = (stat.S_IFLNK | 0o777) << 16
            archive.writestr(info, "/etc/passwd")
    return buffer.getvalue()


# -- paths and uploads --------------------------------------------------------------------------


def test_typed_path_must_stay_under_allowed_roots(tmp_path: Path) -> None:
    root = tmp_path / "root"
    (root / "seq" / "img").mkdir(parents=True)
    outside = tmp_path / "outside"
    outside.mkdir()
    (root / "escape").symlink_to(outside)
    roots = (root.resolve(),)

    assert resolve_user_path("seq", roots) == (root / "seq").resolve()
    assert resolve_user_path(str(root / "seq"), roots) == (root / "seq").resolve()
    refused = "no such file or folder among those this server may open.*--allow-root DIR"
    for typed in (
        str(outside),
        "seq/../../outside",
        "escape",  # a symlink leading out counts as outside
        "missing",
        "~",  # no home-folder expansion
        str(tmp_path / "not-there"),
    ):
        # Existing and missing paths outside the roots read alike: no probing the disk.
        with pytest.raises(InputError, match=refused):
            resolve_user_path(typed, roots)


def test_sequence_list_finds_benchmark_folders_image_folders_and_videos(tmp_path: Path) -> None:
    (tmp_path / "bench" / "seqA" / "img").mkdir(parents=True)
    (tmp_path / "bench" / "seqA" / "img" / "0001.jpg").write_bytes(_jpeg(1))
    (tmp_path / "frames").mkdir()
    (tmp_path / "frames" / "a.png").write_bytes(b"x")
    (tmp_path / "clips").mkdir()
    (tmp_path / "clips" / "flight.mp4").write_bytes(b"x")
    (tmp_path / "empty").mkdir()

    found = find_sequences((tmp_path,))

    assert found == [
        tmp_path / "bench" / "seqA",
        tmp_path / "clips" / "flight.mp4",
        tmp_path / "frames",
    ]


def test_shared_sequences_are_listed() -> None:
    if not SHARED_SEQUENCES.is_dir():
        pytest.skip("../shared/data/sequences is not present")
    found = find_sequences((SHARED_SEQUENCES.resolve(),))
    names = {path.name for path in found}
    assert {"boat5", "Crossing", "S1301", "bag"} <= names


def test_zip_upload_is_unpacked_in_name_order_with_safe_names(tmp_path: Path) -> None:
    content = _zip(
        {
            "flight/frame_0002.jpg": _jpeg(2),
            "flight/frame_0001.jpg": _jpeg(1),
            "flight/notes.txt": b"ignored",
            "__MACOSX/flight/._frame_0001.jpg": b"junk",
        }
    )
    folder = store_upload("my flight.zip", content, tmp_path / "uploads", UploadLimits())

    images = sorted((folder / "img").iterdir())
    assert [path.name for path in images] == ["000001.jpg", "000002.jpg"]
    assert images[0].read_bytes() == _jpeg(1)
    assert folder.parent == tmp_path / "uploads"


@pytest.mark.parametrize(
    ("members", "symlinks", "message"),
    [
        ({"../evil.jpg": b"x"}, (), "leaving the archive"),
        ({"/abs/evil.jpg": b"x"}, (), "absolute path"),
        ({"ok.jpg": b"x"}, ("link.jpg",), "symbolic link"),
        ({"readme.txt": b"x"}, (), "no images"),
    ],
)
def test_unsafe_or_empty_zips_are_refused_before_writing(
    tmp_path: Path, members: dict[str, bytes], symlinks: tuple[str, ...], message: str
) -> None:
    destination = tmp_path / "dest"
    destination.mkdir()
    with pytest.raises(InputError, match=message):
        extract_image_zip(_zip(members, symlinks), destination, UploadLimits())
    assert list(destination.iterdir()) == []


def test_upload_limits_on_size_count_and_unpacked_bytes(tmp_path: Path) -> None:
    many = _zip({f"{i:03d}.jpg": _jpeg(i) for i in range(5)})
    with pytest.raises(InputError, match="limit is 4"):
        store_upload("a.zip", many, tmp_path, UploadLimits(max_members=4))
    with pytest.raises(InputError, match="the upload is"):
        store_upload("a.zip", many, tmp_path, UploadLimits(max_upload_bytes=100))
    bomb = _zip({"big.png": bytes(200_000)})
    with pytest.raises(InputError, match="unpacks to"):
        store_upload("a.zip", bomb, tmp_path, UploadLimits(max_extracted_bytes=100_000))
    with pytest.raises(InputError, match="upload a video"):
        store_upload("script.sh", b"rm -rf /", tmp_path, UploadLimits())


def test_video_upload_keeps_a_sanitised_name(tmp_path: Path) -> None:
    target = store_upload("../../a b;rm.mp4", b"data", tmp_path, UploadLimits())
    assert target.name == "a_b_rm.mp4"
    assert target.parent.parent == tmp_path
    assert target.read_bytes() == b"data"


# -- canvas mapping and overlays ----------------------------------------------------------------


@pytest.mark.parametrize("canvas", [(1600, 700), (900, 1000), (1280, 720), (333, 517)])
def test_rect_select_maps_back_to_frame_pixels(canvas: tuple[int, int]) -> None:
    letterbox = fit_letterbox((1280, 720), canvas)
    box = (100.0, 50.0, 300.0, 200.0)
    corner_a = letterbox.frame_to_screen(box[0], box[1])
    corner_b = letterbox.frame_to_screen(box[0] + box[2], box[1] + box[3])

    mapped = letterbox.rect_to_box(corner_b, corner_a)  # drag direction does not matter

    assert mapped is not None
    np.testing.assert_allclose(mapped, box, atol=1e-6)
    # The padded image has the canvas's aspect to within one pixel of rounding.
    assert abs(letterbox.padded_width / letterbox.padded_height - canvas[0] / canvas[1]) < (
        1.0 / min(letterbox.padded_height, letterbox.padded_width) * 2
    )


def test_letterboxed_image_puts_the_frame_where_the_mapping_says() -> None:
    frame = np.zeros((72, 128, 3), np.uint8)
    frame[10:20, 30:50] = 255
    letterbox = fit_letterbox((128, 72), (400, 400))
    image = letterbox_image(frame, letterbox, max_width=10_000)

    assert image.shape[:2] == (letterbox.padded_height, letterbox.padded_width)
    rows, cols = np.nonzero(image[:, :, 0])
    u0, v0 = cols.min() / image.shape[1], rows.min() / image.shape[0]
    assert letterbox.screen_to_frame(u0, v0) == pytest.approx((30.0, 10.0))


def test_drags_off_the_frame_are_clipped_or_rejected() -> None:
    letterbox = fit_letterbox((1280, 720), (1280, 1280))
    assert letterbox.rect_to_box((0.0, 0.0), (1.0, 0.05)) is None  # only the black bar
    clipped = letterbox.rect_to_box((0.0, 0.0), (0.5, 0.5))
    assert clipped is not None
    assert clipped[0] == 0.0 and clipped[1] == 0.0


def _result(map_values: np.ndarray) -> TrackResult:
    return TrackResult(
        frame_index=3,
        box=(40.0, 30.0, 20.0, 10.0),
        peak_score=0.8,
        response_map=map_values,
        local_variation=map_values * 0.5,
        global_variation=0.1,
        theta_ref=13.0,
        theta=12.0,
        aberrant=True,
        scale_factor=1.0,
        search_box=(20.0, 15.0, 50.0, 50.0),
    )


def test_overlay_draws_the_map_inside_the_search_region_only() -> None:
    values = np.zeros((25, 25), np.float32)
    values[5, 20] = 1.0
    result = _result(values)
    frame = np.full((120, 640, 3), 128, np.uint8)
    drawing = TargetDrawing(label="T1", colour=(255, 0, 0), box=result.box, result=result)

    plain = draw_overlays(frame, [drawing], "none")
    mapped = draw_overlays(frame, [drawing], "response")

    changed = np.any(mapped != plain, axis=2)
    assert changed[:40, 420:].any()  # the colour scale's legend, top right
    changed[:40, 420:] = False
    rows, cols = np.nonzero(changed)
    assert rows.min() >= 15 and rows.max() < 65 and cols.min() >= 20 and cols.max() < 70
    assert np.array_equal(frame, np.full((120, 640, 3), 128, np.uint8))  # input untouched
    # The peak lies in cell (5, 20) of a 50-px search region on a 25-cell map.
    assert peak_position(result) == pytest.approx((20.0 + 20.5 * 2.0, 15.0 + 5.5 * 2.0))


def test_local_variation_can_be_drawn_over_the_target_region_only() -> None:
    rng = np.random.default_rng(1)
    result = _result(rng.uniform(0.1, 1.0, (25, 25)).astype(np.float32))
    frame = np.full((120, 160, 3), 128, np.uint8)
    drawing = TargetDrawing(label="T1", colour=(255, 0, 0), box=result.box, result=result)
    plain = draw_overlays(frame, [drawing], "none")
    whole = draw_overlays(frame, [drawing], "local_variation")
    target = draw_overlays(frame, [drawing], "local_variation_target")

    def changed(image: np.ndarray) -> np.ndarray:
        return np.any(image != plain, axis=2)[30:, :]  # below the legend strip

    rows, cols = np.nonzero(changed(target))
    # the box (40, 30, 20, 10) in whole 2-px cells, the outline drawn around it
    assert rows.min() + 30 >= 29 and rows.max() + 30 <= 41 and cols.min() >= 39 and cols.max() <= 61
    assert changed(whole).sum() > 4 * changed(target).sum()  # the whole search region
    assert np.any(whole[:26] != plain[:26])  # the colour-scale legend, top right


def test_colour_map_spans_the_jet_range() -> None:
    image = colour_map(np.linspace(0, 1, 256, dtype=np.float32).reshape(16, 16))
    assert image.shape == (16, 16, 3)
    assert tuple(image[0, 0]) != tuple(image[-1, -1])
    assert image[-1, -1, 0] > image[-1, -1, 2]  # hot end is red (RGB)


def test_chart_range_fits_the_values_shown() -> None:
    from autotrack_studio.plots import y_range

    low, high = y_range([np.array([np.nan, 0.02, 0.1]), np.array([np.nan, np.nan])])
    assert 0.0 <= low <= 0.02 and 0.1 <= high <= 0.12  # peaks of 0.02-0.1 fill the chart
    assert y_range([np.array([2.0, 3.0])])[0] > 1.0  # shrinks and moves with the data
    assert y_range([np.array([np.nan])]) == (0.0, 1.0)  # nothing finite yet


def test_the_eta_chart_is_logarithmic_and_always_holds_phi() -> None:
    from autotrack_studio.plots import log_range

    low, high = log_range([np.array([0.01, 0.05, 370.0, np.inf, np.nan, 0.0])], 0.3)
    assert (low, high) == (0.01, 1000.0)  # whole decades; inf and 0 left out
    assert log_range([np.array([0.01, 0.02])], 0.3) == (0.01, 1.0)  # phi above the data
    assert log_range([np.array([np.nan])], 0.3) == (0.1, 1.0)


def test_a_flat_signal_gets_a_range_around_its_value() -> None:
    from autotrack_studio.plots import y_range

    for value in (12.9, -3.0, 1e-4):  # e.g. theta while nothing changes
        low, high = y_range([np.full(30, value), np.array([np.nan])])
        assert low < value < high and high - low >= 0.2 * abs(value), (value, low, high)
    low, high = y_range([np.zeros(30)])
    assert low <= -1.0 and high >= 1.0  # not +-1e-7, whose ticks all read "0"


def test_the_eta_axis_labels_one_decade_per_grid_line() -> None:
    from autotrack_studio.plots import decade_axis

    axis = decade_axis((1e-3, 1e3))
    assert axis["splits"] == (1e-3, 1e-2, 0.1, 1.0, 10.0, 100.0, 1e3)
    assert axis["values"] == ("1e-3", "1e-2", "0.1", "1", "10", "100", "1e3")
    assert decade_axis((0.1, 1.0))["values"] == ("0.1", "1")


def test_frames_without_a_value_reach_the_chart_as_gaps() -> None:
    from autotrack_studio.plots import chart_data

    fps = np.array([np.nan, 20.0, 21.0, np.nan, np.nan, 19.0])  # two dropped frames
    x, values, line = chart_data(6, [fps], 5, (0.0, 30.0))
    assert values[:6] == [None, 20.0, 21.0, None, None, 19.0]  # null: uPlot breaks the line
    assert len(x) == len(values) == len(line) and line.count(None) == 6


def test_the_cursor_line_stands_at_the_current_frame() -> None:
    from autotrack_studio.plots import CURSOR_OFFSETS, with_cursor

    x, values, line = with_cursor(5, [np.arange(5, dtype=float) * 10], 2, (-1.0, 7.0))
    assert np.all(np.diff(x) > 0) and len(x) == 5 + len(CURSOR_OFFSETS)
    at = np.flatnonzero(np.isfinite(line))
    np.testing.assert_allclose(x[at], 3 + np.array(CURSOR_OFFSETS))  # frame 3, 1-based
    np.testing.assert_array_equal(line[at], [-1.0, 7.0])
    np.testing.assert_array_equal(values[at], [20.0, 20.0])  # the series do not break there
    np.testing.assert_array_equal(values[np.isin(x, np.arange(1, 6))], np.arange(5) * 10.0)


def test_the_cursor_line_stays_in_the_x_range_on_the_last_frame() -> None:
    from autotrack_studio.plots import CURSOR_OFFSETS, chart_data, x_range

    for last, count in ((59, 60), (10, 60), (0, 1), (120, 121)):
        x, _values, line = chart_data(last + 1, [np.zeros(last + 1)], last, (0.0, 1.0))
        low, high = x_range(last, count)
        drawn = [at for at, value in zip(x, line, strict=True) if value is not None]
        assert len(drawn) == len(CURSOR_OFFSETS) and low <= min(drawn) and max(drawn) <= high
    assert x_range(10, 60) == (1.0, 50.0) and x_range(59, 60)[1] < 60.01
    assert x_range(49, 200) == (1.0, 100.0)  # frame 50 is shown with the cursor after it


def test_local_variation_colour_scale_ignores_a_few_extreme_values() -> None:
    from autotrack_studio.canvas import colour_map, map_tile, robust_limits

    rng = np.random.default_rng(0)
    variation = rng.uniform(0.0, 1.0, (40, 40)).astype(np.float32)
    variation[3, 4], variation[10, 10] = 1e6, np.inf  # divisions by a near-zero response
    low, high = robust_limits(variation)
    assert 0.0 <= low < 0.05 and 0.95 < high <= 1.0
    spread = colour_map(variation, (low, high)).reshape(-1, 3)
    assert len(np.unique(spread, axis=0)) > 50  # not one hot pixel on a flat blue
    tile = map_tile(variation, "local variation", "robust")
    assert tile.shape == (18 + 160 + 26, 160, 3)


def test_trajectory_has_a_gap_where_poses_are_missing() -> None:
    from autotrack_studio.view3d import segments_with_gaps

    positions = np.arange(15, dtype=float).reshape(5, 3)
    segments = segments_with_gaps([0, 1, 2, 4, 5], positions)
    assert segments.shape == (3, 2, 3)
    np.testing.assert_array_equal(segments[2], [positions[3], positions[4]])  # frames 4-5


def test_ground_truth_is_drawn_dashed_so_the_estimate_on_it_shows() -> None:
    from autotrack_studio.view3d import GT_DASH, dashes, segments_with_gaps

    positions = np.arange(30, dtype=float).reshape(10, 3)
    drawn = dashes(segments_with_gaps(range(10), positions), *GT_DASH)
    assert 0 < GT_DASH[0] < GT_DASH[1]
    starts = [int(segment[0, 0]) // 3 for segment in drawn]  # the frame each segment leaves
    assert starts == [i for i in range(9) if i % GT_DASH[1] < GT_DASH[0]]


# -- a tab driven through its widgets -----------------------------------------------------------

DEMO = REPO / "static" / "demo"


class RecordingChannel:
    """Stands in for a browser: records notifications and downloads, reports a canvas size."""

    def __init__(self, canvas: tuple[int, int] = (1000, 700)) -> None:
        self.canvas = canvas
        self.notes: list[tuple[str, bool]] = []
        self.downloads: list[tuple[str, bytes]] = []
        self.camera_moves = 0

    def notify(self, title: str, body: str, *, error: bool = False) -> None:
        self.notes.append((body, error))

    def download(self, file_name: str, content: bytes) -> None:
        self.downloads.append((file_name, content))

    def canvas_size(self) -> tuple[int, int]:
        return self.canvas

    def on_canvas_change(self, callback) -> None:
        self.changed = callback

    def field_of_view(self) -> float:
        return np.radians(50.0)

    def look_at(self, position, target, up) -> None:
        self.camera_moves += 1


def _free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


@pytest.fixture
def studio(tmp_path: Path):
    if not (DEMO / "img").is_dir():
        pytest.skip("static/demo is missing (generated by `autotrack synth`, see its README)")
    from autotrack_studio.server import StudioServer

    config = AppConfig(
        port=_free_port(),
        sessions_dir=tmp_path / "sessions",
        allowed_roots=(tmp_path / "sessions",),
        demo_dir=DEMO,
        tracker_threads=1,
    )
    (tmp_path / "sessions").mkdir()
    server = StudioServer(config)
    yield server
    server.stop()


def _open_tab(
    studio, tab_id: int = 1, channel: RecordingChannel | None = None, browser: str = "alice"
):
    """A tab of `browser` (by default every test tab is one user's: tabs of one browser)."""
    channel = channel or RecordingChannel()
    tab = studio.open_tab(
        channel, studio.viser.gui, studio.viser.scene, tab_id=tab_id, browser_id=browser
    )
    assert tab.wait_idle()
    return tab, channel


def _wait_for(predicate, timeout: float = 120.0) -> None:
    deadline = time.monotonic() + timeout
    while not predicate():
        assert time.monotonic() < deadline, "condition not reached"
        time.sleep(0.02)


def _drag(tab, box) -> None:
    """A shift-drag over `box` (frame pixels) as the browser reports it."""
    size = tab.controller.frame_size
    _wait_for(
        lambda: (
            tab.display.letterbox is not None
            and (tab.display.letterbox.frame_width, tab.display.letterbox.frame_height) == size
        )
    )
    x, y, w, h = box
    letterbox = tab.display.letterbox
    tab.rect_selected(
        viser.SceneRectSelectEvent(
            client=None,
            client_id=0,
            screen_min=letterbox.frame_to_screen(x, y),
            screen_max=letterbox.frame_to_screen(x + w, y + h),
            modifier="shift",
        )
    )
    assert tab.wait_idle()


def _demo_boxes() -> dict[str, list[float]]:
    return json.loads((DEMO / "boxes.json").read_text())


def _draw_demo_boxes(tab) -> dict[str, list[float]]:
    boxes = _demo_boxes()
    for landmark_id in tab.controller.run.scene.landmark_ids:
        _drag(tab, boxes[landmark_id])
    return boxes


def _click(button) -> None:
    button.value = True


def _set(widget, value) -> None:
    widget.value = value


def test_demo_opens_with_its_scene_and_boxes_file(studio) -> None:
    tab, channel = _open_tab(studio)

    run = tab.controller.run
    assert run is not None and run.frame_count == len(list((DEMO / "img").iterdir()))
    assert len(run.scene.landmarks) == 4
    assert tab.panels.targets.boxes_json.visible
    assert any(name.endswith("demo") for name in tab.panels.sequence.dropdown.options)
    assert run.session_path is None  # nothing recorded before the first box
    assert channel.camera_moves >= 1
    assert tab.panels.playback.frame.max == run.frame_count


def test_four_drags_make_four_targets_tied_to_the_landmarks(studio) -> None:
    tab, _ = _open_tab(studio)
    boxes = _draw_demo_boxes(tab)

    run = tab.controller.run
    assert list(run.targets) == ["T1", "T2", "T3", "T4"]
    assert [t.landmark_id for t in run.targets.values()] == list(run.scene.landmark_ids)
    for target in run.targets.values():
        np.testing.assert_allclose(target.results[0].box, boxes[target.landmark_id], atol=2.0)
    assert run.poses[0].valid  # four boxes on frame 1 give a pose already
    session = run.session_path
    assert session is not None and studio.recordings.writer_of(session) == tab.tab_id
    assert session.name in tab.panels.session.recording.content
    assert "| T4 " in tab.panels.targets.table.content


def test_boxes_json_button_places_the_demo_boxes(studio) -> None:
    tab, _ = _open_tab(studio)
    _click(tab.panels.targets.boxes_json)
    assert tab.wait_idle()

    run = tab.controller.run
    boxes = _demo_boxes()
    assert sorted(t.landmark_id for t in run.targets.values()) == sorted(boxes)
    for target in run.targets.values():
        np.testing.assert_allclose(target.results[0].box, boxes[target.landmark_id], atol=2.0)
    assert run.poses[0].valid
    # A second press would stack a target per landmark: greyed, the button says so.
    button = tab.panels.targets.boxes_json
    assert button.disabled and button.label == "Load boxes.json (delete the targets first)"
    for target_id in list(run.targets):
        _set(tab.panels.targets.draw, target_id)
        _click(tab.panels.targets.delete)
        assert tab.wait_idle()
    assert not run.targets and not button.disabled and button.label == "Load boxes.json"


def test_an_overlay_with_no_map_on_the_frame_says_why(studio) -> None:
    """On the boxes' first frame there is no response map (and on the next no local
    variation): the status says so instead of leaving an empty overlay unexplained."""
    tab, _ = _open_tab(studio)
    _click(tab.panels.targets.boxes_json)
    assert tab.wait_idle()
    status = tab.panels.status
    _wait_for(lambda: "No response map on this frame yet" in status.content)
    _set(tab.panels.display.maps, "local variation on frame")
    _click(tab.panels.playback.step)
    assert tab.wait_idle()
    _wait_for(
        lambda: "frame 2 / 60" in status.content and "No local-variation map" in status.content
    )
    _click(tab.panels.playback.step)
    assert tab.wait_idle()
    _wait_for(lambda: "frame 3 / 60" in status.content)
    assert "No local-variation map" not in status.content
    _set(tab.panels.display.maps, "off")
    _click(tab.panels.playback.step_back)
    _click(tab.panels.playback.step_back)
    assert tab.wait_idle()
    _wait_for(lambda: "frame 1 / 60" in status.content)
    assert "map on this frame" not in status.content  # nothing asked for, nothing said


def _tracked_to(tab, target_id: str) -> int:
    """The 'tracked to' column of a target's row in the Targets table."""
    for row in tab.panels.targets.table.content.splitlines():
        if row.startswith(f"| {target_id} "):
            return int(row.strip("| ").split("|")[-1])
    return 0


def test_the_server_compiles_the_tracker_kernels_in_the_background(studio) -> None:
    studio.warm_up.join(timeout=120)
    assert not studio.warm_up.is_alive()


def test_status_shows_the_in_app_and_trackers_alone_rates() -> None:
    from autotrack_studio.views import rates_text

    tracked = np.array([np.nan, 0.05, 0.05, 0.05])
    played = np.array([np.nan, np.nan, 0.1, 0.1])
    assert rates_text(tracked, played, 3) == (
        "played at 10.0 frames/s in the app · trackers alone 20.0 frames/s"
    )
    assert rates_text(tracked, np.full(4, np.nan), 3) == ""  # nothing played


def test_playing_tracks_every_target_and_estimates_poses(studio) -> None:
    tab, _ = _open_tab(studio)
    _draw_demo_boxes(tab)
    playback = tab.panels.playback
    playback.unlimited.value = True

    _click(playback.play)
    _wait_for(lambda: tab.controller.cursor >= 6)
    assert playback.play.label == "Pause"
    # While playing, the Targets table follows (no command runs to refresh it)
    _wait_for(lambda: not tab.controller.playing or _tracked_to(tab, "T1") >= 6)
    assert tab.controller.playing, "the demo ended before the check"
    _wait_for(lambda: "frames/s in the app" in tab.panels.status.content)
    _click(playback.play)
    assert tab.wait_idle()

    controller, run = tab.controller, tab.controller.run
    assert not controller.playing and playback.play.label == "Play"
    last = controller.cursor
    assert last >= 6 and run.tracked_until == last and playback.frame.value == last + 1
    for target in run.targets.values():
        assert sorted(target.results) == list(range(last + 1))
        assert np.isfinite(target.signals["peak_score"][1 : last + 1]).all()
    assert all(run.poses[index].valid for index in range(last + 1))
    display = tab.display
    _wait_for(lambda: display.stats.overlay_maps > 0 and display.stats.canvas_frames > 0)
    # The 3-D view is not sent while the canvas shows the frame, and is on switching to it.
    assert display.stats.scene_updates == 0 and display.view3d.segments_sent == 0
    _set(tab.panels.display.canvas, CANVAS_3D)
    _wait_for(lambda: display.view3d.segments_sent >= last - 1)
    _wait_for(lambda: (data := display.plots.data_of(0)) is not None and len(data[0]) == last + 3)
    peaks = np.concatenate([t.signals["peak_score"][1 : last + 1] for t in run.targets.values()])
    low, high = display.plots.y_scale_of(0)["range"]
    assert low <= peaks.min() and peaks.max() <= high and high - low < 2 * np.ptp(peaks) + 0.05
    eta_scale = display.plots.y_scale_of(1)
    assert (
        eta_scale["distr"] == 3 and eta_scale["range"][0] < run.params.phi < eta_scale["range"][1]
    )


def test_3d_view_switches_between_raw_and_smoothed_trajectories(studio) -> None:
    tab, _ = _open_tab(studio)
    _draw_demo_boxes(tab)
    _set(tab.panels.display.canvas, CANVAS_3D)
    _set(tab.panels.playback.frame, 9)
    assert tab.wait_idle()
    view3d = tab.display.view3d
    _wait_for(lambda: len(view3d.trajectory_drawn) == 9)
    raw = np.array(view3d.trajectory_drawn)
    np.testing.assert_allclose(raw[-1], tab.controller.run.poses[8].position)

    _set(tab.panels.display.trajectory, "smoothed (0.3 s lag)")
    assert tab.wait_idle()
    _wait_for(lambda: not np.allclose(view3d.trajectory_drawn, raw))
    smoothed = np.array(view3d.trajectory_drawn)
    assert smoothed.shape == raw.shape and np.max(np.abs(smoothed - raw)) < 0.05

    _set(tab.panels.display.trajectory, "raw poses")
    assert tab.wait_idle()
    _wait_for(lambda: np.allclose(view3d.trajectory_drawn, raw))


def _tiles(run, target_id: str, frame_index: int) -> list[np.ndarray | None]:
    """What the 2 x 2 map panel shows, in its order: previous response, response, local
    variation, ASR weights."""
    target = run.targets[target_id]
    result = target.results[frame_index]
    previous = target.results[frame_index - 1].response_map
    # an aberrant frame does not train: the filter keeps the weights of its last training
    trained = max(k for k in range(frame_index + 1) if target.results[k].spatial_window is not None)
    weights = target.results[trained].spatial_window
    return [previous, result.response_map, result.local_variation, weights]


def test_map_panels_show_each_targets_own_maps_and_asr_weights(studio) -> None:
    from autotrack_studio.panels import MAPS_PANELS

    tab, _ = _open_tab(studio)
    _draw_demo_boxes(tab)
    _set(tab.panels.playback.frame, 4)  # local variation exists from the third frame on
    assert tab.wait_idle()
    _set(tab.panels.display.maps, MAPS_PANELS)
    assert tab.wait_idle()

    run = tab.controller.run
    panels = tab.display.map_panels
    _wait_for(lambda: set(panels.shown()) == set(run.targets))
    assert tab.panels.display.maps_folder.visible
    shown = panels.shown()
    assert not np.array_equal(shown["T1"], shown["T2"])  # each target's own maps
    for target_id in run.targets:
        tiles = _tiles(run, target_id, 3)
        assert all(values is not None for values in tiles), target_id
        weights = tiles[3]
        assert weights.min() < run.params.reg_window_min * 10  # ASR: small inside the target
        assert not np.array_equal(tiles[0], tiles[1])
        for index, values in enumerate(tiles):
            # Independently of map_tile: the hottest finite cell of each map is drawn red (JET's
            # top), the coldest blue, where the cell lies in its tile (2 x 2, 160 px bodies
            # under an 18 px title, 26 px legend, 4 px gaps).
            rows, cols = values.shape
            top, left = (index // 2) * (18 + 160 + 26 + 4) + 18, (index % 2) * 164
            image = shown[target_id][top : top + 160, left : left + 160].astype(int)
            finite = np.where(np.isfinite(values), values, np.nan)
            for pick, hot in ((np.nanargmax, True), (np.nanargmin, False)):
                row, col = np.unravel_index(int(pick(finite)), values.shape)
                red, _, blue = image[int((row + 0.5) * 160 / rows), int((col + 0.5) * 160 / cols)]
                assert (red > blue + 64) if hot else (blue > red + 64), (target_id, index, hot)

    _set(tab.panels.display.maps, "off")
    assert tab.wait_idle()
    _wait_for(lambda: not panels.shown())
    assert not tab.panels.display.maps_folder.visible


def test_slider_tracks_up_to_the_chosen_frame_and_stepping_back_replays(studio) -> None:
    tab, _ = _open_tab(studio)
    _draw_demo_boxes(tab)
    controller = tab.controller

    _set(tab.panels.playback.frame, 9)  # 1-based: frame index 8
    assert tab.wait_idle()
    assert controller.cursor == 8 and controller.run.tracked_until == 8
    recorded = controller.run.results_at(7)

    _click(tab.panels.playback.step_back)
    assert tab.wait_idle()
    assert controller.cursor == 7 and controller.run.tracked_until == 8
    assert controller.run.results_at(7) == recorded  # shown from the record, not re-tracked
    assert tab.panels.playback.frame.value == 8


def test_correcting_a_box_by_dragging_retracks_that_target_from_there(studio) -> None:
    tab, _ = _open_tab(studio)
    _draw_demo_boxes(tab)
    controller = tab.controller
    _set(tab.panels.playback.frame, 8)
    assert tab.wait_idle()
    run = controller.run
    before = {tid: dict(t.results) for tid, t in run.targets.items()}

    _click(tab.panels.playback.step_back)
    _click(tab.panels.playback.step_back)
    assert tab.wait_idle() and controller.cursor == 5
    _set(tab.panels.targets.draw, "T2")
    assert tab.wait_idle() and controller.selected == "T2"
    old = before["T2"][5].box
    corrected = (old[0] + 6.0, old[1] + 4.0, old[2], old[3])
    _drag(tab, corrected)

    t2 = run.targets["T2"]
    np.testing.assert_allclose(t2.results[5].box, corrected, atol=2.0)
    assert max(t2.results) == 5  # its later results were dropped
    for other in ("T1", "T3", "T4"):
        assert run.targets[other].results == before[other]  # untouched
    assert "T2 corrected at frame 6" in controller.message


def test_invalid_poses_are_drawn_as_invalid(studio) -> None:
    tab, _ = _open_tab(studio)
    _draw_demo_boxes(tab)
    _set(tab.panels.display.canvas, CANVAS_3D)
    _set(tab.panels.playback.frame, 4)
    assert tab.wait_idle()
    view3d = tab.display.view3d
    _wait_for(lambda: view3d.frustum_state == "valid" and view3d.segments_sent == 3)

    targets = tab.panels.targets
    for target_id in ("T1", "T2"):  # two landmarks left: no pose can be trusted
        _set(targets.draw, target_id)
        assert tab.wait_idle()
        _set(targets.landmark, "none")
        assert tab.wait_idle()
    _set(targets.draw, "new target")
    _click(tab.panels.playback.step)
    _click(tab.panels.playback.step)
    assert tab.wait_idle()

    run = tab.controller.run
    assert not run.poses[5].valid and run.poses[5].reason
    _wait_for(lambda: view3d.frustum_state == "invalid")
    _wait_for(lambda: "pose invalid" in tab.panels.status.content)


def test_typed_box_landmark_and_delete_through_the_widgets(studio) -> None:
    tab, channel = _open_tab(studio)
    _draw_demo_boxes(tab)
    targets = tab.panels.targets
    run = tab.controller.run

    _set(targets.box, "10, 20, 30, 40")
    _click(targets.apply_box)
    assert tab.wait_idle()
    assert "the maximum" in channel.notes[-1][0] and len(run.targets) == 4

    # Greyed, the button says what enables it (a disabled button shows no tooltip).
    assert targets.delete.disabled and "choose it in Drag draws" in targets.delete.label
    _set(targets.draw, "T1")
    assert tab.wait_idle()
    assert not targets.landmark.disabled and not targets.delete.disabled
    assert targets.delete.label == "Delete T1"
    landmark_of_t1 = run.targets["T1"].landmark_id
    assert targets.landmark.value == landmark_of_t1
    _set(targets.landmark, "none")
    assert tab.wait_idle()
    assert run.targets["T1"].landmark_id is None
    assert landmark_of_t1 not in run.poses[0].used_landmarks
    _set(targets.landmark, landmark_of_t1)
    assert tab.wait_idle()
    assert run.poses[0].valid and len(run.poses[0].used_landmarks) == 4

    _set(targets.draw, "T4")
    assert tab.wait_idle()
    _click(targets.delete)
    assert tab.wait_idle()
    assert "T4" not in run.targets and targets.draw.value == "new target"
    assert targets.delete.disabled
    assert targets.box.value == ""  # choosing T4 showed its box there: gone with it
    _set(targets.box, "10, 20, 30, 40")
    _click(targets.apply_box)  # now a new target, and T4 once more
    assert tab.wait_idle()
    assert run.targets["T4"].results[0].box == (10.0, 20.0, 30.0, 40.0)
    # T1 was tied by hand, so three boxes are left to search: too few, D is still to draw
    assert run.targets["T4"].landmark_id is None and "*to draw*" in targets.table.content

    _set(targets.box, "ten, 20, 30")
    _click(targets.apply_box)
    assert tab.wait_idle()
    assert "x, y, w, h" in channel.notes[-1][0] and channel.notes[-1][1]

    _set(targets.box, "5000, 5000, 30, 30")  # outside the frame: the tracker refuses it
    _click(targets.apply_box)
    assert tab.wait_idle()
    assert channel.notes[-1][1] and list(run.targets) == ["T1", "T2", "T3", "T4"]
    _set(tab.panels.playback.frame, 3)
    assert tab.wait_idle()
    assert run.tracked_until == 2  # nothing half-made is left to break tracking


def test_download_buttons_send_tracks_poses_and_the_session(studio) -> None:
    tab, channel = _open_tab(studio)
    _draw_demo_boxes(tab)
    _set(tab.panels.playback.frame, 6)
    assert tab.wait_idle()

    session = tab.panels.session
    buttons = (
        session.download_tracks,
        session.download_poses,
        session.download_mot,
        session.download_cvat,
        session.download_mcap,
    )
    for button in buttons:
        _click(button)
    assert tab.wait_idle()

    path = tab.controller.run.session_path
    names = [name for name, _ in channel.downloads]
    assert names == [
        f"{path.stem}_tracks.zip",
        f"{path.stem}_poses.tum",
        f"{path.stem}_mot.txt",
        f"{path.stem}_cvat.xml",
        path.name,
    ]
    with zipfile.ZipFile(io.BytesIO(channel.downloads[0][1])) as archive:
        names = sorted(archive.namelist())  # T<n>_<landmark>.txt, then tracks.csv
        assert [name.split("_")[0] for name in names] == ["T1", "T2", "T3", "T4", "tracks.csv"]
    # MOT: frame, id, x, y, w, h, score, ... one row per target and frame (1-based frames).
    mot_rows = [row.split(",") for row in channel.downloads[2][1].decode().splitlines()]
    assert len(mot_rows) == 4 * 6 and {row[0] for row in mot_rows} == {str(k) for k in range(1, 7)}
    cvat = channel.downloads[3][1].decode()
    assert "<original_size>" in cvat and "<width>960</width>" in cvat and cvat.count("<track ") == 4
    assert channel.downloads[4][1][:8] == b"\x89MCAP0\r\n"


def test_two_tabs_keep_separate_runs_and_cannot_reopen_a_live_session(studio) -> None:
    first, _ = _open_tab(studio, tab_id=1)
    second, second_channel = _open_tab(studio, tab_id=2)
    _drag(first, _demo_boxes()[first.controller.run.scene.landmark_ids[0]])

    assert list(first.controller.run.targets) == ["T1"] and not second.controller.run.targets
    live = first.controller.run.session_path
    _click(second.panels.session.refresh)
    assert second.wait_idle()
    _set(second.panels.session.sessions, live.name)
    _click(second.panels.session.reopen)
    assert second.wait_idle()
    assert "another tab" in second_channel.notes[-1][0]
    assert not second.controller.run.targets


def test_reopened_session_restores_targets_and_continues(studio) -> None:
    first, _ = _open_tab(studio, tab_id=1)
    _draw_demo_boxes(first)
    _set(first.panels.playback.frame, 5)
    assert first.wait_idle()
    recorded = {tid: t.results[4].box for tid, t in first.controller.run.targets.items()}
    old_path = first.controller.run.session_path
    studio.close_tab(1)
    assert studio.recordings.writer_of(old_path) is None

    tab, _ = _open_tab(studio, tab_id=2)
    _click(tab.panels.session.refresh)
    assert tab.wait_idle()
    _set(tab.panels.targets.box, "1, 2, zz")  # a refused typed box ...
    _click(tab.panels.targets.apply_box)
    _set(tab.panels.session.sessions, old_path.name)
    _click(tab.panels.session.reopen)
    assert tab.wait_idle()
    assert tab.panels.targets.box.value == ""  # ... is not left over the reopened run

    controller = tab.controller
    run = controller.run
    assert controller.cursor == 4 and list(run.targets) == ["T1", "T2", "T3", "T4"]
    assert tab.panels.playback.frame.value == 5
    for target_id, box in recorded.items():
        assert run.targets[target_id].results[4].box == box  # history kept as recorded
        assert sorted(run.targets[target_id].results) == list(range(5))
    assert run.session_path != old_path
    _click(tab.panels.playback.step)
    assert tab.wait_idle()
    assert run.tracked_until == 5


def test_paths_outside_the_allowed_folders_are_refused(studio, tmp_path: Path) -> None:
    tab, channel = _open_tab(studio)
    opened = tab.controller.sequence_path
    _set(tab.panels.sequence.path, str(tmp_path.parent))
    _click(tab.panels.sequence.open_path)
    assert tab.wait_idle()
    assert "no such file or folder among those" in channel.notes[-1][0] and channel.notes[-1][1]
    assert tab.controller.sequence_path == opened


def test_uploaded_zip_opens_as_a_sequence(studio) -> None:
    tab, _ = _open_tab(studio)
    frames = sorted((DEMO / "img").iterdir())[:3]
    content = _zip({f"clip/{path.name}": path.read_bytes() for path in frames})
    tab.receive_upload("clip.zip", content)
    assert tab.wait_idle()
    run = tab.controller.run
    assert run.frame_count == 3 and run.scene is None
    assert tab.controller.sequence_path.is_relative_to(studio.config.upload_dir.resolve())
    assert any("uploads" in name for name in tab.panels.sequence.dropdown.options)
    # the list shows the sequence that is open (not the first listed)
    shown = tab.panels.sequence.dropdown.value
    assert tab.controller.sequence_choices[shown] == tab.controller.sequence_path
    assert not tab.panels.targets.boxes_json.visible


def test_an_upload_that_does_not_open_is_neither_kept_nor_listed(studio) -> None:
    """A file named .mp4 that is no video is refused in one line, and deleted: listed, it
    would fail again each time it is picked. The open run stays."""
    tab, channel = _open_tab(studio)
    demo = tab.controller.run
    tab.receive_upload("flight.mp4", b"this is not a video" * 50)
    assert tab.wait_idle()
    assert "cannot open video" in channel.notes[-1][0] and channel.notes[-1][1]
    assert tab.controller.run is demo
    assert not [p for p in studio.config.upload_dir.rglob("*") if p.is_file()]
    assert not any("flight" in name for name in tab.controller.sequence_choices)


def test_a_drag_off_the_frame_is_refused_and_one_past_its_edge_is_cut(studio) -> None:
    tab, _ = _open_tab(studio)
    width, height = tab.controller.frame_size
    _drag(tab, (100.0, -80.0, 60.0, 50.0))  # in the letterbox band above the frame
    assert not tab.controller.run.targets and "misses the frame" in tab.controller.message
    _drag(tab, (width - 30.0, height - 20.0, 60.0, 50.0))
    (target,) = tab.controller.targets()
    np.testing.assert_allclose(target.results[0].box, (width - 30, height - 20, 30, 20), atol=1.0)
    assert "the box is cut there" in tab.controller.message
    _drag(tab, (100.0, 100.0, 50.0, 40.0))  # inside: nothing said about edges
    assert len(tab.controller.targets()) == 2 and "edge" not in tab.controller.message


def test_drawing_needs_the_frame_canvas(studio) -> None:
    tab, channel = _open_tab(studio)
    _set(tab.panels.display.canvas, "3-D view")
    assert tab.wait_idle()
    moves = channel.camera_moves
    tab.rect_selected(
        viser.SceneRectSelectEvent(
            client=None, client_id=0, screen_min=(0.4, 0.4), screen_max=(0.6, 0.6), modifier="shift"
        )
    )
    assert tab.wait_idle()
    assert not tab.controller.run.targets and "Canvas to 'frame'" in tab.controller.message
    assert "Canvas to 'frame'" in channel.notes[-1][0]  # said over the canvas too
    assert moves >= 2  # switching to the 3-D view aimed the camera


def _click_canvas(tab, modifier: str | None) -> None:
    """A click at the canvas centre, as viser reports it, and the tab done with it."""
    tab.clicked(
        viser.SceneClickEvent(
            client=None,
            client_id=0,
            ray_origin=(0.0, 0.0, 0.0),
            ray_direction=(0.0, 0.0, 1.0),
            screen_pos=(0.5, 0.5),
            modifier=modifier,
        )
    )
    assert tab.wait_idle()


def test_a_click_on_the_frame_says_how_to_draw_a_box(studio) -> None:
    """viser sends no rect-select for a shift-click (a drag of no size), only a click: the
    user is told to drag, at once and in the status line; on the 3-D view, to switch."""
    from autotrack_studio.tab import DRAW_HINT, SWITCH_HINT

    tab, channel = _open_tab(studio)
    assert "none yet" in tab.panels.targets.delete.label
    for modifier in ("shift", None):
        channel.notes.clear()
        _click_canvas(tab, modifier)
        assert channel.notes == [(DRAW_HINT, False)] and tab.controller.message == DRAW_HINT
        assert "hold Shift and drag" in DRAW_HINT and not tab.controller.run.targets
    _set(tab.panels.display.canvas, "3-D view")
    assert tab.wait_idle()
    channel.notes.clear()
    _click_canvas(tab, "shift")
    assert channel.notes == [(SWITCH_HINT, False)] and tab.controller.message == SWITCH_HINT


def test_shared_benchmark_sequence_opens_by_typed_path_and_tracks(tmp_path: Path) -> None:
    if not SHARED_SEQUENCES.is_dir():
        pytest.skip("../shared/data/sequences is not present")
    from autotrack_studio.server import StudioServer

    studio = StudioServer(
        AppConfig(
            sequence=(SHARED_SEQUENCES / "OTB" / "Crossing").resolve(),
            port=_free_port(),
            sessions_dir=tmp_path / "sessions",
            allowed_roots=(SHARED_SEQUENCES.resolve(),),
        )
    )
    try:
        tab, _ = _open_tab(studio)
        assert tab.controller.run.frames.name == "Crossing" and tab.controller.run.scene is None
        _set(tab.panels.sequence.path, "UAV123_10fps/boat5")
        _click(tab.panels.sequence.open_path)
        assert tab.wait_idle()
        run = tab.controller.run
        assert run.frames.name == "boat5" and not tab.panels.targets.boxes_json.visible
        first = np.loadtxt(
            SHARED_SEQUENCES / "UAV123_10fps" / "boat5" / "groundtruth_rect.txt", delimiter=","
        )[0]
        _drag(tab, tuple(first - [1, 1, 0, 0]))
        _click(tab.panels.playback.step)
        _click(tab.panels.playback.step)
        assert tab.wait_idle()
        target = run.targets["T1"]
        assert target.landmark_id is None and sorted(target.results) == [0, 1, 2]
        assert not run.poses
    finally:
        studio.stop()


def _screen_fractions(eye, centre, points, fov, aspect) -> np.ndarray:
    """(n, 2) points as fractions of the view's half-width and half-height (|v| <= 1 is on
    screen) for a camera at `eye` looking at `centre` with +z up."""
    forward = (centre - eye) / np.linalg.norm(centre - eye)
    right = np.cross(forward, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, forward)
    offsets = np.asarray(points) - eye
    depth = offsets @ forward
    assert (depth > 0).all()  # every point in front of the eye
    tan_y = np.tan(fov / 2)
    return np.stack(
        [offsets @ right / depth / (tan_y * aspect), offsets @ up / depth / tan_y], axis=1
    )


def test_the_3d_view_frames_landmarks_ground_truth_and_trajectory() -> None:
    """The view fits the landmarks, the ground truth and the estimated trajectory tightly
    (all inside, filling the view along one axis) for the browser's own view angle and
    canvas shape, tall or wide; so the demo's flight is not a speck in the middle."""
    from autotrack.localization.scene import load_scene
    from autotrack_studio.boxes import ground_truth_positions
    from autotrack_studio.view3d import FRAME_MARGIN, SceneView

    scene = load_scene(DEMO / "scene.json")
    truth = ground_truth_positions(DEMO / "scene.json")
    server = viser.ViserServer(port=0, verbose=False)
    view = SceneView(server.scene)
    view.show_scene(scene, truth)
    server.stop()
    far = truth[-1] + np.array([6.0, -4.0, 2.0])  # an estimate that drifted far away
    landmarks = [lm.position for lm in scene.landmarks]
    for trajectory in (None, np.array([truth[0], far])):
        points = landmarks + list(truth) + ([] if trajectory is None else list(trajectory))
        for fov, aspect in ((np.radians(50), 16 / 9), (np.radians(75), 0.69), (1.0, 1.0)):
            eye, centre = view.viewpoint(trajectory, fov, aspect)
            on_screen = np.abs(_screen_fractions(eye, centre, points, fov, aspect))
            assert on_screen.max() <= FRAME_MARGIN + 1e-9
            assert on_screen.max() >= FRAME_MARGIN - 0.05  # tight, not a speck
    # The demo's flight (its ground truth) spans a third of a tall canvas's width or more
    # (the sphere-fitted view before gave it 11 %).
    fov, aspect = np.radians(75), 0.69
    eye, centre = view.viewpoint(None, fov, aspect)
    flight = _screen_fractions(eye, centre, truth, fov, aspect)
    assert np.ptp(flight[:, 0]) / 2 >= 0.3


def test_the_3d_view_is_framed_again_when_localisation_starts_and_on_reopening(
    studio,
) -> None:
    """Opening frames the scene; the first trusted pose (the fourth box) frames it again with
    the trajectory, once: later frames leave the user's view alone; reopening frames it."""
    tab, channel = _open_tab(studio)
    opened = channel.camera_moves
    assert opened >= 1
    boxes = _demo_boxes()
    for landmark_id in ("A", "B", "C"):
        _drag(tab, boxes[landmark_id])
    assert channel.camera_moves == opened  # no pose from three boxes yet
    _drag(tab, boxes["D"])
    run = tab.controller.run
    assert run.poses[0].valid and channel.camera_moves == opened + 1
    _click(tab.panels.playback.step)
    _click(tab.panels.playback.step)
    assert tab.wait_idle()
    assert channel.camera_moves == opened + 1
    name = run.session_path.name
    _click(tab.panels.session.refresh)
    assert tab.wait_idle()
    _set(tab.panels.session.sessions, name)
    _click(tab.panels.session.reopen)
    assert tab.wait_idle()
    assert tab.controller.run is not run and channel.camera_moves > opened + 1


def test_one_browser_does_not_see_another_browsers_sessions_and_uploads(studio) -> None:
    """Sessions and uploads are listed to the browser that made them only; a session file the
    operator put in the sessions folder is listed to everyone (app/owners.py)."""
    from autotrack.sessions import SessionRecorder

    alice, _ = _open_tab(studio, tab_id=1, browser="alice")
    _drag(alice, _demo_boxes()[alice.controller.run.scene.landmark_ids[0]])
    recorded = alice.controller.run.session_path
    frames = sorted((DEMO / "img").iterdir())[:3]
    alice.receive_upload("clip.zip", _zip({f"clip/{p.name}": p.read_bytes() for p in frames}))
    assert alice.wait_idle()
    uploaded = alice.controller.sequence_path
    with SessionRecorder.create(studio.config.sessions_dir, source="cli", tracker_params={}):
        pass  # an operator's recording, straight in the sessions folder
    operators = next(studio.config.sessions_dir.glob("*.mcap"))
    studio.close_tab(1)

    bob, bob_channel = _open_tab(studio, tab_id=2, browser="bob")
    bob.controller.sessions.refresh()
    assert list(bob.controller.sessions.choices) == [operators.name]
    assert not any(path == uploaded for path in bob.controller.sequence_choices.values())
    bob.controller.refresh_sequences()
    assert uploaded not in bob.controller.sequence_choices.values()
    _set(bob.panels.sequence.path, str(uploaded))
    _click(bob.panels.sequence.open_path)
    assert bob.wait_idle()
    assert "no such file or folder" in bob_channel.notes[-1][0]
    assert bob.controller.sequence_path != uploaded

    again, _ = _open_tab(studio, tab_id=3, browser="alice")  # alice's next tab sees hers
    again.controller.sessions.refresh()
    assert {recorded.name, operators.name} <= set(again.controller.sessions.choices)
    assert uploaded in again.controller.sequence_choices.values()


def test_share_sessions_lists_every_browsers_sessions(studio) -> None:
    from dataclasses import replace

    alice, _ = _open_tab(studio, tab_id=1, browser="alice")
    _drag(alice, _demo_boxes()[alice.controller.run.scene.landmark_ids[0]])
    recorded = alice.controller.run.session_path
    studio.close_tab(1)
    studio.config = replace(studio.config, share_sessions=True)
    bob, _ = _open_tab(studio, tab_id=2, browser="bob")
    bob.controller.sessions.refresh()
    assert recorded.name in bob.controller.sessions.choices


def test_messages_and_fields_show_paths_relative_to_their_root(studio, tmp_path: Path) -> None:
    """Nothing sent to the browser names the server's absolute paths: errors and the path
    fields show `<root name>/...`, which the path field takes back."""
    sessions = studio.config.sessions_dir
    (sessions / "clips").mkdir()
    (sessions / "clips" / "broken.mp4").write_bytes(b"not a video at all")
    tab, channel = _open_tab(studio)
    shown = tab.panels.sequence.path.value  # the demo, opened at start
    assert not Path(shown).is_absolute() and shown.startswith(DEMO.name)
    _set(tab.panels.sequence.path, str(sessions / "clips" / "broken.mp4"))
    _click(tab.panels.sequence.open_path)
    assert tab.wait_idle()
    note = channel.notes[-1][0]
    assert "sessions/clips/broken.mp4" in note and str(tmp_path) not in note, note
    assert str(tmp_path) not in tab.controller.message

    _set(tab.panels.sequence.path, shown)
    _click(tab.panels.sequence.open_path)
    assert tab.wait_idle()
    assert tab.controller.sequence_path == DEMO.resolve()


def test_shown_paths_hides_every_absolute_server_path(tmp_path: Path) -> None:
    from autotrack_studio.paths import shown_paths

    root = (tmp_path / "data").resolve()
    text = (
        f"cannot open {root}/car/x.mp4; cannot write {tmp_path}/sessions/b/s.mcap: "
        f"[Errno 28] No space left on device: '{tmp_path}/sessions/b/s.mcap'; see /etc/passwd"
    )
    shown = shown_paths(text, [root], [tmp_path / "sessions"])
    assert str(tmp_path) not in shown and "/etc" not in shown
    assert "data/car/x.mp4" in shown and "'sessions/b/s.mcap'" in shown and "passwd" in shown


def test_shown_paths_leaves_urls_intact(tmp_path: Path) -> None:
    from autotrack_studio.paths import shown_paths

    root = (tmp_path / "data").resolve()
    urls = ("rtsp://cam.local:8554/live/main", "http://example.com/data/x.mp4", "https://h/a/b")
    text = f"cannot open {urls[0]} (timeout); {urls[1]} and {urls[2]}: see {root}/car/y.mp4"
    shown = shown_paths(text, [root, Path("/data")], [tmp_path / "sessions"])
    assert all(url in shown for url in urls), shown
    assert "data/car/y.mp4" in shown and str(tmp_path) not in shown
    assert "file://passwd" in shown_paths("file:///etc/passwd", [root])  # a server file: hidden


def test_a_reopened_session_shows_the_preset_it_was_recorded_with(studio) -> None:
    first, _ = _open_tab(studio, tab_id=1)
    _set(first.panels.sequence.preset, "strcf")
    _set(first.panels.sequence.path, "demo")
    _click(first.panels.sequence.open_path)
    assert first.wait_idle()
    assert first.controller.run.params.name == "strcf"
    _drag(first, _demo_boxes()["A"])
    recorded = first.controller.run.session_path
    studio.close_tab(1)

    tab, _ = _open_tab(studio, tab_id=2)
    assert tab.panels.sequence.preset.value == "autotrack"  # the server's default
    _click(tab.panels.session.refresh)
    assert tab.wait_idle()
    _set(tab.panels.session.sessions, recorded.name)
    _click(tab.panels.session.reopen)
    assert tab.wait_idle()
    assert tab.controller.run.params.name == "strcf"
    assert tab.panels.sequence.preset.value == "strcf"  # not the default it showed
    assert tab.controller.preset_name == "strcf"  # and the next sequence opened uses it


def test_load_boxes_json_follows_the_open_source(studio, tmp_path: Path) -> None:
    from autotrack_studio.live import LiveControl
    from tests.test_app_live import _demo_video

    tab, _ = _open_tab(studio)
    boxes_json = tab.panels.targets.boxes_json
    assert boxes_json.visible and not boxes_json.disabled  # the demo has one
    media = tmp_path / "sessions" / "media"
    media.mkdir()
    _demo_video(media)
    tab.live = LiveControl(tab.controller, allowed=True)  # as --allow-live gives it
    tab.worker.submit(tab.live.open_source, "sessions/media/flight.avi")
    _wait_for(lambda: tab.live.state == "preview", timeout=120)
    _wait_for(lambda: not boxes_json.visible, timeout=120)  # not the demo's any more
    assert tab.live.state == "preview" and tab.controller.boxes_path is None
    tab.worker.submit(tab.live.stop)
    assert tab.wait_idle()


def test_a_tab_can_reopen_the_session_it_is_recording(studio) -> None:
    tab, channel = _open_tab(studio)
    _drag(tab, _demo_boxes()["A"])
    _set(tab.panels.playback.frame, 4)
    assert tab.wait_idle()
    own = tab.controller.run.session_path
    _click(tab.panels.session.refresh)
    assert tab.wait_idle()
    _set(tab.panels.session.sessions, own.name)
    _click(tab.panels.session.reopen)
    assert tab.wait_idle()
    assert not [note for note, error in channel.notes if error], channel.notes  # not "another tab"
    controller = tab.controller
    assert controller.message.startswith(f"Reopened {own.name}") and controller.cursor == 3
    assert list(controller.run.targets) == ["T1"] and controller.run.session_path != own
    assert studio.recordings.writer_of(own) is None


def test_show_ground_truth_redraws_the_canvas_at_once(tmp_path: Path) -> None:
    if not (SHARED_SEQUENCES / "DTB70" / "Gull1").is_dir():
        pytest.skip("../shared/data/sequences is not present")
    from autotrack_studio.server import StudioServer
    from tests.test_app_controller import _first_frames

    sequence = _first_frames(SHARED_SEQUENCES / "DTB70" / "Gull1", tmp_path / "Gull1", 3)
    studio = StudioServer(
        AppConfig(sequence=sequence, port=_free_port(), sessions_dir=tmp_path / "sessions")
    )
    try:
        tab, channel = _open_tab(studio)
        stats = tab.display.stats
        _wait_for(lambda: stats.canvas_frames >= 1)
        time.sleep(0.5)  # nothing else to draw
        drawn = stats.canvas_frames
        _set(tab.panels.targets.show_truth, True)  # no command runs: only the checkbox
        _wait_for(lambda: stats.canvas_frames > drawn, timeout=120)
        assert not [note for note, error in channel.notes if error]
    finally:
        studio.stop()


def test_the_tracker_choice_applies_or_offers_a_restart_with_it(studio) -> None:
    tab, _ = _open_tab(studio)
    sequence, restart = tab.panels.sequence, tab.panels.sequence.restart
    _set(sequence.preset, "autotrack+")  # no target yet: the run takes it at once
    assert tab.wait_idle()
    assert tab.controller.run.params.name == "autotrack+" and not restart.visible
    _drag(tab, _demo_boxes()["A"])
    assert tab.controller.run.params.name == "autotrack+"
    _set(sequence.preset, "strcf")  # T1 tracks with autotrack+: the page offers a restart
    assert tab.wait_idle()
    assert restart.visible and restart.label == "Restart with strcf"
    assert tab.controller.run.params.name == "autotrack+"
    assert "Restart with strcf" in tab.controller.message
    _click(restart)
    assert tab.wait_idle()
    assert tab.controller.run.params.name == "strcf" and not restart.visible
    assert sequence.preset.value == "strcf" and not tab.controller.run.targets


def test_while_playing_the_display_sends_less_of_what_the_browser_draws() -> None:
    from autotrack_studio.display import GUI_FPS, PLAYING_SLOW_FPS, SLOW_FPS, send_periods

    assert send_periods(False, True, 0.2) == (1.0 / GUI_FPS, 1.0 / SLOW_FPS)  # paused: all
    assert send_periods(True, True, 0.2) == (0.2, 1.0 / PLAYING_SLOW_FPS)  # the canvas's rate
    assert send_periods(True, False, 0.2) == (1.0 / GUI_FPS, 1.0 / PLAYING_SLOW_FPS)  # 3-D


def test_the_frame_slider_follows_playback_at_a_few_updates_a_second(studio) -> None:
    from autotrack_studio.tab import SLIDER_PERIOD

    tab, _ = _open_tab(studio)
    slider, controller = tab.panels.playback.frame, tab.controller
    tab.worker.submit(controller.load_boxes_json)
    assert tab.wait_idle()
    writes: list[float] = []
    original = tab.panels.quiet.set

    def counted(handle, attribute, value) -> None:
        if handle is slider and attribute == "value":
            writes.append(time.monotonic())
        original(handle, attribute, value)

    tab.panels.quiet.set = counted
    _set(tab.panels.playback.unlimited, True)
    started = time.monotonic()
    _click(tab.panels.playback.play)
    _wait_for(
        lambda: not controller.playing and controller.cursor == controller.run.frame_count - 1, 120
    )
    assert tab.wait_idle()
    seconds = time.monotonic() - started
    assert len(writes) <= seconds / SLIDER_PERIOD + 3  # not one a frame
    assert slider.value == controller.run.frame_count  # the last frame once it stops


def test_target_colours_are_distinct_and_none_is_the_aberrant_red() -> None:
    from autotrack_studio.canvas import ABERRANT, TARGET_COLOURS

    colours = np.array(TARGET_COLOURS, dtype=float)
    assert len({tuple(c) for c in TARGET_COLOURS}) == len(TARGET_COLOURS)
    assert np.linalg.norm(colours - np.array(ABERRANT), axis=1).min() > 150
    assert not any(r > 200 and g < 120 and b < 120 for r, g, b in TARGET_COLOURS)  # no red


def test_the_response_overlay_uses_a_robust_scale_and_the_chosen_opacity() -> None:
    values = np.random.default_rng(2).uniform(0.0, 0.1, (25, 25)).astype(np.float32)
    values[5, 20] = 50.0  # one extreme peak: a min-max scale would leave the rest dark blue
    result = _result(values)
    frame = np.full((120, 160, 3), 128, np.uint8)
    drawing = TargetDrawing(label="T1", colour=(64, 200, 255), box=result.box, result=result)
    plain = draw_overlays(frame, [drawing], "none").astype(int)
    faint = draw_overlays(frame, [drawing], "response", map_opacity=0.2).astype(int)
    strong = draw_overlays(frame, [drawing], "response", map_opacity=0.9).astype(int)
    region = (slice(30, 64), slice(22, 68))  # inside the search region, below the legend
    faint_change = np.abs(faint[region] - plain[region]).mean()
    strong_change = np.abs(strong[region] - plain[region]).mean()
    assert strong_change > 3 * faint_change > 0
    # Spread over the colour scale: the region's colours vary, not one flat blue.
    assert strong[region].reshape(-1, 3).std(axis=0).max() > 30


def test_play_needs_frames_and_the_maps_hint_goes_once_the_panels_are_chosen(studio) -> None:
    from autotrack_studio.panels import MAPS_PANELS, MAPS_RESPONSE

    tab, _ = _open_tab(studio)
    playback, display = tab.panels.playback, tab.panels.display
    assert not playback.play.disabled and not playback.step.disabled
    tab.worker.submit(tab.controller.close_run)  # nothing open: nothing to play
    assert tab.wait_idle()
    assert playback.play.disabled and playback.step.disabled and playback.step_back.disabled
    tab.worker.submit(tab.controller.open_initial)
    assert tab.wait_idle() and not playback.play.disabled
    assert display.maps_hint.visible
    _set(display.maps, MAPS_PANELS)
    assert tab.wait_idle()
    assert not display.maps_hint.visible and display.maps_folder.visible
    _set(display.maps, MAPS_RESPONSE)
    assert tab.wait_idle() and display.maps_hint.visible


def test_a_reloaded_page_points_to_the_session_its_tab_recorded(studio) -> None:
    first, _ = _open_tab(studio, tab_id=1, browser="alice")
    assert first.controller.suggested_session is None  # nothing recorded before
    _drag(first, _demo_boxes()["A"])
    _set(first.panels.playback.frame, 5)
    assert first.wait_idle()
    recorded = first.controller.run.session_path
    studio.close_tab(1)  # a reload closes the tab ...

    again, _ = _open_tab(studio, tab_id=2, browser="alice")  # ... and opens a new one
    assert again.controller.suggested_session == recorded.name
    assert again.panels.session.sessions.value == recorded.name
    assert "Reopen and continue" in again.controller.message
    _click(again.panels.session.reopen)
    assert again.wait_idle()
    assert again.controller.cursor == 4 and list(again.controller.run.targets) == ["T1"]
    other, _ = _open_tab(studio, tab_id=3, browser="bob")  # another browser: not its session
    assert other.controller.suggested_session is None
