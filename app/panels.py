"""A tab's GUI: flat `gui.add_*` calls, one small function per folder, and `show_state`, which
writes the controller's state back into the widgets after each command.

No callbacks and no state here: app/tab.py connects each widget to a controller command, and
the controller (app/controller.py) holds the state.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import viser

from autotrack.hybrid.factory import TRACKERS
from autotrack_studio.boxes import format_box
from autotrack_studio.browser_text import markdown_literal
from autotrack_studio.config import AppConfig
from autotrack_studio.controller import TabController
from autotrack_studio.live import DISABLED_HINT, FROZEN, OFF, PREVIEW, TRACKING, LiveControl
from autotrack_studio.paths import display_name
from autotrack_studio.quiet import QuietWrites
from autotrack_studio.targets_table import targets_table
from autotrack_studio.zoom import MAX_ZOOM

NEW_TARGET = "new target"
NO_LANDMARK = "none"
NO_CHOICE = "(none)"
CANVAS_FRAME = "frame (shift-drag draws a box)"
CANVAS_3D = "3-D view"
MAPS_OFF = "off"
MAPS_RESPONSE = "response map on frame"
MAPS_VARIATION = "local variation on frame"
MAPS_VARIATION_TARGET = "local variation, target region (ASR)"
MAPS_PANELS = "per-target panels (Debugging → Maps)"
"""Named with where the panels show: the Signals tab stays in front when it is chosen."""
MAP_KINDS = {
    MAPS_RESPONSE: "response",
    MAPS_VARIATION: "local_variation",
    MAPS_VARIATION_TARGET: "local_variation_target",
}
BOXES_JSON = "Load boxes.json"
TRAJECTORY_RAW = "raw poses"
TRAJECTORY_SMOOTHED = "smoothed (0.3 s lag)"
ZOOM_CLICK = "where you click"
ZOOM_FOLLOW = "the target in Drag draws"
"""Maps choice -> the map `draw_overlays` blends over the frame."""


@dataclass
class SequencePanel:
    """The Sequence folder: pick, type or upload a sequence, its scene and the tracker."""

    dropdown: viser.GuiDropdownHandle
    open_listed: viser.GuiButtonHandle
    refresh: viser.GuiButtonHandle
    path: viser.GuiTextHandle
    open_path: viser.GuiButtonHandle
    scene: viser.GuiTextHandle
    use_scene: viser.GuiButtonHandle
    preset: viser.GuiDropdownHandle
    restart: viser.GuiButtonHandle
    """Restart with the chosen preset (shown while the run's targets track with another)."""
    upload: viser.GuiUploadButtonHandle


def _sequence_panel(gui: viser.GuiApi, config: AppConfig) -> SequencePanel:
    with gui.add_folder("Sequence", expand_by_default=False):
        return SequencePanel(
            dropdown=gui.add_dropdown("Sequences", options=(NO_CHOICE,)),
            open_listed=gui.add_button("Open selected sequence"),
            refresh=gui.add_button("Refresh list"),
            path=gui.add_text("Path", initial_value=""),
            open_path=gui.add_button("Open path"),
            scene=gui.add_text("Scene file", initial_value=""),
            use_scene=gui.add_button("Use scene file (reopens)"),
            preset=gui.add_dropdown(
                "Tracker", options=TRACKERS, initial_value=config.tracker_preset
            ),
            restart=gui.add_button("Restart with the chosen tracker", visible=False),
            upload=gui.add_upload_button(
                "Upload video or zip of images", mime_type="video/*,.zip,application/zip"
            ),
        )


@dataclass
class LivePanel:
    """The Live folder (controls only with `--allow-live`; else how to enable it)."""

    note: viser.GuiMarkdownHandle
    source: viser.GuiTextHandle | None = None
    scene: viser.GuiTextHandle | None = None
    open: viser.GuiButtonHandle | None = None
    freeze: viser.GuiButtonHandle | None = None
    start: viser.GuiButtonHandle | None = None
    stop: viser.GuiButtonHandle | None = None


def _live_panel(gui: viser.GuiApi, config: AppConfig) -> LivePanel:
    with gui.add_folder("Live source", expand_by_default=config.allow_live):
        if not config.allow_live:
            return LivePanel(note=gui.add_markdown(DISABLED_HINT))
        return LivePanel(
            note=gui.add_markdown(
                "A camera index (`0`), an `rtsp://` or `http(s)://` stream, or a video file "
                "(played at its frame rate). Open, *Freeze* a frame, draw the boxes on it, "
                "*Start*: the newest frame is always tracked and late frames are dropped."
            ),
            source=gui.add_text("Source", initial_value=""),
            scene=gui.add_text("Live scene file", initial_value=""),
            open=gui.add_button("Open live source", icon=viser.Icon.VIDEO),
            freeze=gui.add_button("Freeze frame", disabled=True),
            start=gui.add_button("Start tracking", disabled=True, icon=viser.Icon.PLAYER_PLAY),
            stop=gui.add_button("Stop", disabled=True, color="red"),
        )


def show_live(panels: Panels, live: LiveControl) -> None:
    """The live buttons enabled as the live state allows."""
    widgets, quiet = panels.live, panels.quiet
    if widgets.open is None:
        return
    quiet.set(widgets.freeze, "disabled", live.state != PREVIEW)
    quiet.set(widgets.start, "disabled", live.state != FROZEN)
    quiet.set(widgets.stop, "disabled", live.state == OFF)
    quiet.set(widgets.open, "disabled", live.state == TRACKING)


def show_boxes_json(panels: Panels, any_target: bool, live_state: str) -> None:
    """Load boxes.json adds a target per landmark on a still frame: greyed once a target
    exists or while a live source runs, and then saying why (after each command)."""
    waiting = {PREVIEW: "freeze a frame first", TRACKING: "Stop first"}.get(live_state)
    if waiting is None and any_target:
        waiting = "delete the targets first"
    button, quiet = panels.targets.boxes_json, panels.quiet
    quiet.set(button, "disabled", waiting is not None)
    quiet.set(button, "label", BOXES_JSON if waiting is None else f"{BOXES_JSON} ({waiting})")


@dataclass
class TargetsPanel:
    """The Targets folder: the table, which target a drag draws, its landmark, typed box."""

    table: viser.GuiMarkdownHandle
    draw: viser.GuiDropdownHandle
    landmark: viser.GuiDropdownHandle
    box: viser.GuiTextHandle
    apply_box: viser.GuiButtonHandle
    delete: viser.GuiButtonHandle
    boxes_json: viser.GuiButtonHandle
    show_truth: viser.GuiCheckboxHandle
    from_truth: viser.GuiButtonHandle


def _targets_panel(gui: viser.GuiApi) -> TargetsPanel:
    with gui.add_folder("Targets"):
        return TargetsPanel(
            table=gui.add_markdown("No targets yet."),
            draw=gui.add_dropdown("Drag draws", options=(NEW_TARGET,), initial_value=NEW_TARGET),
            landmark=gui.add_dropdown(
                "Landmark", options=(NO_LANDMARK,), initial_value=NO_LANDMARK
            ),
            box=gui.add_text("Box x, y, w, h", initial_value=""),
            apply_box=gui.add_button("Apply typed box"),
            delete=gui.add_button(delete_label(None, False), color="red", disabled=True),
            boxes_json=gui.add_button(BOXES_JSON, visible=False),
            show_truth=gui.add_checkbox("Show ground truth", False, visible=False),
            from_truth=gui.add_button("Start from ground truth", visible=False),
        )


@dataclass
class PlaybackPanel:
    """The Playback folder: play / pause, steps, the frame slider and the speed."""

    play: viser.GuiButtonHandle
    step_back: viser.GuiButtonHandle
    step: viser.GuiButtonHandle
    frame: viser.GuiSliderHandle
    speed: viser.GuiSliderHandle
    unlimited: viser.GuiCheckboxHandle

    def frame_period(self) -> float:
        """Seconds between played frames (0 when playing as fast as tracking goes)."""
        return 0.0 if self.unlimited.value else 1.0 / max(1.0, float(self.speed.value))


def _playback_panel(gui: viser.GuiApi) -> PlaybackPanel:
    with gui.add_folder("Playback"):
        return PlaybackPanel(
            play=gui.add_button("Play", icon=viser.Icon.PLAYER_PLAY),
            step_back=gui.add_button("Step back", icon=viser.Icon.PLAYER_SKIP_BACK),
            step=gui.add_button("Step forward", icon=viser.Icon.PLAYER_SKIP_FORWARD),
            frame=gui.add_slider("Frame", min=1, max=2, step=1, initial_value=1),
            speed=gui.add_slider("Speed (frames/s)", min=1, max=60, step=1, initial_value=30),
            unlimited=gui.add_checkbox("As fast as tracking goes", False),
        )


@dataclass
class DisplayPanel:
    """The Display folder: canvas mode, maps, 3-D trajectory, canvas frame-rate cap (and the
    Maps folder)."""

    canvas: viser.GuiDropdownHandle
    maps: viser.GuiDropdownHandle
    trajectory: viser.GuiDropdownHandle
    """The 3-D view's trajectory: TRAJECTORY_RAW or TRAJECTORY_SMOOTHED."""
    canvas_fps: viser.GuiSliderHandle
    maps_folder: viser.GuiFolderHandle
    """Holds one image per target while `maps` is MAPS_PANELS (see app/display.py)."""
    legend: viser.GuiMarkdownHandle
    """The 3-D view's legend and the pose error against the ground truth (app/view3d.py)."""
    map_opacity: viser.GuiSliderHandle
    """How opaque the map overlay on the frame is (0..1)."""
    maps_hint: viser.GuiMarkdownHandle
    """In the Maps tab: how to show the per-target panels (hidden once they are shown)."""
    zoom: viser.GuiSliderHandle
    """How much the frame canvas enlarges the frame (1: all of it; app/zoom.py)."""
    zoom_centre: viser.GuiDropdownHandle
    """What the zoomed canvas centres on: ZOOM_CLICK or ZOOM_FOLLOW."""


def _display_panel(
    gui: viser.GuiApi, config: AppConfig, maps_tab: viser.GuiTabHandle
) -> DisplayPanel:
    with gui.add_folder("Display"):
        canvas = gui.add_dropdown(
            "Canvas", options=(CANVAS_FRAME, CANVAS_3D), initial_value=CANVAS_FRAME
        )
        zoom = gui.add_slider("Frame zoom", min=1.0, max=MAX_ZOOM, step=0.5, initial_value=1.0)
        zoom_centre = gui.add_dropdown(
            "Zoom centre",
            options=(ZOOM_CLICK, ZOOM_FOLLOW),
            initial_value=ZOOM_CLICK,
            hint="Zoomed, a click on the frame (without Shift) centres it there; or follow "
            "the target chosen in Drag draws.",
        )
        maps = gui.add_dropdown(
            "Maps",
            options=(MAPS_OFF, MAPS_RESPONSE, MAPS_VARIATION, MAPS_VARIATION_TARGET, MAPS_PANELS),
            initial_value=MAPS_RESPONSE,
        )
        map_opacity = gui.add_slider("Map opacity", min=0.1, max=1.0, step=0.05, initial_value=0.7)
        trajectory = gui.add_dropdown(
            "3-D trajectory",
            options=(TRAJECTORY_RAW, TRAJECTORY_SMOOTHED),
            initial_value=TRAJECTORY_RAW,
        )
        legend = gui.add_markdown("")
        canvas_fps = gui.add_slider(
            "Canvas frames/s cap",
            min=1,
            max=30,
            step=1,
            initial_value=min(30, max(1, round(config.canvas_fps))),
        )
    with maps_tab:
        maps_hint = gui.add_markdown(
            f"Choose *Display → Maps → {MAPS_PANELS}* to show each target's maps here."
        )
        folder = gui.add_folder("Maps per target", visible=False)
    return DisplayPanel(
        canvas,
        maps,
        trajectory,
        canvas_fps,
        folder,
        legend,
        map_opacity,
        maps_hint,
        zoom,
        zoom_centre,
    )


@dataclass
class SessionPanel:
    """The Session folder: recording status, downloads, reopening a session."""

    recording: viser.GuiMarkdownHandle
    download_tracks: viser.GuiButtonHandle
    download_poses: viser.GuiButtonHandle
    download_mot: viser.GuiButtonHandle
    download_cvat: viser.GuiButtonHandle
    download_mcap: viser.GuiButtonHandle
    sessions: viser.GuiDropdownHandle
    refresh: viser.GuiButtonHandle
    reopen: viser.GuiButtonHandle


def _session_panel(gui: viser.GuiApi) -> SessionPanel:
    with gui.add_folder("Session", expand_by_default=False):
        return SessionPanel(
            recording=gui.add_markdown("Not recording yet (draw a box)."),
            download_tracks=gui.add_button("Download tracks (zip)"),
            download_poses=gui.add_button("Download poses (TUM)"),
            download_mot=gui.add_button("Download tracks (MOT Challenge)"),
            download_cvat=gui.add_button("Download tracks (CVAT for video XML)"),
            download_mcap=gui.add_button("Download session (MCAP)"),
            sessions=gui.add_dropdown("Sessions", options=(NO_CHOICE,)),
            refresh=gui.add_button("Refresh sessions"),
            reopen=gui.add_button("Reopen and continue"),
        )


@dataclass
class DebugPanel:
    """The debugging window docked left (wide enough to read the charts): the signal charts,
    the per-target map panels, the ground-truth scores."""

    panel: viser.PanelHandle
    signals: viser.GuiTabHandle
    maps: viser.GuiTabHandle
    truth: viser.GuiTabHandle


DEBUG_WIDTH = 520
"""Width of the debugging window (CSS pixels)."""


def _debug_panel(gui: viser.GuiApi) -> DebugPanel:
    panel = gui.add_panel()
    debug = DebugPanel(
        panel=panel,
        signals=panel.add_tab("Signals"),
        maps=panel.add_tab("Maps"),
        truth=panel.add_tab("Ground truth"),
    )
    panel.dock_left()
    panel.set_width(DEBUG_WIDTH)
    return debug


@dataclass
class Panels:
    """Every widget of a tab, top to bottom (the plots are added after these)."""

    startup: viser.GuiMarkdownHandle
    """What the server prepares before the first box can track (app/startup.py), while it
    does; hidden otherwise."""
    status: viser.GuiMarkdownHandle
    video: viser.GuiImageHandle
    sequence: SequencePanel
    live: LivePanel
    targets: TargetsPanel
    playback: PlaybackPanel
    display: DisplayPanel
    session: SessionPanel
    debug: DebugPanel
    quiet: QuietWrites


def build_panels(gui: viser.GuiApi, config: AppConfig) -> Panels:
    """A tab's widgets, in panel order."""
    startup = gui.add_markdown("", visible=False)
    status = gui.add_markdown("Opening…")
    video = gui.add_image(
        np.zeros((90, 160, 3), np.uint8), label="Video", format="jpeg", jpeg_quality=80
    )
    debug = _debug_panel(gui)
    return Panels(
        startup=startup,
        status=status,
        video=video,
        sequence=_sequence_panel(gui, config),
        live=_live_panel(gui, config),
        targets=_targets_panel(gui),
        playback=_playback_panel(gui),
        display=_display_panel(gui, config, debug.maps),
        session=_session_panel(gui),
        debug=debug,
        quiet=QuietWrites(),
    )


def show_state(panels: Panels, controller: TabController) -> None:
    """Write the controller's state into the widgets (after each command; see show_opened)."""
    quiet = panels.quiet
    run = controller.run
    sequence = panels.sequence
    quiet.set_options(sequence.dropdown, tuple(controller.sequence_choices) or (NO_CHOICE,))
    show_preset(panels, controller)
    show_targets(panels, controller)
    show_frame(panels, controller)
    show_playing(panels, controller.playing)
    playback = panels.playback
    for button in (playback.play, playback.step_back, playback.step):  # nothing to play
        quiet.set(button, "disabled", run is None or run.frame_count == 0)
    session = panels.session
    quiet.set_options(session.sessions, tuple(controller.sessions.choices) or (NO_CHOICE,))
    path = None if run is None else run.session_path
    recording = "Not recording yet (draw a box)." if path is None else f"Recording to `{path.name}`"
    quiet.set(session.recording, "content", recording)
    if run is None:
        quiet.set(panels.status, "content", markdown_literal(controller.message))


def show_preset(panels: Panels, controller: TabController) -> None:
    """The Tracker choice as the controller holds it, and *Restart with ...* while the run's
    targets track with another preset."""
    quiet, sequence = panels.quiet, panels.sequence
    if sequence.preset.value != controller.preset_name:
        quiet.set(sequence.preset, "value", controller.preset_name)
    pending = controller.preset_pending and controller.file_run
    quiet.set(sequence.restart, "visible", pending)
    label = f"Restart with {controller.preset_name}"
    if pending and sequence.restart.label != label:
        quiet.set(sequence.restart, "label", label)


def show_opened(panels: Panels, controller: TabController) -> None:
    """The opened sequence's path, scene file, tracker preset (a reopened session's own) and
    length (only when one was opened, so that a path being typed is not overwritten)."""
    quiet, sequence = panels.quiet, panels.sequence
    path, scene_path, run = controller.sequence_path, controller.scene_path, controller.run
    roots = controller.roots
    quiet.set(sequence.path, "value", "" if path is None else display_name(path, roots))
    shown_scene = "" if scene_path is None else display_name(scene_path, roots)
    quiet.set(sequence.scene, "value", shown_scene)
    quiet.set(sequence.preset, "value", controller.preset_name)
    quiet.set(panels.targets.box, "value", "")  # a box typed for the run before is not this one's
    quiet.set(panels.playback.frame, "max", max(2, 0 if run is None else run.frame_count))
    suggested = controller.suggested_session  # this browser's last session, after a reload
    if suggested is not None and suggested in controller.sessions.choices:
        quiet.set_options(panels.session.sessions, tuple(controller.sessions.choices))
        quiet.set(panels.session.sessions, "value", suggested)
    listed = next((n for n, p in controller.sequence_choices.items() if p == path), None)
    if listed is not None:  # the list shows the sequence that is open
        quiet.set(sequence.dropdown, "value", listed)


def show_frame(panels: Panels, controller: TabController) -> None:
    """The frame slider at the current frame (1-based), its end moved on as a live source
    grows."""
    slider = panels.playback.frame
    if controller.cursor + 1 > slider.max:
        panels.quiet.set(slider, "max", controller.cursor + 1)
    panels.quiet.set(slider, "value", controller.cursor + 1)


def show_playing(panels: Panels, playing: bool) -> None:
    """The Play button as Pause while playing."""
    play = panels.playback.play
    label = "Pause" if playing else "Play"
    if play.label != label:
        panels.quiet.set(play, "label", label)
        icon = viser.Icon.PLAYER_PAUSE if playing else viser.Icon.PLAYER_PLAY
        panels.quiet.set(play, "icon", icon)


def show_targets(panels: Panels, controller: TabController) -> None:
    """The targets table, the target and landmark choosers, the typed box."""
    quiet, widgets = panels.quiet, panels.targets
    run = controller.run
    targets = controller.targets()
    quiet.set_options(widgets.draw, (NEW_TARGET, *(target.id for target in targets)))
    quiet.set(widgets.draw, "value", controller.selected or NEW_TARGET)
    landmarks = () if run is None or run.scene is None else run.scene.landmark_ids
    quiet.set_options(widgets.landmark, (NO_LANDMARK, *landmarks))
    chosen = controller.selected_target()
    landmark = None if chosen is None else chosen.landmark_id
    quiet.set(widgets.landmark, "value", landmark or NO_LANDMARK)
    quiet.set(widgets.landmark, "disabled", chosen is None)
    quiet.set(widgets.delete, "disabled", chosen is None)
    quiet.set(widgets.delete, "label", delete_label(chosen and chosen.id, bool(targets)))
    quiet.set(widgets.boxes_json, "visible", controller.boxes_path is not None)
    quiet.set(widgets.show_truth, "visible", controller.has_truth)
    quiet.set(widgets.from_truth, "visible", controller.has_truth)
    if chosen is not None and controller.cursor in chosen.results:
        quiet.set(widgets.box, "value", format_box(chosen.results[controller.cursor].box))
    quiet.set(widgets.table, "content", targets_table(controller))


def delete_label(chosen: str | None, any_target: bool) -> str:
    """The Delete button says what it deletes, or while greyed what enables it (tooltips on
    disabled buttons do not show)."""
    if chosen is not None:
        return f"Delete {chosen}"
    if any_target:
        return "Delete target (choose it in Drag draws)"
    return "Delete target (none yet)"
