"""A tab's display thread: turns the latest `FrameView` into what the browser gets.

The worker publishes a view per frame; this thread sends the video panel (JPEG, every view up
to `GUI_FPS`), the 3-D canvas background (letterboxed, capped at the user's canvas rate because
software WebGL draws only a few per second), and the status, plots, map panels and 3-D view
(`SLOW_FPS`). Views it had no time for are skipped, so a slow browser never slows tracking.
"""

from __future__ import annotations

import sys
import threading
import time
import traceback
from collections import deque
from dataclasses import dataclass, field

import numpy as np
import viser

from autotrack_studio.canvas import (
    Letterbox,
    draw_overlays,
    fit_letterbox,
    letterbox_image,
    map_tile,
    thumbnail,
)
from autotrack_studio.channel import ClientChannel
from autotrack_studio.groundtruth import pose_errors
from autotrack_studio.panels import (
    CANVAS_3D,
    CANVAS_FRAME,
    MAP_KINDS,
    MAPS_PANELS,
    TRAJECTORY_SMOOTHED,
    ZOOM_FOLLOW,
    Panels,
)
from autotrack_studio.plots import SignalPlots
from autotrack_studio.truthplots import TruthPlots
from autotrack_studio.view3d import SceneView, view3d_legend
from autotrack_studio.views import FrameView, smoothed_view
from autotrack_studio.zoom import CanvasMapping, ZoomWindow, canvas_mapping, zoom_window

GUI_FPS = 30.0
"""Most video-panel updates per second (viser keeps only the latest anyway)."""
SLOW_FPS = 5.0
"""Most status, plot, map-panel and 3-D updates per second."""
PLAYING_SLOW_FPS = 2.0
"""The same while playing: the browser shares the machine's cores with the trackers (headless
Chromium drew the demo's playback with 0.65 of a core), and charts redrawn more often than
this do not read any better while they scroll."""


def send_periods(
    playing: bool, canvas_shows_frame: bool, canvas_period: float
) -> tuple[float, float]:
    """(video panel, slow updates) periods in seconds. While playing with the frame on the
    canvas, the video panel (the same picture, smaller) follows the canvas's rate, and the
    slow updates come PLAYING_SLOW_FPS times a second: what the browser draws is what takes
    the trackers' CPU. Paused, everything is sent at its full rate."""
    if not playing:
        return 1.0 / GUI_FPS, 1.0 / SLOW_FPS
    video = max(1.0 / GUI_FPS, canvas_period) if canvas_shows_frame else 1.0 / GUI_FPS
    return video, 1.0 / PLAYING_SLOW_FPS


VIDEO_MAX_WIDTH = 640
"""Largest width of the video-panel image (pixels): the panel is narrow, and drawing on a
smaller image leaves the CPU to the tracker."""
CANVAS_MAX_WIDTH = 1280
"""Largest width of the letterboxed canvas background (pixels)."""
DEFAULT_CANVAS_SIZE = (1280, 720)
"""Canvas size assumed until the browser reports one."""
TIMES_KEPT = 2000
"""Send times kept per kind for measuring display rates."""


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
    video_targets: tuple[int, tuple[str, ...]] = (-1, ())
    """The last video-panel frame sent: its index and the targets whose boxes it shows."""


def map_panel_image(view: FrameView, target_id: str) -> np.ndarray:
    """A target's map panel, 2 x 2: the previous and the current response (min-max), the local
    variation (robust scale) and the ASR spatial weights the filter trained with (log10)."""
    drawing = view.drawings[target_id]
    result = drawing.result
    tiles = (
        map_tile(drawing.previous_response, "previous response"),
        map_tile(None if result is None else result.response_map, "response"),
        map_tile(None if result is None else result.local_variation, "local variation", "robust"),
        map_tile(
            drawing.weights, weights_title(drawing.weights, drawing.weights_frame, view), "log"
        ),
    )
    gap = np.full((tiles[0].shape[0], 4, 3), 255, np.uint8)
    rows = [np.concatenate([tiles[i], gap, tiles[i + 1]], axis=1) for i in (0, 2)]
    return np.concatenate([rows[0], np.full((4, rows[0].shape[1], 3), 255, np.uint8), rows[1]])


