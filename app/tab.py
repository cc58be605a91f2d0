"""One browser tab: its panels wired to its controller, through its worker and display threads.

    widget callback --queue--> Worker thread --runs--> TabController command
                                     |--> panels follow the state (show_state)
                                     '--> TabController.snapshot() --> DisplayLoop --> browser

Callbacks here are one line each: they read the widget's value and queue a controller command.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import viser

from autotrack.errors import InputError
from autotrack.tracker.parallel.target_process import WorkerPool
from autotrack_studio.boxes import parse_box
from autotrack_studio.channel import ClientChannel
from autotrack_studio.config import AppConfig
from autotrack_studio.controller import TabController
from autotrack_studio.display import DEFAULT_CANVAS_SIZE, DisplayLoop
from autotrack_studio.live import FROZEN, OFF, PREVIEW, LiveControl
from autotrack_studio.owners import BrowserSpace
from autotrack_studio.panels import (
    CANVAS_3D,
    CANVAS_FRAME,
    MAPS_PANELS,
    NEW_TARGET,
    NO_LANDMARK,
    build_panels,
    show_boxes_json,
    show_frame,
    show_live,
    show_opened,
    show_state,
    show_targets,
)
from autotrack_studio.paths import shown_paths
from autotrack_studio.recordings import RecordingRegistry
from autotrack_studio.startup import KernelWarmUp
from autotrack_studio.view3d import DEFAULT_FOV
from autotrack_studio.worker import Worker

TABLE_PERIOD = 0.5
"""Seconds between Targets-table updates while frames change (playing, tracking ahead)."""
SLIDER_PERIOD = 0.2
"""Seconds between Frame-slider updates while frames change: each is a GUI message the page
re-renders its panel for, which cost headless Chromium more than a tracked frame at 50
frames/s (the slider is set to the last frame when playback stops)."""
DRAW_HINT = (
    "A click draws no box: hold Shift and drag from one corner of the box to the other "
    "(on a target's box, the drag corrects it)."
)
"""Said when the frame canvas is clicked (viser reports a click, never a box of no size)."""
SWITCH_HINT = "switch Display → Canvas to 'frame' to draw boxes"
"""Said when a box is drawn on the 3-D view."""
UP = np.array([0.0, 0.0, 1.0])
"""The 3-D view's up direction (the scenes' world frame has +z up)."""


class Tab:
    """The controller, panels, worker and display of one browser tab."""

    def __init__(
        self,
        config: AppConfig,
        roots: tuple[Path, ...],
        recordings: RecordingRegistry,
        channel: ClientChannel,
        gui: viser.GuiApi,
        scene_api: viser.SceneApi,
        *,
        tab_id: int,
        space: BrowserSpace | None = None,
        worker_pool: WorkerPool | None = None,
        warm_up: KernelWarmUp | None = None,
    ) -> None:
        self.tab_id = tab_id
        self.warm_up = warm_up
        """The server's kernel warm-up (None: none runs), whose notice the tab shows."""
        self.channel = channel
        self.controller = TabController(
            config,
            roots,
            recordings,
            tab_id,
            on_visit=self._frame_changed,
            space=space,
            worker_pool=worker_pool,
        )
        self.panels = build_panels(gui, config)
        self.display = DisplayLoop(
            self.panels,
            gui,
            scene_api,
            channel,
            name=f"tab{tab_id}-display",
            max_targets=config.max_targets,
        )
        self._scene_shown = 0
        self._framed: tuple[object, bool] = (None, False)
        """(run, with its trajectory) the 3-D view was last framed on."""
        self._table_shown = 0.0
        self._slider_shown = 0.0
        controller = self.controller
        self.live = LiveControl(controller, config.allow_live)
        self.worker = Worker(
            is_playing=lambda: controller.playing or self.live.active,
            play_step=self._play_step,
            frame_period=self._frame_period,
            after_command=self._command_done,
            after_step=self._step_done,
            report=self._report,
            stop_playing=controller.stop_playing,
            name=f"tab{tab_id}-worker",
        )
        self._connect()
        scene_api.on_rect_select(modifier="shift")(self.rect_selected)
        scene_api.on_click(modifier="shift")(self.clicked)  # a drag of no size is a click
        scene_api.on_click()(self.clicked)
        channel.on_canvas_change(self.display.canvas_resized)
        self._stop_notice = None if warm_up is None else warm_up.subscribe(self.show_startup)

    def _connect(self) -> None:
        """Each widget's callback: read its value, queue a controller command."""
        panels, controller, submit = self.panels, self.controller, self.worker.submit
        edit = panels.quiet.user_edit
        sequence, targets = panels.sequence, panels.targets
        playback, display, session = panels.playback, panels.display, panels.session
        sequence.open_listed.on_click(
            lambda _: submit(controller.open_listed, sequence.dropdown.value)
        )
        sequence.refresh.on_click(lambda _: submit(controller.refresh_sequences))
        sequence.open_path.on_click(lambda _: submit(controller.open_typed, sequence.path.value))
        sequence.use_scene.on_click(lambda _: submit(controller.use_scene, sequence.scene.value))
        sequence.preset.on_update(
            edit(lambda: submit(controller.choose_preset, sequence.preset.value))
        )
        sequence.restart.on_click(lambda _: submit(controller.restart_with_preset))
        sequence.upload.on_upload(
            lambda _: self.receive_upload(sequence.upload.value.name, sequence.upload.value.content)
        )
        targets.draw.on_update(edit(lambda: submit(controller.select, _target(targets.draw.value))))
        targets.landmark.on_update(
            edit(lambda: submit(controller.assign_landmark, _landmark(targets.landmark.value)))
        )
        targets.apply_box.on_click(lambda _: submit(self.place_typed_box, targets.box.value))
        targets.delete.on_click(lambda _: submit(self.delete_target))
        targets.boxes_json.on_click(lambda _: submit(self.load_boxes_json))
        targets.from_truth.on_click(
            lambda _: (
                self._busy("starting from the ground truth…"),
                submit(controller.start_from_truth),
            )
        )
        targets.show_truth.on_update(edit(lambda: submit(self.redraw_canvas)))
        playback.play.on_click(lambda _: submit(self.not_live, controller.toggle_play))
        playback.step_back.on_click(lambda _: submit(self.not_live, controller.step, -1))
        playback.step.on_click(lambda _: submit(self.not_live, controller.step, 1))
        playback.frame.on_update(edit(lambda: submit(self.seek, int(playback.frame.value) - 1)))
        display.canvas.on_update(edit(lambda: submit(self.canvas_mode_changed)))
        display.maps.on_update(edit(lambda: submit(self.maps_changed)))
        display.trajectory.on_update(edit(lambda: submit(self.display.wake)))
        display.canvas_fps.on_update(edit(self.display.wake))
        display.zoom.on_update(edit(lambda: self.display.wake(canvas=True)))
        display.map_opacity.on_update(edit(lambda: self.display.wake(canvas=True)))
        display.zoom_centre.on_update(edit(lambda: self.display.wake(canvas=True)))
        self._connect_live()
        session.download_tracks.on_click(lambda _: submit(self.download, "tracks"))
        session.download_poses.on_click(lambda _: submit(self.download, "poses"))
        session.download_mot.on_click(lambda _: submit(self.download, "mot"))
        session.download_cvat.on_click(lambda _: submit(self.download, "cvat"))
        session.download_mcap.on_click(lambda _: submit(self.download, "mcap"))
        session.refresh.on_click(lambda _: submit(controller.sessions.refresh))
        session.reopen.on_click(
            lambda _: submit(controller.sessions.reopen, session.sessions.value)
        )

    def _connect_live(self) -> None:
        """The Live folder's buttons (absent without --allow-live)."""
        widgets, live, submit = self.panels.live, self.live, self.worker.submit
        if widgets.open is None:
            return
        widgets.open.on_click(
            lambda _: (
                self._busy("opening the live source…"),
                submit(live.open_source, widgets.source.value, widgets.scene.value),
            )
        )
        widgets.freeze.on_click(lambda _: submit(live.freeze))
        widgets.start.on_click(lambda _: submit(live.start))
        widgets.stop.on_click(lambda _: submit(live.stop))

    # -- commands that need the browser as well as the controller ----------------------------

    def _play_step(self) -> None:
        """Play the next frame, or while live take the newest (a failure ends the live run)."""
        if not self.live.active:
            self.controller.play_step()
            return
        try:
            self.live.step()
        except Exception:
            self.live.halt()
            raise

    def _frame_period(self) -> float:
        """The playback period; live frames come at the source's rate (the step waits)."""
        return 0.0 if self.live.active else self.panels.playback.frame_period()

    def not_live(self, command: Callable[..., None], *args: object) -> None:
        """Run a playback command, refused while a live source is open."""
        if self.live.state != OFF:
            raise InputError("a live source is open: Stop it to look back through its recording")
        command(*args)

    def delete_target(self) -> None:
        """Delete the chosen target and empty the typed box, which showed its box (applied
        now, it would make a new target there)."""
        self.controller.delete_selected()
        self.panels.quiet.set(self.panels.targets.box, "value", "")

    def load_boxes_json(self) -> None:
        """boxes.json on frame 1, or on the frozen frame of a live source."""
        if self.live.state == FROZEN:
            self.live.load_boxes_json()
        else:
            self.controller.load_boxes_json()

    def open_initial(self) -> None:
        """Queue the start-up sequence (the configured one, else the demo)."""
        self.worker.submit(self.controller.open_initial)

    def receive_upload(self, file_name: str, content: bytes) -> None:
        """An uploaded video or zip of images: stored safely, then opened (queued)."""
        self.worker.submit(self.controller.open_upload, file_name, content)

    def receive_upload_file(self, file_name: str, path: Path) -> None:
        """An upload received on disk: stored (moved or unpacked), then opened (queued); the
        received file is deleted whatever happens."""

        def store_and_open() -> None:
            try:
                self.controller.open_upload(file_name, path)
            finally:
                path.unlink(missing_ok=True)

        self.worker.submit(store_and_open)

    def refuse_upload(self, message: str) -> None:
        """An upload refused while it arrived: say why."""
        self.channel.notify("AutoTrack Studio", self._shown(message), error=True)

    def _shown(self, message: str) -> str:
        """`message` with the server's absolute paths hidden (app/paths.py, shown_paths)."""
        config = self.controller.config
        return shown_paths(message, self.controller.roots, (config.sessions_dir,))

    def rect_selected(self, event: viser.SceneRectSelectEvent) -> None:
        """A shift-drag on the canvas: a box at the current frame (queued)."""
        if self.panels.display.canvas.value != CANVAS_FRAME:
            self._hint(SWITCH_HINT)
            return
        waiting = "" if self.warm_up is None else self.warm_up.box_wait()
        self._busy(f"drawing the box: starting its tracker{waiting}…")
        self.worker.submit(self.place_dragged_box, event.screen_min, event.screen_max)

    def clicked(self, event: viser.SceneClickEvent) -> None:
        """A click on the canvas draws nothing (viser sends no rect-select for a drag of no
        size): on the frame, say how to draw; a shift-click on the 3-D view, where to."""
        display = self.panels.display
        if (
            display.canvas.value == CANVAS_FRAME
            and event.modifier is None
            and (float(display.zoom.value) > 1.0)
        ):
            self.worker.submit(self.pan_to, event.screen_pos)
        elif display.canvas.value == CANVAS_FRAME:
            self._hint(DRAW_HINT)
        elif event.modifier == "shift":
            self._hint(SWITCH_HINT)

    def pan_to(self, screen_pos: tuple[float, float]) -> None:
        """Centre the zoomed frame canvas on a clicked point (canvas fractions)."""
        run = self.controller.run
        if run is None:
            return
        mapping = self.display.canvas_mapping(self.controller.frame_size)
        self.display.zoom_centre = mapping.screen_to_frame(*screen_pos)
        self.display.wake(canvas=True)
        x, y = self.display.zoom_centre
        self.controller.message = f"Zoomed view centred on ({x:.0f}, {y:.0f})."

    def place_dragged_box(
        self, screen_min: tuple[float, float], screen_max: tuple[float, float]
    ) -> None:
        """A drag (canvas fractions) as a box in frame pixels, placed on the current frame."""
        if self.live.state == PREVIEW:
            raise InputError("freeze a frame first, then draw the boxes on it")
        mapping = self.display.canvas_mapping(self.controller.frame_size)
        box = mapping.rect_to_box(screen_min, screen_max)
        if box is None:
            raise InputError("the dragged box misses the frame or is too thin; drag again")
        self.controller.place_box(box)
        if not mapping.rect_inside(screen_min, screen_max):
            self.controller.message += " The drag passed the frame's edge: the box is cut there."

    def seek(self, frame_index: int) -> None:
        """Go to a frame chosen on the slider; tracking up to it stops at the next command."""
        if self.live.state != OFF:
            raise InputError("a live source is open: Stop it to look back through its recording")
        self.controller.seek(frame_index, interrupted=self.worker.has_waiting)
        if self.panels.display.canvas.value == CANVAS_3D:  # after a jump, frame it all again
            self._aim_camera()

    def place_typed_box(self, text: str) -> None:
        """A box typed as 'x, y, w, h', placed on the current frame."""
        self.controller.place_box(parse_box(text))

    def download(self, what: str) -> None:
        """Send one of the exports (see TabController.export) to the browser."""
        self.channel.download(*self.controller.export(what))

    def canvas_mode_changed(self) -> None:
        """The canvas switched between the frame and the 3-D view."""
        self.display.wake(canvas=True)
        if self.panels.display.canvas.value == CANVAS_3D:
            self._aim_camera()

    def redraw_canvas(self) -> None:
        """Draw the canvas again (the ground truth shown or hidden)."""
        self.display.wake(canvas=True)

    def maps_changed(self) -> None:
        """Show the per-target map panels only when chosen."""
        shown = self.panels.display.maps.value == MAPS_PANELS
        self.panels.quiet.set(self.panels.display.maps_folder, "visible", shown)
        self.panels.quiet.set(self.panels.display.maps_hint, "visible", not shown)
        self.display.wake(canvas=True)

    # -- after each command and frame ---------------------------------------------------------

    def _command_done(self) -> None:
        controller = self.controller
        self.live.forget_if_replaced()
        show_state(self.panels, controller)  # first: it may replace the sequence list
        show_live(self.panels, self.live)
        show_boxes_json(self.panels, bool(controller.targets()), self.live.state)
        if controller.sequences_opened != self._scene_shown:
            self._scene_shown = controller.sequences_opened
            run = controller.run
            self.display.view3d.show_scene(
                None if run is None else run.scene, controller.ground_truth
            )
            self._aim_camera()
            self.display.wake(canvas=True)
            show_opened(self.panels, controller)
        self._frame_localisation_start()
        self._publish()

    def _step_done(self) -> None:
        if not self.controller.playing and not self.live.active:  # playback ended by itself
            self._command_done()

    def _frame_changed(self) -> None:
        now = time.monotonic()
        if now >= self._slider_shown + SLIDER_PERIOD:  # the Frame slider follows playback
            show_frame(self.panels, self.controller)
            self._slider_shown = now
        if now >= self._table_shown + TABLE_PERIOD:  # the Targets table follows playback
            show_targets(self.panels, self.controller)
            self._table_shown = now
        self._frame_localisation_start()
        self._publish()

    def _publish(self) -> None:
        view = self.live.snapshot()  # the controller's view, or the live one
        if view is not None:
            self.display.publish(view)

    def _busy(self, what: str) -> None:
        """Say at once (on viser's thread) that a command is under way; the status line is
        rewritten when it is done."""
        status = self.panels.status
        self.panels.quiet.set(status, "content", f"⏳ **Working**: {what}\n\n{status.content}")

    def show_startup(self, notice: str) -> None:
        """Show what the server prepares before a box can track ('' hides the notice)."""
        startup, quiet = self.panels.startup, self.panels.quiet
        if startup.content != notice:
            quiet.set(startup, "content", notice)
        if startup.visible != bool(notice):
            quiet.set(startup, "visible", bool(notice))

    def _hint(self, message: str) -> None:
        """Say how to use the canvas, over it (a note) and in the status line."""
        self.channel.notify("AutoTrack Studio", message)
        self.worker.submit(self._tell, message)

    def _tell(self, message: str) -> None:
        self.controller.message = message

    def _report(self, message: str) -> None:
        """A failed command or frame: tell the user (the panels follow after it)."""
        message = self._shown(message)
        self.controller.message = message
        self.channel.notify("AutoTrack Studio", message, error=True)
        self._publish()

    def _aim_camera(self) -> None:
        """Frame the scene, the ground truth and the estimated trajectory in the 3-D view, as
        the tab's canvas and camera show it."""
        run = self.controller.run
        trajectory = None if run is None else [p for _, p in run.valid_positions()]
        width, height = self.channel.canvas_size() or DEFAULT_CANVAS_SIZE
        fov = self.channel.field_of_view() or DEFAULT_FOV
        eye, centre = self.display.view3d.viewpoint(
            None if not trajectory else np.array(trajectory), fov, width / max(1, height)
        )
        self.channel.look_at(eye, centre, UP)
        self._framed = (run, bool(trajectory))

    def _frame_localisation_start(self) -> None:
        """Frame the 3-D view again once the run has its first trusted pose (localisation
        started), so the trajectory is framed as it begins, not only the scene."""
        run = self.controller.run
        if run is None or run.scene is None or self._framed == (run, True):
            return
        if any(pose.valid for pose in run.poses.values()):
            self._aim_camera()

    def wait_idle(self, timeout: float = 300.0) -> bool:
        """Block until every queued command ran and playback stopped; False on timeout."""
        return self.worker.wait_idle(timeout)

    def close(self) -> None:
        """Stop the threads and finish the recording (the tab's browser went away)."""
        if self._stop_notice is not None:
            self._stop_notice()
        try:
            self.worker.close()
            self.live.halt()
            self.display.close()
        finally:
            self.controller.close()  # whatever the rest raised: the recording is let go


def _target(choice: str) -> str | None:
    return None if choice == NEW_TARGET else choice


def _landmark(choice: str) -> str | None:
    return None if choice == NO_LANDMARK else choice
