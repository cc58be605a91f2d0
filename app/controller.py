"""The per-tab state, and every command a tab's user can give, with no viser.

One `TabController` per browser tab holds what is open (sequence, scene, the tracking run), the
playback position, the target being edited and the last message. Its public methods are the
tab's commands; the tab's worker thread runs them one at a time, so this state needs no lock.
The panels (app/panels.py) read the state back after each command, and the display thread only
ever sees the immutable `FrameView` snapshots of `snapshot()`. Tests drive this class directly.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from pathlib import Path

import numpy as np

from app import exports
from app.config import AppConfig
from app.paths import display_name, find_sequences, resolve_user_path, store_upload
from app.recordings import RecordingRegistry
from app.views import FrameView, frame_view
from autotrack.errors import InputError
from autotrack.io.boxes_json import read_boxes_json
from autotrack.io.frames import FrameSource, open_frames
from autotrack.io.tum import read_tum
from autotrack.localization.pnp import boxes_by_landmark
from autotrack.localization.scene import Scene, load_scene
from autotrack.params import PRESETS, preset
from autotrack.pipeline import Pipeline, Recording, TrackedTarget
from autotrack.sessions import open_session

Box = tuple[float, float, float, float]

EXPORTS = ("tracks", "poses", "mcap")
"""What `export` can build: the tracks zip, the TUM poses, the session file itself."""


def parse_box(text: str) -> Box:
    """'x, y, w, h' (0-based pixels) typed by the user."""
    parts = [part for part in text.replace(";", ",").replace(" ", ",").split(",") if part]
    try:
        values = [float(part) for part in parts]
    except ValueError:
        raise InputError(f"type the box as four numbers 'x, y, w, h', not {text!r}") from None
    if len(values) != 4 or not all(math.isfinite(value) for value in values):
        raise InputError(f"type the box as four numbers 'x, y, w, h', not {text!r}")
    return (values[0], values[1], values[2], values[3])


def format_box(box: Box) -> str:
    """A box as the text field shows it."""
    return ", ".join(f"{value:.1f}" for value in box)


def ground_truth_positions(scene_path: Path | None) -> np.ndarray | None:
    """Camera positions of the `poses_gt.tum` beside a scene file, if there is one."""
    if scene_path is None:
        return None
    tum = scene_path.parent / "poses_gt.tum"
    if not tum.is_file():
        return None
    _stamps, positions, _quaternions = read_tum(tum)
    return positions


class TabController:
    """One tab's state and commands (see the module docstring).

    Args:
        config: How the server was started (sessions folder, start-up sequence, limits).
        roots: Folders this tab may open sequences, scenes and sessions' sources from.
        recordings: The server-wide registry of session files being written.
        tab_id: This tab's id in `recordings`.
        on_visit: Called whenever the current frame changes while a command runs (each frame
            played or tracked through), so the display can follow.
    """

    def __init__(
        self,
        config: AppConfig,
        roots: tuple[Path, ...],
        recordings: RecordingRegistry,
        tab_id: int,
        on_visit: Callable[[], None] | None = None,
    ) -> None:
        self.config = config
        self.roots = roots
        self.recordings = recordings
        self.tab_id = tab_id
        self.on_visit = on_visit
        self.run: Pipeline | None = None
        self.sequence_path: Path | None = None
        self.scene_path: Path | None = None
        self.boxes_path: Path | None = None
        """The sequence's boxes.json (None: none, or no scene to tie its boxes to)."""
        self.ground_truth: np.ndarray | None = None
        """(n, 3) ground-truth camera positions of the scene, if known."""
        self.preset_name = config.tracker_preset
        """Tracker preset the next opened sequence uses."""
        self.cursor = 0
        """The frame shown (0-based)."""
        self.playing = False
        self.selected: str | None = None
        """The target a drag redraws (None: a drag makes a new target)."""
        self.message = ""
        """The last thing the tab told its user."""
        self.sequence_choices: dict[str, Path] = {}
        """Name shown in the sequence list -> sequence path."""
        self.session_choices: dict[str, Path] = {}
        """Name shown in the session list -> session file, newest first."""
        self.sequences_opened = 0
        """How many sequences this tab opened (the 3-D scene is rebuilt when it changes)."""
        self.recording_path: Path | None = None
        """The session file this tab writes and has claimed in `recordings`."""

    # -- reading the state --------------------------------------------------------------------

    def require_run(self) -> Pipeline:
        """The open run; InputError when no sequence is open."""
        if self.run is None:
            raise InputError("open a sequence first")
        return self.run

    def targets(self) -> list[TrackedTarget]:
        """The run's targets in the order they were drawn (empty without a run)."""
        return [] if self.run is None else list(self.run.targets.values())

    def selected_target(self) -> TrackedTarget | None:
        """The target a drag redraws, if any."""
        return (
            None
            if self.run is None or self.selected is None
            else self.run.targets.get(self.selected)
        )

    @property
    def frame_size(self) -> tuple[int, int]:
        """(width, height) of the open sequence's frames."""
        return self.require_run().frames.frame_size

    # -- opening sequences --------------------------------------------------------------------

    def open_initial(self) -> None:
        """List sequences and sessions, then open the start-up sequence (else the demo)."""
        self.refresh_sequences()
        self.refresh_sessions()
        self.open(self.config.sequence or self.config.demo_dir, self.config.scene)

    def refresh_sequences(self) -> None:
        """List the sequences under this tab's folders."""
        found = find_sequences(self.roots)
        self.sequence_choices = {display_name(path, self.roots): path for path in found}

    def open_listed(self, name: str) -> None:
        """Open the sequence listed as `name`."""
        path = self.sequence_choices.get(name)
        if path is None:
            raise InputError("choose a sequence from the list first")
        self.open(path, None)

    def open_typed(self, text: str) -> None:
        """Open a sequence path typed by the user (it must lie under the allowed folders)."""
        self.open(resolve_user_path(text, self.roots), None)

    def use_scene(self, text: str) -> None:
        """Reopen the sequence with the scene file typed by the user (empty: no scene)."""
        if self.sequence_path is None:
            raise InputError("open a sequence first")
        scene = resolve_user_path(text.strip(), self.roots) if text.strip() else None
        self.open(self.sequence_path, scene, scene_given=True)

    def choose_preset(self, name: str) -> None:
        """Use tracker preset `name` for the sequences opened from now on."""
        if name not in PRESETS:
            raise InputError(f"unknown tracker preset {name!r}; choose one of {sorted(PRESETS)}")
        self.preset_name = name

    def open_upload(self, file_name: str, content: bytes) -> None:
        """Store an uploaded video or zip of images safely, then open it."""
        config = self.config
        path = store_upload(file_name, content, config.upload_dir, config.upload_limits)
        self.refresh_sequences()
        self.open(path, None)

    def open(self, path: Path, scene_path: Path | None, *, scene_given: bool = False) -> None:
        """Open a sequence (and its scene: `scene_path`, else a scene.json beside it unless
        `scene_given`) with the chosen preset, closing the current run and its recording."""
        frames, scene, scene_path = self._load(path, scene_path, scene_given=scene_given)
        try:
            run = Pipeline(
                frames,
                preset(self.preset_name),
                scene=scene,
                recording=self._recording(path, scene_path),
                tracker_threads=self.config.tracker_threads,
            )
        except Exception:
            frames.close()
            raise
        self._start(run, path, scene_path)

    def _load(
        self, path: Path, scene_path: Path | None, *, scene_given: bool
    ) -> tuple[FrameSource, Scene | None, Path | None]:
        """The frames and scene of a sequence (the first frame read, so a broken file fails
        here and the open run stays)."""
        self.stop_playing()
        frames = open_frames(path)
        if len(frames) == 0:
            raise InputError(f"{path} holds no frames")
        frames.read(0)
        folder = path if path.is_dir() else path.parent
        if scene_path is None and not scene_given and (folder / "scene.json").is_file():
            scene_path = folder / "scene.json"
        scene = load_scene(scene_path) if scene_path is not None else None
        return frames, scene, scene_path

    def _recording(self, path: Path, scene_path: Path | None) -> Recording:
        """A new session file in the sessions folder, created at the first box."""
        return Recording(
            source=str(path), directory=self.config.sessions_dir, scene_path=scene_path
        )

    def _start(self, run: Pipeline, path: Path, scene_path: Path | None) -> None:
        """Make `run` (on the sequence `path`) this tab's run, replacing the current one."""
        self.close_run()
        self.run = run
        self.ground_truth = ground_truth_positions(scene_path)
        self.sequence_path = path
        self.scene_path = scene_path
        boxes = (path if path.is_dir() else path.parent) / "boxes.json"
        self.boxes_path = boxes if boxes.is_file() and run.scene is not None else None
        self.cursor = 0
        self.selected = None
        self.sequences_opened += 1
        scene = run.scene
        landmarks = "" if scene is None else f", scene with {len(scene.landmarks)} landmarks"
        self.message = (
            f"Opened {display_name(path, self.roots)}: {run.frame_count} frames{landmarks}."
        )

    def close_run(self) -> None:
        """Close the run: its trackers, frames and recording (released for other tabs)."""
        if self.run is None:
            return
        self.run.close()
        self.run.frames.close()
        if self.recording_path is not None:
            self.recordings.release(self.recording_path)
        self.run = None
        self.recording_path = None

    def _claim_recording(self) -> None:
        """Register the run's session file (created at the first edit) as this tab's."""
        path = None if self.run is None else self.run.session_path
        if path is not None and path != self.recording_path:
            self.recordings.claim(path, self.tab_id)
            self.recording_path = path

    # -- targets ------------------------------------------------------------------------------

    def place_box(self, box: Box) -> None:
        """A box drawn or typed on the current frame: a new target, or the selected target's
        box redrawn (a correction when it was tracked there; it re-tracks from here)."""
        run = self.require_run()
        self.stop_playing()
        if self.selected is None:
            target_id = run.add_target(self.cursor, box)
            landmark = run.targets[target_id].landmark_id
            tied = f" → landmark {landmark}" if landmark else ""
            self.message = f"{target_id}{tied} drawn at frame {self.cursor + 1}."
        else:
            corrected = self.cursor in run.targets[self.selected].results
            run.place_box(self.selected, self.cursor, box)
            verb = "corrected" if corrected else "drawn"
            self.message = (
                f"{self.selected} {verb} at frame {self.cursor + 1}; it re-tracks from here."
            )
        self._claim_recording()

    def select(self, target_id: str | None) -> None:
        """Choose the target a drag redraws (None: drags make new targets)."""
        if target_id is not None and (self.run is None or target_id not in self.run.targets):
            raise InputError(f"no target {target_id!r}")
        self.selected = target_id

    def assign_landmark(self, landmark_id: str | None) -> None:
        """Tie the selected target to `landmark_id` (None: to no landmark)."""
        run = self.require_run()
        if self.selected is None:
            return
        run.assign_landmark(self.selected, landmark_id, self.cursor)

    def delete_selected(self) -> None:
        """Delete the selected target with its results."""
        run = self.require_run()
        if self.selected is None:
            raise InputError("choose the target to delete in 'Drag draws' first")
        run.delete_target(self.selected, self.cursor)
        self.message = f"Deleted {self.selected}."
        self.selected = None

    def load_boxes_json(self) -> None:
        """Place the boxes of the sequence's boxes.json on frame 1, one target per landmark
        (a list of boxes is assigned to landmarks by the correspondence search)."""
        run = self.require_run()
        if self.boxes_path is None or run.scene is None:
            raise InputError("this sequence has no boxes.json")
        boxes = boxes_by_landmark(read_boxes_json(self.boxes_path), run.scene)
        self.stop_playing()
        self.cursor = 0
        run.add_targets(0, boxes)
        self.message = f"Loaded {len(boxes)} boxes from boxes.json on frame 1."
        self._claim_recording()

    # -- playback -----------------------------------------------------------------------------

    def toggle_play(self) -> None:
        """Play from the current frame, or pause."""
        if self.playing:
            self.stop_playing()
            return
        run = self.require_run()
        if self.cursor >= run.frame_count - 1:
            raise InputError("already at the last frame")
        self.playing = True

    def stop_playing(self) -> None:
        """Pause (nothing happens when not playing)."""
        self.playing = False

    def play_step(self) -> None:
        """While playing: show (tracking it first) the next frame; stop at the last."""
        run = self.run
        if run is None or self.cursor >= run.frame_count - 1:
            self.stop_playing()
            return
        self.visit(self.cursor + 1)
        if self.cursor >= run.frame_count - 1:
            self.stop_playing()

    def visit(self, frame_index: int) -> None:
        """Show `frame_index`, tracking there first when it is the frame after the current."""
        run = self.require_run()
        if frame_index == self.cursor + 1:
            run.track_to(frame_index)
            run.advance(frame_index)
        self.cursor = frame_index
        if self.on_visit is not None:
            self.on_visit()

    def step(self, delta: int) -> None:
        """Pause and move `delta` frames (tracking when moving onto the next frame)."""
        run = self.require_run()
        self.stop_playing()
        target = min(max(self.cursor + delta, 0), run.frame_count - 1)
        if target != self.cursor:
            self.visit(target)

    def seek(self, frame_index: int, interrupted: Callable[[], bool] = lambda: False) -> None:
        """Go to `frame_index`; forward past the tracked frames, track (and show) each frame in
        between until there or until `interrupted()` (another command is waiting)."""
        run = self.require_run()
        target = min(max(frame_index, 0), run.frame_count - 1)
        if run.targets and target > self.cursor:
            while self.cursor < target and not interrupted():
                self.visit(self.cursor + 1)
        else:
            self.visit(target)

    # -- sessions -----------------------------------------------------------------------------

    def refresh_sessions(self) -> None:
        """List the recorded sessions, newest first."""
        files = sorted(
            self.config.sessions_dir.glob("*.mcap"), key=lambda p: p.stat().st_mtime, reverse=True
        )
        self.session_choices = {path.name: path for path in files}

    def reopen(self, name: str) -> None:
        """Reopen the session listed as `name` and continue it into a new session file, with
        the tracker parameters it was recorded with."""
        path = self.session_choices.get(name)
        if path is None:
            raise InputError("choose a session from the list first (Refresh sessions)")
        if self.recordings.writer_of(path) is not None:
            raise InputError(f"{path.name} is being recorded by another tab; reopen it later")
        session = open_session(path)
        source = resolve_user_path(session.source, self.roots)
        scene_path = (
            resolve_user_path(session.scene_path, self.roots) if session.scene_path else None
        )
        frames, scene, scene_path = self._load(source, scene_path, scene_given=True)
        try:
            run = Pipeline.resume(
                session,
                frames,
                scene=scene,
                recording=self._recording(source, scene_path),
                tracker_threads=self.config.tracker_threads,
            )
        except Exception:
            frames.close()
            raise
        self._start(run, source, scene_path)
        self.cursor = run.resume_frame
        self._claim_recording()
        note = " (the file was cut short)" if session.truncated else ""
        self.message = (
            f"Reopened {path.name}{note}: {len(run.targets)} targets, continuing from frame "
            f"{self.cursor + 1}; recording to a new session file."
        )

    def export(self, what: str) -> tuple[str, bytes]:
        """(file name, content) of a download: 'tracks', 'poses' or 'mcap' (see EXPORTS)."""
        run = self.require_run()
        path = run.session_path
        if path is None:
            raise InputError("nothing recorded yet: draw a box and track first")
        run.flush()
        if what == "tracks":
            name, content = f"{path.stem}_tracks.zip", exports.tracks_zip(path)
        elif what == "poses":
            name, content = f"{path.stem}_poses.tum", exports.poses_tum(path)
        elif what == "mcap":
            name, content = path.name, path.read_bytes()
        else:
            raise InputError(f"unknown export {what!r}; choose one of {EXPORTS}")
        self.message = f"Sent {name} ({len(content) / 1024:.0f} kB)."
        return name, content

    # -- what the display shows ---------------------------------------------------------------

    def snapshot(self) -> FrameView | None:
        """Everything the display shows for the current frame (None without a run)."""
        if self.run is None:
            return None
        return frame_view(self.run, self.cursor, self.selected, self.message)

    def close(self) -> None:
        """Stop playing and close the run (finishing its recording)."""
        self.stop_playing()
        self.close_run()