def missing_map_note(view: FrameView, map_kind: str | None) -> str:
    """A line for the status when the chosen overlay has nothing to show on this frame (no
    target has that map yet: a box's first frame has no detection, the local variation also
    needs the frame before it), so an empty overlay is not taken for a broken one."""
    if map_kind is None or not view.drawings:
        return ""
    results = [d.result for d in view.drawings.values() if d.result is not None]
    field = "response_map" if map_kind == "response" else "local_variation"
    if any(getattr(result, field) is not None for result in results):
        return ""
    name = "response" if map_kind == "response" else "local-variation"
    return (
        f"\n\nNo {name} map on this frame yet: a target has one once it was tracked "
        "from the frame before (step forward)."
    )


def weights_title(weights: np.ndarray | None, trained: int | None, view: FrameView) -> str:
    """The ASR tile's title: says when the weights are those of an earlier frame's training,
    and when there are none (a tracker that learns no filter, such as NanoTrack)."""
    if weights is None:
        return "no ASR weights"
    if trained is None or trained == view.frame_index:
        return "ASR weights u"
    return f"ASR u (trained frame {trained + 1})"


class MapPanels:
    """One image per target with its maps, in the Display panel's Maps folder."""

    def __init__(self, gui: viser.GuiApi, folder: viser.GuiFolderHandle) -> None:
        self.gui = gui
        self.folder = folder
        self._images: dict[str, viser.GuiImageHandle] = {}

    def shown(self) -> dict[str, np.ndarray]:
        """Target id -> the image its panel shows now."""
        return {target_id: handle.image for target_id, handle in self._images.items()}

    def update(self, view: FrameView, shown: bool) -> int:
        """Show (or, when not `shown`, remove) the panels of the view's targets; returns how
        many panels were sent."""
        for target_id in [t for t in self._images if t not in view.drawings or not shown]:
            self._images.pop(target_id).remove()
        if not shown:
            return 0
        for target_id in view.drawings:
            image = map_panel_image(view, target_id)
            handle = self._images.get(target_id)
            if handle is None:
                with self.folder:
                    self._images[target_id] = self.gui.add_image(
                        image, label=f"{target_id} maps", format="png"
                    )
            else:
                handle.image = image
        return len(view.drawings)


def picture(
    view: FrameView,
    maps: str,
    max_width: int | None,
    show_truth: bool = False,
    map_opacity: float = 0.7,
) -> np.ndarray:
    """The view's frame with boxes, labels, peaks, the chosen map and (`show_truth`) the
    ground-truth box drawn."""
    kind = MAP_KINDS.get(maps, "none")
    truths = [(t.box, t.label) for t in view.truths if t.box is not None] if show_truth else []
    drawings = list(view.drawings.values())
    return draw_overlays(view.frame, drawings, kind, max_width, map_opacity, truths)


