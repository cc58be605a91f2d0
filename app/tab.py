"""One browser tab: its GUI, its tracking run, and two threads that keep them apart.

GUI callbacks never track: they put a command on the tab's queue. The worker thread runs the
commands and, while playing, tracks the next frame, then publishes an immutable `FrameView`.
The display thread turns the latest view into what the browser gets: the video panel (JPEG,
every view up to `GUI_FPS`), the 3-D canvas background (letterboxed, capped at the user's
canvas rate because software WebGL draws only a few per second), plots, map panels and the
3-D view (`SLOW_FPS`). Views the display thread had no time for are skipped, so a slow
browser never slows tracking.
"""

from __future__ import annotations

import json
import math
import queue
import sys
import threading
import time
import traceback
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import viser

from app import exports
from app.canvas import (
    Letterbox,
    TargetDrawing,
    draw_overlays,
    fit_letterbox,
    letterbox_image,
    map_panel,
    target_colour,
    thumbnail,
)
from app.channel import ClientChannel
from app.paths import display_name, find_sequences, resolve_user_path, store_upload
from app.plots import SignalHistory, SignalPlots
from app.run import TrackingRun
from app.view3d import PoseView, SceneView
from autotrack.errors import AutoTrackError, InputError
from autotrack.frames import open_frames
from autotrack.localize import PoseEstimate, read_tum
from autotrack.params import PRESETS, preset
from autotrack.scene import load_scene
from autotrack.sessions import last_state, open_session
from autotrack.smoothing import SmootherParams, smoothed_positions

if TYPE_CHECKING:
    from app.server import StudioServer

NEW_TARGET = "new target"
NO_LANDMARK = "none"
CANVAS_FRAME = "frame (shift-drag draws a box)"
CANVAS_3D = "3-D view"
MAPS_OFF = "off"
MAPS_RESPONSE = "response map on frame"
MAPS_VARIATION = "local variation on frame"
MAPS_PANELS = "panels (per target)"
TRAJECTORY_RAW = "raw poses"
TRAJECTORY_SMOOTHED = "smoothed (0.3 s lag)"

GUI_FPS = 30.0
"""Most video-panel updates per second (viser keeps only the latest anyway)."""
SLOW_FPS = 5.0
"""Most plot, map-panel and 3-D updates per second."""
VIDEO_MAX_WIDTH = 640
"""Largest width of the video-panel image (pixels): the panel is narrow, and drawing on a
smaller image leaves the CPU to the tracker."""
CANVAS_MAX_WIDTH = 1280
"""Largest width of the letterboxed canvas background (pixels)."""
DEFAULT_CANVAS_SIZE = (1280, 720)
"""Canvas size assumed until the browser reports one."""
TIMES_KEPT = 2000
"""Send times kept per kind for measuring display rates."""


@dataclass(frozen=True)
class FrameView:
    """Everything the display needs for one frame, published by the worker thread."""

    version: int
    frame_index: int
    frame_count: int
    frame: np.ndarray
    drawings: tuple[TargetDrawing, ...]
    pose_view: PoseView | None
    history: SignalHistory
    status: str


@dataclass
class DisplayStats:
    """What the display thread sent (counts since the tab opened, for tests and figures)."""

    views_published: int = 0
    video_frames: int = 0
    canvas_frames: int = 0
    overlay_maps: int = 0
    """Video frames sent with a map drawn over a search region."""
    map_panel_updates: int = 0
    plot_updates: int = 0
    scene_updates: int = 0
    canvas_times: deque[float] = field(default_factory=lambda: deque(maxlen=TIMES_KEPT))
    """Send times (time.monotonic) of the latest canvas frames."""
    video_times: deque[float] = field(default_factory=lambda: deque(maxlen=TIMES_KEPT))
    """Send times of the latest video-panel frames."""


def parse_box(text: str) -> tuple[float, float, float, float]:
    """'x, y, w, h' (0-based pixels) typed by the user."""
    parts = [part for part in text.replace(";", ",").replace(" ", ",").split(",") if part]
    try:
        values = [float(part) for part in parts]
    except ValueError:
        raise InputError(f"type the box as four numbers 'x, y, w, h', not {text!r}") from None
    if len(values) != 4 or not all(math.isfinite(value) for value in values):
        raise InputError(f"type the box as four numbers 'x, y, w, h', not {text!r}")
    return (values[0], values[1], values[2], values[3])


def format_box(box: tuple[float, float, float, float]) -> str:
    """A box as the text field shows it."""
    return ", ".join(f"{value:.1f}" for value in box)


