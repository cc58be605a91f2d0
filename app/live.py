"""A tab's live source (only on a server started with `--allow-live`): preview, freeze a frame,
draw the boxes on it, track the newest frame, stop into a recorded session.

The library does the live work: `autotrack.io.live.LiveReader` takes the source's frames at its
rate keeping the newest, `LiveLog` times each result, and `autotrack.pipeline.live.follow_live`
advances the tab's `Pipeline` over the newest frame each time it is free (a frame it had no time
for is dropped). `LiveControl` only sequences these for the tab, on the tab's worker thread,
and puts the live figures in the status line. The boxes are drawn on the frozen frame through
the controller's usual commands (drag, typed box, boxes.json), and the run is recorded with
its frames (a live source cannot be replayed); Stop reopens that recording to look through.
"""

from __future__ import annotations

import time
from collections.abc import Iterator
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from autotrack.errors import AutoTrackError, InputError
from autotrack.hybrid.factory import tracker_params
from autotrack.io.live import CapturedFrame, LiveFrames, LiveLog, LiveReader, describe_source
from autotrack.localization.scene import Scene, load_scene
from autotrack.params import preset
from autotrack.pipeline import Pipeline, Recording
from autotrack.pipeline.live import follow_live
from autotrack.pipeline.targets import FrameOutcome
from autotrack_studio.browser_text import markdown_literal
from autotrack_studio.controller import POSE_OPTIONS, TabController
from autotrack_studio.landmarks import boxes_json_boxes
from autotrack_studio.paths import display_name, live_source
from autotrack_studio.views import FrameView, SignalHistory

DISABLED_HINT = "Live sources are off on this server: restart it with `autotrack app --allow-live`."
DEFAULT_LIVE_FPS = 30.0
"""Log-time frame rate of a recording whose source announces none (a camera)."""
LATENCY_WINDOW = 30
"""Processed frames the status line's latency and rates cover."""
OFF, PREVIEW, FROZEN, TRACKING = "off", "preview", "frozen", "tracking"


@dataclass(frozen=True)
class LiveFigures:
    """What a live run did since Start (the frames dropped while the boxes were drawn on the
    frozen frame are not counted)."""

    captured: int
    """Frames the source delivered after the frozen one."""
    processed: int
    """Of those, frames tracked."""
    dropped: int
    """Of those, frames replaced by a newer one before the tracker was free (never tracked);
    the rest are tracked or, the newest, still to be."""
    capture_fps: float
    """Frames per second the source delivered."""
    processed_fps: float
    """Frames per second tracked (over the last LATENCY_WINDOW)."""
    latency_ms: float
    """Median capture-to-result latency of the last LATENCY_WINDOW tracked frames (ms)."""

    def text(self) -> str:
        """The status line's live part."""
        return (
            f"● live: capture {self.capture_fps:.1f} fps · processed {self.processed_fps:.1f} "
            f"fps · {self.processed} tracked, {self.dropped} dropped of {self.captured} · "
            f"latency {self.latency_ms:.0f} ms"
        )