class DisplayLoop:
    """The display thread of one tab (see the module docstring)."""

    def __init__(
        self,
        panels: Panels,
        gui: viser.GuiApi,
        scene_api: viser.SceneApi,
        channel: ClientChannel,
        *,
        name: str,
        max_targets: int = 4,
    ) -> None:
        self.panels = panels
        self.scene_api = scene_api
        self.channel = channel
        self.plots = SignalPlots(gui, panels.debug.signals, slots=max_targets)
        self.truth_plots = TruthPlots(gui, panels.debug.truth)
        self.view3d = SceneView(scene_api)
        self.map_panels = MapPanels(gui, panels.display.maps_folder)
        self.stats = DisplayStats()
        self.letterbox: Letterbox | None = None
        """How the last canvas background placed the frame's shown window."""
        self.mapping: CanvasMapping | None = None
        """How the last canvas background maps canvas fractions to frame pixels (zoomed)."""
        self._mapped_frame: tuple[int, int] | None = None
        self.zoom_centre: tuple[float, float] | None = None
        """Where the zoomed canvas is centred (frame pixels; None: the frame's centre)."""
        self._lock = threading.Condition()
        self._view: FrameView | None = None
        self._version = 0
        self._canvas_dirty = True
        self._closed = False
        self._thread = threading.Thread(target=self._loop, name=name, daemon=True)
        self._thread.start()

    def publish(self, view: FrameView) -> None:
        """Show `view` next (replacing any view not shown yet)."""
        with self._lock:
            self._view = view
            self._version += 1
            self.stats.views_published += 1
            self._lock.notify_all()

    def wake(self, *, canvas: bool = False) -> None:
        """Look at the settings again (`canvas`: send the canvas background again)."""
        with self._lock:
            self._canvas_dirty = self._canvas_dirty or canvas
            self._lock.notify_all()

    def canvas_mapping(self, frame_size: tuple[int, int]) -> CanvasMapping:
        """How the canvas maps (or will map) a drag to pixels of a frame of `frame_size`."""
        mapping = self.mapping
        if mapping is None or self._mapped_frame != frame_size:
            # The canvas still shows another sequence's frame: map as the next one will show.
            size = self.channel.canvas_size() or DEFAULT_CANVAS_SIZE
            mapping = canvas_mapping(frame_size, size, self.zoom_window(frame_size))
        return mapping

    def zoom_window(self, frame_size: tuple[int, int], view: FrameView | None = None) -> ZoomWindow:
        """The window of the frame the canvas shows: the Zoom slider's scale, centred on the
        target chosen in Drag draws when *Zoom centre* follows it (and `view` has its box),
        else where the user last clicked."""
        display = self.panels.display
        centre = self.zoom_centre
        if view is not None and display.zoom_centre.value == ZOOM_FOLLOW:
            chosen = [d for d in view.drawings.values() if d.selected]
            if chosen:
                x, y, w, h = chosen[0].box
                centre = (x + w / 2.0, y + h / 2.0)
        return zoom_window(frame_size, float(display.zoom.value), centre)

    def canvas_resized(self) -> None:
        """The browser's canvas changed: resend the background if its letterbox changed."""
        size = self.channel.canvas_size()
        mapping = self.mapping
        if mapping is None or size is None:
            return
        window = mapping.window
        if fit_letterbox((window.width, window.height), size) != mapping.letterbox:
            self.wake(canvas=True)

    def close(self, timeout: float = 10.0) -> None:
        """Stop the thread and remove the 3-D scene."""
        with self._lock:
            self._closed = True
            self._view = None  # the last frame, its maps and plots: not kept past the tab
            self._lock.notify_all()
        self._thread.join(timeout=timeout)
        self.view3d.clear()

    # -- the thread ---------------------------------------------------------------------------

    def _loop(self) -> None:
        shown = {"video": -1, "canvas": -1, "slow": -1}
        last = {"video": 0.0, "canvas": 0.0, "slow": 0.0}
        mode_shown: str | None = None
        while True:
            woken = self._wait(shown, last, mode_shown)
            if woken is None:
                return
            view, version, mode, now = woken
            try:
                if mode != mode_shown:
                    self._show_canvas_mode(mode)
                    mode_shown = mode
                if view is not None:
                    self._send_due(view, version, mode, now, shown, last)
            except Exception:  # the display must keep running whatever one view contained
                traceback.print_exc(file=sys.stderr)
                shown = dict.fromkeys(shown, version)
                last = dict.fromkeys(last, time.monotonic())
                self._canvas_dirty = False

    def _canvas_period(self) -> float:
        return 1.0 / max(1.0, float(self.panels.display.canvas_fps.value))

    def _periods(self, view: FrameView | None, mode: str) -> tuple[float, float]:
        playing = view is not None and view.playing
        return send_periods(playing, mode == CANVAS_FRAME, self._canvas_period())

    def _wait(
        self, shown: dict[str, int], last: dict[str, float], mode_shown: str | None
    ) -> tuple[FrameView | None, int, str, float] | None:
        """Sleep until something is due; (view, its version, canvas mode, now), None when
        closed."""
        with self._lock:
            while True:
                if self._closed:
                    return None
                view, version, now = self._view, self._version, time.monotonic()
                mode = self.panels.display.canvas.value
                video_period, slow_period = self._periods(view, mode)
                due: list[float] = []
                if view is not None and version != shown["video"]:
                    due.append(last["video"] + video_period)
                if view is not None and version != shown["slow"]:
                    due.append(last["slow"] + slow_period)
                if (
                    view is not None
                    and mode == CANVAS_FRAME
                    and (version != shown["canvas"] or self._canvas_dirty)
                ):
                    due.append(last["canvas"] + self._canvas_period())
                if mode != mode_shown:
                    due.append(now)
                if due and min(due) <= now:
                    return view, version, mode, now
                self._lock.wait(None if not due else min(due) - now)

    def _send_due(
        self,
        view: FrameView,
        version: int,
        mode: str,
        now: float,
        shown: dict[str, int],
        last: dict[str, float],
    ) -> None:
        maps = self.panels.display.maps.value
        video_period, slow_period = self._periods(view, mode)
        if version != shown["video"] and now >= last["video"] + video_period:
            self.panels.video.image = picture(
                view, maps, VIDEO_MAX_WIDTH, self._show_truth(), self._opacity()
            )
            self.stats.video_frames += 1
            self.stats.video_times.append(now)
            self.stats.video_targets = (view.frame_index, tuple(view.drawings))
            if maps in MAP_KINDS and any(
                drawing.result is not None and drawing.result.response_map is not None
                for drawing in view.drawings.values()
            ):
                self.stats.overlay_maps += 1
            shown["video"], last["video"] = version, now
        if (
            mode == CANVAS_FRAME
            and (version != shown["canvas"] or self._canvas_dirty)
            and now >= last["canvas"] + self._canvas_period()
        ):
            self._send_canvas(view, maps)
            shown["canvas"], last["canvas"] = version, now
        if version != shown["slow"] and now >= last["slow"] + slow_period:
            self._send_slow(view, maps, mode)
            shown["slow"], last["slow"] = version, now

    def _send_canvas(self, view: FrameView, maps: str) -> None:
        size = self.channel.canvas_size() or DEFAULT_CANVAS_SIZE
        height, width = view.frame.shape[:2]
        mapping = canvas_mapping((width, height), size, self.zoom_window((width, height), view))
        # Drawn at full size, cut to the zoom window and padded in its pixels, then scaled as
        # a whole (never up: a zoomed window is sent at its own resolution): canvas fractions
        # map to frame pixels exactly through `mapping`.
        image = letterbox_image(
            mapping.window.crop(picture(view, maps, None, self._show_truth(), self._opacity())),
            mapping.letterbox,
            min(CANVAS_MAX_WIDTH, max(size[0], 320)),
        )
        self.scene_api.set_background_image(image, format="jpeg", jpeg_quality=80)
        self.letterbox, self.mapping, self._mapped_frame = (
            mapping.letterbox,
            mapping,
            (width, height),
        )
        self._canvas_dirty = False
        self.stats.canvas_frames += 1
        self.stats.canvas_times.append(time.monotonic())

    def _opacity(self) -> float:
        return float(self.panels.display.map_opacity.value)

    def _show_truth(self) -> bool:
        return bool(self.panels.targets.show_truth.value)

    def _show_canvas_mode(self, mode: str) -> None:
        if mode == CANVAS_3D:
            self.scene_api.set_background_image(None)
            self.scene_api.set_global_visibility(True)
        else:
            self.scene_api.set_global_visibility(False)
            self._canvas_dirty = True

    def _send_slow(self, view: FrameView, maps: str, mode: str) -> None:
        status = view.status + missing_map_note(view, MAP_KINDS.get(maps))
        self.panels.quiet.set(self.panels.status, "content", status)
        self.plots.update(view.history, view.frame_index)
        errors = None
        if view.truth_poses is not None and view.pose_view is not None:
            errors = pose_errors(view.truth_poses, view.pose_view.poses, view.pose_view.fps)
        self.truth_plots.update(view.truth, view.frame_index, view.truths, errors)
        legend = view3d_legend(view.truth_poses is not None, errors)
        if self.panels.display.legend.content != legend:
            self.panels.quiet.set(self.panels.display.legend, "content", legend)
        self.stats.plot_updates += 1
        if mode == CANVAS_3D:
            self._send_scene(view)
        self.stats.map_panel_updates += self.map_panels.update(view, maps == MAPS_PANELS)

    def _send_scene(self, view: FrameView) -> None:
        """The 3-D view's camera and trajectory, sent only while the canvas shows the 3-D view
        (the switch to it publishes a view, which brings it up to date): viser's client renders
        its canvas continuously for 250 ms after every scene message, hidden nodes or not, and
        under software WebGL those frames cost the browser ~90 ms of CPU each (docs/app.md)."""
        pose_view = view.pose_view
        if pose_view is None:
            return
        if self.panels.display.trajectory.value == TRAJECTORY_SMOOTHED:
            pose_view = smoothed_view(pose_view)
        self.view3d.update(pose_view, thumbnail(view.frame))
        self.stats.scene_updates += 1