class Tab:
    """The state and GUI of one browser tab (see the module docstring for the threads)."""

    def __init__(
        self,
        studio: StudioServer,
        channel: ClientChannel,
        gui: viser.GuiApi,
        scene_api: viser.SceneApi,
        *,
        tab_id: int,
    ) -> None:
        self.studio = studio
        self.config = studio.config
        self.roots = studio.roots
        self.channel = channel
        self.gui = gui
        self.scene_api = scene_api
        self.tab_id = tab_id
        self.run: TrackingRun | None = None
        self.sequence_path: Path | None = None
        self.scene_path: Path | None = None
        self.boxes_path: Path | None = None
        self.cursor = 0
        self.playing = False
        self.selected = NEW_TARGET
        self.stats = DisplayStats()
        self._sequence_choices: dict[str, Path] = {}
        self._session_choices: dict[str, Path] = {}
        self._quiet = threading.local()
        self._commands: queue.Queue[Callable[[], None] | None] = queue.Queue()
        self._pending = 0
        self._pending_lock = threading.Condition()
        self._view_lock = threading.Condition()
        self._view: FrameView | None = None
        self._version = 0
        self._closed = False
        self._canvas_dirty = True
        self.letterbox: Letterbox | None = None
        """How the last canvas background placed the frame (maps rect-selects to pixels)."""
        self._map_panels: dict[str, viser.GuiImageHandle] = {}
        self._message = ""
        self._claimed: Path | None = None

        self._build_gui()
        self.view3d = SceneView(scene_api)
        self.plots = SignalPlots(gui)
        scene_api.on_rect_select(modifier="shift")(self.handle_rect_select)
        channel.on_canvas_change(self._canvas_changed)
        self._worker = threading.Thread(target=self._work, name=f"tab{tab_id}-worker", daemon=True)
        self._display = threading.Thread(
            target=self._display_loop, name=f"tab{tab_id}-display", daemon=True
        )
        self._worker.start()
        self._display.start()

    # -- GUI ----------------------------------------------------------------------------------

    def _build_gui(self) -> None:
        gui = self.gui
        self.status = gui.add_markdown("Opening…")
        self.video = gui.add_image(
            np.zeros((90, 160, 3), np.uint8), label="Video", format="jpeg", jpeg_quality=80
        )
        with gui.add_folder("Sequence", expand_by_default=False):
            self.sequence_dropdown = gui.add_dropdown("Sequences", options=("(none)",))
            self.open_selected_button = gui.add_button("Open selected sequence")
            self.refresh_sequences_button = gui.add_button("Refresh list")
            self.path_text = gui.add_text("Path", initial_value="")
            self.open_path_button = gui.add_button("Open path")
            self.scene_text = gui.add_text("Scene file", initial_value="")
            self.apply_scene_button = gui.add_button("Use scene file (reopens)")
            self.preset_dropdown = gui.add_dropdown(
                "Tracker", options=tuple(PRESETS), initial_value=self.config.tracker_preset
            )
            self.upload_button = gui.add_upload_button(
                "Upload video or zip of images", mime_type="video/*,.zip,application/zip"
            )
        with gui.add_folder("Targets"):
            self.targets_markdown = gui.add_markdown("No targets yet.")
            self.draw_dropdown = gui.add_dropdown(
                "Drag draws", options=(NEW_TARGET,), initial_value=NEW_TARGET
            )
            self.landmark_dropdown = gui.add_dropdown(
                "Landmark", options=(NO_LANDMARK,), initial_value=NO_LANDMARK
            )
            self.box_text = gui.add_text("Box x, y, w, h", initial_value="")
            self.apply_box_button = gui.add_button("Apply typed box")
            self.delete_button = gui.add_button("Delete target", color="red")
            self.boxes_json_button = gui.add_button("Load boxes.json", visible=False)
        with gui.add_folder("Playback"):
            self.play_button = gui.add_button("Play", icon=viser.Icon.PLAYER_PLAY)
            self.step_back_button = gui.add_button("Step back", icon=viser.Icon.PLAYER_SKIP_BACK)
            self.step_button = gui.add_button("Step forward", icon=viser.Icon.PLAYER_SKIP_FORWARD)
            self.frame_slider = gui.add_slider("Frame", min=1, max=2, step=1, initial_value=1)
            self.speed_slider = gui.add_slider(
                "Speed (frames/s)", min=1, max=60, step=1, initial_value=30
            )
            self.unlimited_checkbox = gui.add_checkbox("As fast as tracking goes", False)
        with gui.add_folder("Display"):
            self.canvas_dropdown = gui.add_dropdown(
                "Canvas", options=(CANVAS_FRAME, CANVAS_3D), initial_value=CANVAS_FRAME
            )
            self.maps_dropdown = gui.add_dropdown(
                "Maps",
                options=(MAPS_OFF, MAPS_RESPONSE, MAPS_VARIATION, MAPS_PANELS),
                initial_value=MAPS_RESPONSE,
            )
            self.trajectory_dropdown = gui.add_dropdown(
                "3-D trajectory",
                options=(TRAJECTORY_RAW, TRAJECTORY_SMOOTHED),
                initial_value=TRAJECTORY_RAW,
            )
            self.canvas_fps_slider = gui.add_slider(
                "Canvas frames/s cap",
                min=1,
                max=30,
                step=1,
                initial_value=min(30, max(1, round(self.config.canvas_fps))),
            )
        self.maps_folder = gui.add_folder("Maps", visible=False)
        with gui.add_folder("Session", expand_by_default=False):
            self.session_markdown = gui.add_markdown("Not recording yet (draw a box).")
            self.download_tracks_button = gui.add_button("Download tracks (zip)")
            self.download_poses_button = gui.add_button("Download poses (TUM)")
            self.download_mcap_button = gui.add_button("Download session (MCAP)")
            self.sessions_dropdown = gui.add_dropdown("Sessions", options=("(none)",))
            self.refresh_sessions_button = gui.add_button("Refresh sessions")
            self.reopen_button = gui.add_button("Reopen and continue")

        self.open_selected_button.on_click(lambda _: self._submit(self._open_selected))
        self.refresh_sequences_button.on_click(lambda _: self._submit(self._refresh_sequences))
        self.open_path_button.on_click(lambda _: self._submit(self._open_typed_path))
        self.apply_scene_button.on_click(lambda _: self._submit(self._apply_scene))
        self.upload_button.on_upload(
            lambda _: self.receive_upload(
                self.upload_button.value.name, self.upload_button.value.content
            )
        )
        self.draw_dropdown.on_update(self._user_edit(self._select_target))
        self.landmark_dropdown.on_update(self._user_edit(self._assign_landmark))
        self.apply_box_button.on_click(lambda _: self._submit(self._apply_typed_box))
        self.delete_button.on_click(lambda _: self._submit(self._delete_selected))
        self.boxes_json_button.on_click(lambda _: self._submit(self._load_boxes_json))
        self.play_button.on_click(lambda _: self._submit(self._toggle_play))
        self.step_back_button.on_click(lambda _: self._submit(self._step, -1))
        self.step_button.on_click(lambda _: self._submit(self._step, 1))
        self.frame_slider.on_update(self._user_edit(self._seek_to_slider))
        self.canvas_dropdown.on_update(self._user_edit(self._canvas_mode_changed))
        self.maps_dropdown.on_update(self._user_edit(self._maps_changed))
        self.canvas_fps_slider.on_update(self._user_edit(self._wake_display))
        self.trajectory_dropdown.on_update(self._user_edit(self._maps_changed))
        self.download_tracks_button.on_click(lambda _: self._submit(self._download, "tracks"))
        self.download_poses_button.on_click(lambda _: self._submit(self._download, "poses"))
        self.download_mcap_button.on_click(lambda _: self._submit(self._download, "mcap"))
        self.refresh_sessions_button.on_click(lambda _: self._submit(self._refresh_sessions))
        self.reopen_button.on_click(lambda _: self._submit(self._reopen_selected))

    def _user_edit(self, command: Callable[[], None]) -> Callable[[Any], None]:
        """An on_update callback that queues `command` unless the app itself wrote the value."""

        def callback(_event: Any) -> None:
            if getattr(self._quiet, "active", False):
                return
            self._submit(command)

        return callback

    def _set(self, handle: Any, attribute: str, value: Any) -> None:
        """Write a widget property without triggering this tab's own callbacks."""
        self._quiet.active = True
        try:
            setattr(handle, attribute, value)
        finally:
            self._quiet.active = False

    # -- the worker ---------------------------------------------------------------------------

    def _submit(self, command: Callable[..., None], *args: Any) -> None:
        with self._pending_lock:
            self._pending += 1
        self._commands.put(lambda: command(*args))

    def wait_idle(self, timeout: float = 60.0) -> bool:
        """Block until every queued command ran and playback stopped; False on timeout."""
        deadline = time.monotonic() + timeout
        with self._pending_lock:
            while self._pending > 0 or self.playing:
                remaining = deadline - time.monotonic()
                if remaining <= 0:
                    return False
                self._pending_lock.wait(remaining)
        return True

    def _work(self) -> None:
        next_step = time.monotonic()
        while True:
            wait = None
            if self.playing:
                wait = max(0.0, next_step - time.monotonic())
            try:
                command = self._commands.get(timeout=wait)
            except queue.Empty:
                command = None
                started = time.monotonic()
                self._guarded(self._play_step)
                next_step = started + self._frame_period()
                continue
            if command is None:
                return
            self._guarded(command)
            with self._pending_lock:
                self._pending -= 1
                self._pending_lock.notify_all()

    def _guarded(self, command: Callable[[], None]) -> None:
        try:
            command()
        except AutoTrackError as error:
            self._stop_playing()
            self._say(str(error), error=True)
        except Exception as error:  # a bug must not kill the tab's worker
            self._stop_playing()
            traceback.print_exc(file=sys.stderr)
            self._say(f"internal error: {type(error).__name__}: {error}", error=True)
        self._after_command()

    def _frame_period(self) -> float:
        if self.unlimited_checkbox.value:
            return 0.0
        return 1.0 / max(1.0, float(self.speed_slider.value))

    def _say(self, message: str, *, error: bool = False) -> None:
        self._message = message
        if error:
            self.channel.notify("AutoTrack Studio", message, error=True)
        if self.run is None:
            self._set(self.status, "content", message)
        self._publish()

    def _after_command(self) -> None:
        run = self.run
        path = None if run is None else run.session_path
        if path is not None and path != self._claimed:
            self.studio.claim_recording(path, self.tab_id)
            self._claimed = path
            self._set(self.session_markdown, "content", f"Recording to `{path.name}`")
        self._publish()

    # -- opening sequences --------------------------------------------------------------------

    def open_initial(self) -> None:
        """Queue the start-up sequence (the configured one, else the demo)."""
        self._submit(self._refresh_sequences)
        self._submit(self._refresh_sessions)
        sequence = self.config.sequence or self.config.demo_dir
        self._submit(self._open, sequence, self.config.scene)

    def _refresh_sequences(self) -> None:
        found = find_sequences(self.roots)
        self._sequence_choices = {display_name(path, self.roots): path for path in found}
        options = tuple(self._sequence_choices) or ("(none)",)
        self._set(self.sequence_dropdown, "options", options)

    def _open_selected(self) -> None:
        path = self._sequence_choices.get(self.sequence_dropdown.value)
        if path is None:
            raise InputError("choose a sequence from the list first")
        self._open(path, None)

    def _open_typed_path(self) -> None:
        self._open(resolve_user_path(self.path_text.value, self.roots), None)

    def _apply_scene(self) -> None:
        if self.sequence_path is None:
            raise InputError("open a sequence first")
        text = self.scene_text.value.strip()
        scene = resolve_user_path(text, self.roots) if text else None
        self._open(self.sequence_path, scene, scene_given=True)

    def receive_upload(self, file_name: str, content: bytes) -> None:
        """An uploaded video or zip of images: stored safely, then opened (queued)."""
        self._submit(self._open_upload, file_name, content)

    def _open_upload(self, file_name: str, content: bytes) -> None:
        path = store_upload(file_name, content, self.config.upload_dir, self.config.upload_limits)
        self._refresh_sequences()
        self._open(path, None)

    def _close_run(self) -> None:
        if self.run is None:
            return
        path = self.run.session_path
        self.run.close()
        self.run.frames.close()
        if path is not None:
            self.studio.release_recording(path)
        self.run = None
        self._claimed = None

    def _open(self, path: Path, scene_path: Path | None, *, scene_given: bool = False) -> None:
        self._stop_playing()
        frames = open_frames(path)
        if len(frames) == 0:
            raise InputError(f"{path} holds no frames")
        frames.read(0)
        folder = path if path.is_dir() else path.parent
        if scene_path is None and not scene_given and (folder / "scene.json").is_file():
            scene_path = folder / "scene.json"
        scene = load_scene(scene_path) if scene_path is not None else None
        gt_positions = self._ground_truth_positions(scene_path)
        self._close_run()
        self.run = TrackingRun(
            frames,
            source=str(path),
            params=preset(self.preset_dropdown.value),
            scene=scene,
            scene_path=scene_path,
            sessions_dir=self.config.sessions_dir,
            tracker_threads=self.config.tracker_threads,
        )
        self.sequence_path = path
        self.scene_path = scene_path
        boxes = folder / "boxes.json"
        self.boxes_path = boxes if boxes.is_file() and scene is not None else None
        self.cursor = 0
        self.selected = NEW_TARGET
        self._set(self.boxes_json_button, "visible", self.boxes_path is not None)
        self._set(self.frame_slider, "max", max(2, len(frames)))
        self._set(self.frame_slider, "value", 1)
        self._set(self.scene_text, "value", "" if scene_path is None else str(scene_path))
        self._set(self.path_text, "value", str(path))
        self._set(self.session_markdown, "content", "Not recording yet (draw a box).")
        self.view3d.show_scene(scene, gt_positions)
        self._aim_camera()
        self._refresh_targets()
        self._canvas_dirty = True
        landmarks = "" if scene is None else f", scene with {len(scene.landmarks)} landmarks"
        self._message = f"Opened {display_name(path, self.roots)}: {len(frames)} frames{landmarks}."

    @staticmethod
    def _ground_truth_positions(scene_path: Path | None) -> np.ndarray | None:
        if scene_path is None:
            return None
        tum = scene_path.parent / "poses_gt.tum"
        if not tum.is_file():
            return None
        _stamps, positions, _quaternions = read_tum(tum)
        return positions

    def _aim_camera(self) -> None:
        eye, centre = self.view3d.viewpoint()
        self.channel.look_at(eye, centre, np.array([0.0, 0.0, 1.0]))

    # -- targets ------------------------------------------------------------------------------

    def _require_run(self) -> TrackingRun:
        if self.run is None:
            raise InputError("open a sequence first")
        return self.run

    def handle_rect_select(self, event: viser.SceneRectSelectEvent) -> None:
        """A shift-drag on the canvas: a box at the current frame (queued for the worker)."""
        if self.canvas_dropdown.value != CANVAS_FRAME:
            self._submit(self._say, "switch the canvas to 'frame' to draw boxes")
            return
        self._submit(self._draw_from_screen, event.screen_min, event.screen_max)

    def _draw_from_screen(
        self, screen_min: tuple[float, float], screen_max: tuple[float, float]
    ) -> None:
        run = self._require_run()
        letterbox = self.letterbox
        if letterbox is None or (letterbox.frame_width, letterbox.frame_height) != (
            run.frames.frame_size
        ):
            # The canvas still shows another sequence's frame: map as the next one will show.
            letterbox = fit_letterbox(
                run.frames.frame_size, self.channel.canvas_size() or DEFAULT_CANVAS_SIZE
            )
        box = letterbox.rect_to_box(screen_min, screen_max)
        if box is None:
            raise InputError("the dragged box misses the frame or is too thin; drag again")
        self._place(box)

    def _place(self, box: tuple[float, float, float, float]) -> None:
        run = self._require_run()
        self._stop_playing()
        if self.selected == NEW_TARGET:
            target_id = run.add_target(self.cursor, box)
            landmark = run.targets[target_id].landmark_id
            tied = f" → landmark {landmark}" if landmark else ""
            self._message = f"{target_id}{tied} drawn at frame {self.cursor + 1}."
        else:
            corrected = self.cursor in run.targets[self.selected].results
            run.place_box(self.selected, self.cursor, box)
            verb = "corrected" if corrected else "drawn"
            self._message = (
                f"{self.selected} {verb} at frame {self.cursor + 1}; it re-tracks from here."
            )
        self._refresh_targets()

    def _apply_typed_box(self) -> None:
        self._place(parse_box(self.box_text.value))

    def _select_target(self) -> None:
        self.selected = self.draw_dropdown.value
        self._refresh_targets()

    def _assign_landmark(self) -> None:
        run = self._require_run()
        if self.selected == NEW_TARGET:
            return
        value = self.landmark_dropdown.value
        run.assign_landmark(self.selected, None if value == NO_LANDMARK else value, self.cursor)
        self._refresh_targets()

    def _delete_selected(self) -> None:
        run = self._require_run()
        if self.selected == NEW_TARGET:
            raise InputError("choose the target to delete in 'Drag draws' first")
        run.delete_target(self.selected, self.cursor)
        self._message = f"Deleted {self.selected}."
        self.selected = NEW_TARGET
        self._refresh_targets()

    def _load_boxes_json(self) -> None:
        run = self._require_run()
        if self.boxes_path is None:
            raise InputError("this sequence has no boxes.json")
        try:
            boxes = json.loads(self.boxes_path.read_text(encoding="utf-8"))
        except (OSError, json.JSONDecodeError) as error:
            raise InputError(f"cannot read {self.boxes_path}: {error}") from None
        self._stop_playing()
        self.cursor = 0
        for landmark_id, box in boxes.items():
            if len(box) != 4:
                raise InputError(f"{self.boxes_path}: box of {landmark_id} is not [x, y, w, h]")
            run.add_target(0, tuple(float(v) for v in box), landmark_id=str(landmark_id))
        self._message = f"Loaded {len(boxes)} boxes from boxes.json on frame 1."
        self._refresh_targets()

    def _refresh_targets(self) -> None:
        run = self.run
        targets = [] if run is None else list(run.targets.values())
        ids = [target.id for target in targets]
        if self.selected not in ids:
            self.selected = NEW_TARGET
        self._set(self.draw_dropdown, "options", (NEW_TARGET, *ids))
        self._set(self.draw_dropdown, "value", self.selected)
        landmarks = () if run is None or run.scene is None else run.scene.landmark_ids
        self._set(self.landmark_dropdown, "options", (NO_LANDMARK, *landmarks))
        chosen = None if run is None else run.targets.get(self.selected)
        self._set(
            self.landmark_dropdown,
            "value",
            NO_LANDMARK if chosen is None or chosen.landmark_id is None else chosen.landmark_id,
        )
        self._set(self.landmark_dropdown, "disabled", chosen is None)
        self._set(self.delete_button, "disabled", chosen is None)
        if chosen is not None and self.cursor in chosen.results:
            self._set(self.box_text, "value", format_box(chosen.results[self.cursor].box))
        if not targets:
            text = "No targets yet. Shift-drag on the frame to draw one."
        else:
            rows = ["| target | landmark | box at this frame | tracked to |", "|---|---|---|---|"]
            for target in targets:
                result = target.results.get(self.cursor)
                box = "—" if result is None else format_box(result.box)
                landmark = target.landmark_id or "—"
                rows.append(f"| {target.id} | {landmark} | {box} | {target.last_frame + 1} |")
            text = "\n".join(rows)
        self._set(self.targets_markdown, "content", text)

    # -- playback -----------------------------------------------------------------------------

    def _toggle_play(self) -> None:
        if self.playing:
            self._stop_playing()
            return
        run = self._require_run()
        if self.cursor >= run.frame_count - 1:
            raise InputError("already at the last frame")
        self.playing = True
        self._set(self.play_button, "label", "Pause")
        self._set(self.play_button, "icon", viser.Icon.PLAYER_PAUSE)

    def _stop_playing(self) -> None:
        if not self.playing:
            return
        with self._pending_lock:
            self.playing = False
            self._pending_lock.notify_all()
        self._set(self.play_button, "label", "Play")
        self._set(self.play_button, "icon", viser.Icon.PLAYER_PLAY)
        self._refresh_targets()

    def _play_step(self) -> None:
        run = self.run
        if run is None or self.cursor >= run.frame_count - 1:
            self._stop_playing()
            return
        self._visit(self.cursor + 1)
        if self.cursor >= run.frame_count - 1:
            self._stop_playing()

    def _visit(self, frame_index: int) -> None:
        """Move to `frame_index`, tracking there first when it is the next frame."""
        run = self._require_run()
        if frame_index == self.cursor + 1:
            run.track_to(frame_index)
            run.advance(frame_index)
        self.cursor = frame_index
        self._set(self.frame_slider, "value", frame_index + 1)
        self._publish()

    def _step(self, delta: int) -> None:
        run = self._require_run()
        self._stop_playing()
        target = min(max(self.cursor + delta, 0), run.frame_count - 1)
        if target != self.cursor:
            self._visit(target)
        self._refresh_targets()

    def _seek_to_slider(self) -> None:
        run = self._require_run()
        target = min(max(int(self.frame_slider.value) - 1, 0), run.frame_count - 1)
        if run.targets and target > self.cursor:
            # Track through the frames in between, showing them; a new command interrupts.
            while self.cursor < target and self._commands.empty():
                self._visit(self.cursor + 1)
        else:
            self._visit(target)
        self._refresh_targets()

    # -- display ------------------------------------------------------------------------------

    def _canvas_mode_changed(self) -> None:
        self._canvas_dirty = True
        if self.canvas_dropdown.value == CANVAS_3D:
            self._aim_camera()

    def _maps_changed(self) -> None:
        self._set(self.maps_folder, "visible", self.maps_dropdown.value == MAPS_PANELS)
        self._canvas_dirty = True

    def _canvas_changed(self) -> None:
        size = self.channel.canvas_size()
        letterbox = self.letterbox
        if letterbox is None or size is None:
            return
        expected = fit_letterbox((letterbox.frame_width, letterbox.frame_height), size)
        if expected != letterbox:
            self._wake_display(canvas=True)

    def _wake_display(self, canvas: bool = False) -> None:
        with self._view_lock:
            if canvas:
                self._canvas_dirty = True
            self._view_lock.notify_all()

    def _publish(self) -> None:
        """Snapshot the run at the cursor for the display thread."""
        run = self.run
        if run is None:
            return
        frame_index = self.cursor
        drawings: list[TargetDrawing] = []
        signals: dict[str, dict[str, np.ndarray]] = {}
        colours: list[tuple[int, int, int]] = []
        for target in run.targets.values():
            colour = target_colour(target.number - 1)
            colours.append(colour)
            signals[target.id] = {name: values.copy() for name, values in target.signals.items()}
            result = target.results.get(frame_index)
            if result is None:
                continue
            label = target.id if target.landmark_id is None else f"{target.id}:{target.landmark_id}"
            drawings.append(
                TargetDrawing(
                    label=label,
                    colour=colour,
                    box=result.box,
                    result=result,
                    selected=target.id == self.selected,
                )
            )
        pose_view = None
        if run.scene is not None:
            trajectory = list(run.valid_positions())
            if self.trajectory_dropdown.value == TRAJECTORY_SMOOTHED:
                fps = run.frames.fps or 10.0
                trajectory = smoothed_positions(run.poses, SmootherParams(fps=fps))
            pose = run.poses.get(frame_index)
            last_valid = next(
                (
                    run.poses[index]
                    for index in sorted(run.poses, reverse=True)
                    if index <= frame_index and run.poses[index].valid
                ),
                None,
            )
            pose_view = PoseView(
                frame_index=frame_index,
                pose=pose,
                last_valid=last_valid,
                trajectory_frames=tuple(index for index, _ in trajectory),
                trajectory_positions=np.array([position for _, position in trajectory]).reshape(
                    -1, 3
                ),
            )
        history = SignalHistory(
            target_ids=tuple(run.targets),
            colours=tuple(colours),
            signals=signals,
            frame_seconds=run.frame_seconds.copy(),
            phi=run.params.phi,
            last_frame=run.furthest_frame,
            frame_count=run.frame_count,
        )
        status = self._status_text(run, pose_view)
        with self._view_lock:
            self._version += 1
            self._view = FrameView(
                version=self._version,
                frame_index=frame_index,
                frame_count=run.frame_count,
                frame=run.frame(frame_index),
                drawings=tuple(drawings),
                pose_view=pose_view,
                history=history,
                status=status,
            )
            self.stats.views_published += 1
            self._view_lock.notify_all()

    def _status_text(self, run: TrackingRun, pose_view: PoseView | None) -> str:
        parts = [
            f"**{run.frames.name}** · frame {self.cursor + 1} / {run.frame_count}",
            f"tracked to {run.tracked_until + 1}" if run.targets else "no targets",
        ]
        pose = None if pose_view is None else pose_view.pose
        if pose is not None:
            parts.append(pose_text(pose))
        text = " · ".join(parts)
        if self._message:
            text += f"\n\n{self._message}"
        return text

    def _display_loop(self) -> None:
        shown_video = shown_canvas = shown_slow = -1
        last_video = last_canvas = last_slow = 0.0
        mode_shown: str | None = None
        while True:
            with self._view_lock:
                while True:
                    if self._closed:
                        return
                    view = self._view
                    now = time.monotonic()
                    canvas_period = 1.0 / max(1.0, float(self.canvas_fps_slider.value))
                    mode = self.canvas_dropdown.value
                    due: list[float] = []
                    if view is not None and view.version != shown_video:
                        due.append(last_video + 1.0 / GUI_FPS)
                    if view is not None and view.version != shown_slow:
                        due.append(last_slow + 1.0 / SLOW_FPS)
                    if (
                        view is not None
                        and mode == CANVAS_FRAME
                        and (view.version != shown_canvas or self._canvas_dirty)
                    ):
                        due.append(last_canvas + canvas_period)
                    if mode != mode_shown:
                        due.append(now)
                    if due and min(due) <= now:
                        break
                    self._view_lock.wait(None if not due else min(due) - now)
            try:
                if mode != mode_shown:
                    self._show_canvas_mode(mode)
                    mode_shown = mode
                if view is None:
                    continue
                maps = self.maps_dropdown.value
                if view.version != shown_video and now >= last_video + 1.0 / GUI_FPS:
                    self.video.image = self._picture(view, maps, VIDEO_MAX_WIDTH)
                    self.stats.video_frames += 1
                    self.stats.video_times.append(now)
                    if maps in (MAPS_RESPONSE, MAPS_VARIATION) and any(
                        drawing.result is not None and drawing.result.response_map is not None
                        for drawing in view.drawings
                    ):
                        self.stats.overlay_maps += 1
                    shown_video, last_video = view.version, now
                if (
                    mode == CANVAS_FRAME
                    and (view.version != shown_canvas or self._canvas_dirty)
                    and now >= last_canvas + canvas_period
                ):
                    self._send_canvas(view, maps)
                    shown_canvas, last_canvas = view.version, now
                if view.version != shown_slow and now >= last_slow + 1.0 / SLOW_FPS:
                    self._send_slow(view, maps)
                    shown_slow, last_slow = view.version, now
            except Exception:  # the display must keep running whatever one view contained
                traceback.print_exc(file=sys.stderr)
                if view is not None:
                    shown_video = shown_canvas = shown_slow = view.version
                last_video = last_canvas = last_slow = time.monotonic()
                self._canvas_dirty = False

    @staticmethod
    def _picture(view: FrameView, maps: str, max_width: int | None) -> np.ndarray:
        kind = {MAPS_RESPONSE: "response", MAPS_VARIATION: "local_variation"}.get(maps, "none")
        return draw_overlays(view.frame, view.drawings, kind, max_width)

    def _send_canvas(self, view: FrameView, maps: str) -> None:
        size = self.channel.canvas_size() or DEFAULT_CANVAS_SIZE
        height, width = view.frame.shape[:2]
        letterbox = fit_letterbox((width, height), size)
        # Drawn at full size and padded in frame pixels, then scaled as a whole: canvas
        # fractions map to frame pixels exactly through `letterbox`.
        picture = self._picture(view, maps, None)
        image = letterbox_image(picture, letterbox, min(CANVAS_MAX_WIDTH, max(size[0], 320)))
        self.scene_api.set_background_image(image, format="jpeg", jpeg_quality=80)
        self.letterbox = letterbox
        self._canvas_dirty = False
        self.stats.canvas_frames += 1
        self.stats.canvas_times.append(time.monotonic())

    def _show_canvas_mode(self, mode: str) -> None:
        if mode == CANVAS_FRAME:
            self.scene_api.set_global_visibility(False)
            self._canvas_dirty = True
        else:
            self.scene_api.set_background_image(None)
            self.scene_api.set_global_visibility(True)

    def _send_slow(self, view: FrameView, maps: str) -> None:
        self._set(self.status, "content", view.status)
        self.plots.update(view.history)
        self.stats.plot_updates += 1
        if view.pose_view is not None:
            self.view3d.update(view.pose_view, thumbnail(view.frame))
            self.stats.scene_updates += 1
        self._update_map_panels(view, maps == MAPS_PANELS)

    def _update_map_panels(self, view: FrameView, shown: bool) -> None:
        labels = {drawing.label.split(":")[0]: drawing for drawing in view.drawings}
        for target_id in [tid for tid in self._map_panels if tid not in labels or not shown]:
            self._map_panels.pop(target_id).remove()
        if not shown:
            return
        gap = np.full((160, 4, 3), 255, np.uint8)
        for target_id, drawing in labels.items():
            result = drawing.result
            response = None if result is None else result.response_map
            variation = None if result is None else result.local_variation
            image = np.concatenate([map_panel(response), gap, map_panel(variation)], axis=1)
            handle = self._map_panels.get(target_id)
            if handle is None:
                with self.maps_folder:
                    self._map_panels[target_id] = self.gui.add_image(
                        image,
                        label=f"{target_id}: response | local variation",
                        format="png",
                    )
            else:
                handle.image = image
            self.stats.map_panel_updates += 1

    # -- sessions -----------------------------------------------------------------------------

    def _refresh_sessions(self) -> None:
        files = sorted(
            self.config.sessions_dir.glob("*.mcap"), key=lambda p: p.stat().st_mtime, reverse=True
        )
        self._session_choices = {path.name: path for path in files}
        self._set(self.sessions_dropdown, "options", tuple(self._session_choices) or ("(none)",))

    def _reopen_selected(self) -> None:
        path = self._session_choices.get(self.sessions_dropdown.value)
        if path is None:
            raise InputError("choose a session from the list first (Refresh sessions)")
        owner = self.studio.recorded_by(path)
        if owner is not None:
            raise InputError(f"{path.name} is being recorded by another tab; reopen it later")
        session = open_session(path)
        source = resolve_user_path(str(session.metadata.get("source", "")), self.roots)
        scene_text = session.metadata.get("scene_path")
        scene_path = resolve_user_path(str(scene_text), self.roots) if scene_text else None
        self._open(source, scene_path, scene_given=True)
        run = self._require_run()
        resume_frame = run.restore(session, last_state(session), path)
        self.cursor = resume_frame
        self._set(self.frame_slider, "value", resume_frame + 1)
        self._refresh_targets()
        note = " (the file was cut short)" if session.truncated else ""
        self._message = (
            f"Reopened {path.name}{note}: {len(run.targets)} targets, continuing from frame "
            f"{resume_frame + 1}; recording to a new session file."
        )

    def _download(self, what: str) -> None:
        run = self._require_run()
        path = run.session_path
        if path is None or run.recorder is None:
            raise InputError("nothing recorded yet: draw a box and track first")
        run.recorder.flush()
        if what == "tracks":
            name, content = f"{path.stem}_tracks.zip", exports.tracks_zip(path)
        elif what == "poses":
            name, content = f"{path.stem}_poses.tum", exports.poses_tum(path)
        else:
            name, content = path.name, path.read_bytes()
        self.channel.download(name, content)
        self._message = f"Sent {name} ({len(content) / 1024:.0f} kB)."

    # -- lifecycle ----------------------------------------------------------------------------

    def close(self) -> None:
        """Stop the threads and finish the recording (the tab's browser went away)."""
        with self._view_lock:
            self._closed = True
            self._view_lock.notify_all()
        self.playing = False
        self._commands.put(None)
        self._worker.join(timeout=30.0)
        self._display.join(timeout=10.0)
        self._close_run()
        self.view3d.clear()


def pose_text(pose: PoseEstimate) -> str:
    """One line about a pose for the status bar."""
    if not pose.valid:
        return f"pose invalid: {pose.reason}"
    x, y, z = (float(v) for v in pose.position)
    return f"camera at ({x:.2f}, {y:.2f}, {z:.2f}) m, {pose.rms_error_px:.2f} px RMS"