class LiveControl:
    """One tab's live source and the commands on it (run by the tab's worker thread)."""

    def __init__(self, controller: TabController, allowed: bool) -> None:
        self.controller = controller
        self.allowed = allowed
        self.state = OFF
        self.source: Path | str | None = None
        self.scene_path: Path | None = None
        self._scene: Scene | None = None
        self.reader: LiveReader | None = None
        self.newest: CapturedFrame | None = None
        """The frame shown while previewing; the frozen frame once frozen."""
        self.log: LiveLog | None = None
        self.frames: LiveFrames | None = None
        self.run: Pipeline | None = None
        """The live run (the controller's run from Freeze until Stop)."""
        self._outcomes: Iterator[tuple[CapturedFrame, FrameOutcome]] | None = None
        self.started = (-1, 0.0)
        """At Start: the last frame the source had delivered, the reader's clock (s)."""
        self._last_result: float | None = None
        self.review_error = ""
        """Why the last recording could not be reopened to look through ('' if it was)."""

    @property
    def active(self) -> bool:
        """Whether the worker should call `step` (previewing or tracking)."""
        return self.state in (PREVIEW, TRACKING)

    # -- commands -----------------------------------------------------------------------------

    def open_source(self, text: str, scene_text: str = "") -> None:
        """Open the source typed by the user (and the scene file, if typed) and preview it."""
        if not self.allowed:
            raise InputError(DISABLED_HINT)
        controller = self.controller
        source = live_source(text, controller.roots)
        if isinstance(source, Path) and source.is_absolute():
            source = controller.resolve_path(str(source))  # not another browser's upload
        scene_path = controller.resolve_path(scene_text) if scene_text.strip() else None
        scene = None if scene_path is None else load_scene(scene_path)
        reader = LiveReader(source).start()  # a source that fails leaves the open run alone
        try:
            first = reader.next_frame()
            if first is None:
                raise InputError(f"{self._shown(source)} delivered no frame")
        except Exception:
            reader.close()
            raise
        self.halt()  # a live run open before is stopped and kept
        controller.stop_playing()
        controller.close_run()
        self.reader, self.source, self.newest = reader, source, first
        self.scene_path, self._scene = scene_path, scene
        self.state = PREVIEW
        controller.message = f"Live: {self._shown(source)}. Freeze a frame to draw the boxes on it."

    def step(self) -> None:
        """While previewing, show the newest frame; while tracking, track it."""
        if self.state == PREVIEW:
            frame = self._reader().next_frame()
            if frame is None:
                self.close()
                raise InputError(f"{self._shown(self.source)} ended (nothing was tracked)")
            self.newest = frame
        elif self.state == TRACKING:
            self._track_next()
        else:
            return
        if self.controller.on_visit is not None:
            self.controller.on_visit()

    def freeze(self) -> None:
        """Hold the frame shown: the boxes are drawn on it (drag, typed box, boxes.json)."""
        if self.state != PREVIEW or self.newest is None:
            raise InputError("open a live source first" if self.state == OFF else "already frozen")
        controller, frame = self.controller, self.newest
        frames = LiveFrames(self._shown(self.source), self._reader().fps)
        frames.take(frame)
        recording = Recording(
            source=str(self.source),
            directory=controller.space.sessions_dir,
            scene_path=self.scene_path,
            embed_frames=True,
        )
        run = Pipeline(
            frames,
            tracker_params(controller.preset_name),
            tracker=controller.preset_name,
            scene=self._scene,
            recording=recording,
            fps=self._reader().fps or DEFAULT_LIVE_FPS,
            **controller.tracker_options(),
            **POSE_OPTIONS,
        )
        self.frames, self.run = frames, run
        source = self.source if isinstance(self.source, Path) else Path(str(self.source))
        controller.install_run(run, source, self.scene_path)
        controller.cursor = frame.index
        controller.boxes_path = self._boxes_json() if run.scene is not None else None
        self.state = FROZEN
        controller.message = (
            f"Frozen at frame {frame.index + 1}: draw up to {controller.config.max_targets} "
            "boxes (shift-drag), then Start tracking."
        )

    def load_boxes_json(self) -> None:
        """Place the boxes.json beside the scene (or the video) on the frozen frame."""
        controller = self.controller
        run = controller.require_run()
        boxes = boxes_json_boxes(controller, "no boxes.json beside the scene file or the video")
        run.add_targets(controller.cursor, boxes)
        controller.message = f"Loaded {len(boxes)} boxes from boxes.json on the frozen frame."
        controller.claim_recording()

    def start(self) -> None:
        """Track from the frozen frame on, always on the newest frame."""
        controller = self.controller
        if self.state != FROZEN or self.newest is None or self.frames is None:
            raise InputError("freeze a frame and draw the boxes on it first")
        run = controller.require_run()
        if not run.targets:
            raise InputError("draw at least one box on the frozen frame first")
        controller.selected = None
        self.log = LiveLog(self._reader())
        self.log.adopt(self.newest)
        self.started = (self._reader().captured - 1, self._reader().now())
        self._outcomes = follow_live(self.log, run, self.frames)
        self._last_result = None
        self.state = TRACKING
        controller.message = "Tracking the live source (Stop ends it and keeps the recording)."

    def stop(self) -> None:
        """End the live run: finish its recording and reopen it to look through."""
        if self.state == OFF:
            raise InputError("no live source is open")
        figures = self.figures()
        path = self._finish()
        self._say_recorded(path, figures, "Stopped")

    # -- tracking -----------------------------------------------------------------------------

    def _track_next(self) -> None:
        """Track the newest frame; a source that ends or fails ends the run, keeping it."""
        assert self._outcomes is not None
        controller = self.controller
        try:
            frame, _outcome = next(self._outcomes)
        except StopIteration:
            figures = self.figures()
            ended = "ended" if isinstance(self.source, Path) else "stopped sending (ended or lost)"
            self._say_recorded(self._finish(), figures, f"{self._shown(self.source)} {ended}")
            return
        except InputError as error:
            figures = self.figures()
            path = self._finish()
            self._say_recorded(path, figures, "The live run ended")
            raise InputError(f"{error}; {controller.message}") from None
        now = time.perf_counter()
        run = controller.require_run()
        seconds = controller.play_seconds
        if len(seconds) < run.frame_count:
            seconds = np.concatenate([seconds, np.full(run.frame_count - len(seconds), np.nan)])
        if self._last_result is not None:
            seconds[frame.index] = now - self._last_result
        controller.play_seconds = seconds
        self._last_result = now
        controller.cursor = frame.index

    def _finish(self) -> Path | None:
        """Close the run and the source; the recording's path (None if nothing was drawn)."""
        run = self.controller.run
        path = None if run is None or self.state == PREVIEW else run.session_path
        if self._outcomes is not None:
            self._outcomes.close()
        self.close()
        self.controller.close_run()
        if path is not None and path.is_file():
            try:
                self.controller.sessions.review(path)
            except AutoTrackError as error:  # the recording stays on disk as written
                self.review_error = str(error)
            return path
        return None

    def _say_recorded(self, path: Path | None, figures: LiveFigures | None, what: str) -> None:
        figures_text = "" if figures is None else f" ({figures.text().removeprefix('● ')})"
        if path is None:
            where = "; nothing recorded"
        elif self.controller.run is None:  # the review failed
            where = f"; recorded to {path.name} (cannot reopen it here: {self.review_error})"
        else:
            where = f"; recorded to {path.name}, reopened to look through"
        self.controller.message = f"{what}{figures_text}{where}."

    def figures(self) -> LiveFigures | None:
        """The live figures since Start (None before)."""
        if self.log is None or self.reader is None:
            return None
        start_index, start_time = self.started
        processed = [frame for frame in self.log.processed if frame.index > start_index]
        captured = max(0, self.reader.captured - 1 - start_index)
        dropped = sum(1 for index in list(self.reader.dropped) if index > start_index)
        elapsed = self.reader.now() - start_time
        recent = processed[-LATENCY_WINDOW:]
        span = recent[-1].capture_time - recent[0].capture_time if len(recent) > 1 else 0.0
        latency = float(np.median([f.latency for f in recent])) * 1e3 if recent else float("nan")
        return LiveFigures(
            captured=captured,
            processed=len(processed),
            dropped=dropped,
            capture_fps=captured / elapsed if elapsed > 0 else float("nan"),
            processed_fps=(len(recent) - 1) / span if span > 0 else float("nan"),
            latency_ms=latency,
        )

    # -- the display --------------------------------------------------------------------------

    def snapshot(self) -> FrameView | None:
        """The preview frame, or the controller's view with the live figures (None when off)."""
        controller = self.controller
        if self.state == PREVIEW and self.newest is not None:
            return preview_view(self.newest, self._shown(self.source), controller.message)
        view = controller.snapshot()
        figures = self.figures() if self.state == TRACKING else None
        if view is None or figures is None:
            return view
        return replace(view, status=f"{figures.text()}\n\n{view.status}", playing=True)

    def close(self) -> None:
        """Stop reading the source (the run, if any, is the controller's)."""
        if self.reader is not None:
            self.reader.close()
        self.reader, self._outcomes, self.log, self.frames = None, None, None, None
        self.run = None
        self.state = OFF

    def halt(self) -> None:
        """End whatever is live (a failed step, the tab closing); a run is kept as by Stop."""
        if self.state != OFF:
            self.stop()

    def forget_if_replaced(self) -> None:
        """Close the source when another command replaced the live run (a sequence opened)."""
        if self.state != OFF and self.controller.run is not self.run:
            self.close()

    def _reader(self) -> LiveReader:
        if self.reader is None:
            raise InputError("open a live source first")
        return self.reader

    def _shown(self, source: Path | str | None) -> str:
        """How the browser is told the source: 'camera 0', the URL, or a video file relative
        to the allowed folder holding it (never the server's absolute path)."""
        if isinstance(source, Path) and source.is_absolute():
            return display_name(source, self.controller.roots)
        return describe_source("" if source is None else source)

    def _boxes_json(self) -> Path | None:
        """The boxes.json beside the scene file, else beside the video file."""
        folders = [p.parent for p in (self.scene_path, self.source) if isinstance(p, Path)]
        return next((f / "boxes.json" for f in folders if (f / "boxes.json").is_file()), None)


def preview_view(frame: CapturedFrame, name: str, message: str) -> FrameView:
    """A frame of the live preview: the picture alone (no targets yet)."""
    count = frame.index + 1
    history = SignalHistory(
        target_ids=(),
        colours=(),
        signals={},
        frame_seconds=np.full(count, np.nan),
        play_seconds=np.full(count, np.nan),
        phi=preset("autotrack").phi,
        last_frame=-1,
        frame_count=count,
    )
    status = f"**{markdown_literal(name)}** · live preview, frame {count}"
    return FrameView(
        frame_index=frame.index,
        frame_count=count,
        frame=frame.image,
        drawings={},
        pose_view=None,
        history=history,
        status=f"{status}\n\n{markdown_literal(message)}" if message else status,
    )
