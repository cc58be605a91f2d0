"""The per-tab state, and every command a tab's user can give, with no viser.

One `TabController` per browser tab holds what is open (sequence, scene, the tracking run), the
playback position, the target being edited and the last message. Its public methods are the
tab's commands; the tab's worker thread runs them one at a time, so this state needs no lock.
The panels (app/panels.py) read the state back after each command, and the display thread only
ever sees the immutable `FrameView` snapshots of `snapshot()`. Tests drive this class directly.
"""

from __future__ import annotations

import shutil
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from autotrack.errors import InputError
from autotrack.hybrid.factory import tracker_params
from autotrack.io.frames import FrameSource, open_frames
from autotrack.localization.reacquire import ReacquireParams
from autotrack.localization.refine import RefineParams
from autotrack.localization.scene import Scene, load_scene
from autotrack.pipeline import Pipeline, Recording, TrackedTarget
from autotrack.sessions import Session
from autotrack.tracker.parallel.target_process import WorkerPool
from autotrack_studio import exports
from autotrack_studio.boxes import Box, ground_truth_positions, overlapped_target
from autotrack_studio.config import AppConfig
from autotrack_studio.groundtruth import (
    TruthPoses,
    charted_view,
    load_landmark_truth,
    load_truth,
    load_truth_poses,
)
from autotrack_studio.landmarks import LandmarkTies, load_boxes_json, search_message
from autotrack_studio.owners import BrowserSpace
from autotrack_studio.paths import display_name, find_sequences, resolve_user_path, store_upload
from autotrack_studio.recordings import RecordingRegistry
from autotrack_studio.reopening import SessionList
from autotrack_studio.tracker_choice import TrackerChoice
from autotrack_studio.truth_commands import start_from_truth, truth_views
from autotrack_studio.views import FrameView, frame_view

POSE_OPTIONS = {"refine_params": RefineParams(), "reacquire_params": ReacquireParams()}
"""With a scene, the pipeline gives the solver sub-pixel landmark points and re-acquires lost
landmarks, as `autotrack localize` does."""


class TabController:
    """One tab's state and commands (see the module docstring).

    Args:
        config: How the server was started (sessions folder, start-up sequence, limits).
        roots: Folders this tab may open sequences, scenes and sessions' sources from.
        recordings: The server-wide registry of session files being written.
        tab_id: This tab's id in `recordings`.
        worker_pool: The server-wide pool lending the trackers their child processes (None:
            each run its own).
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
        space: BrowserSpace | None = None,
        worker_pool: WorkerPool | None = None,
    ) -> None:
        self.config = config
        self.worker_pool = worker_pool
        self.space = space or BrowserSpace(config.sessions_dir, config.upload_dir, None)
        """Where this tab's recordings and uploads go, and whose it may list."""
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
        self.tracker = TrackerChoice(self)
        """The Tracker choice and when it applies (app/tracker_choice.py)."""
        self.sessions = SessionList(self)
        """The recorded sessions this tab lists, and reopening them (app/reopening.py)."""
        self.suggested_session: str | None = None
        """The session the Sessions list points to at the start: this browser's last one."""
        self.sequences_opened = 0
        """How many sequences this tab opened (the 3-D scene is rebuilt when it changes)."""
        self.recording_path: Path | None = None
        """The session file this tab writes and has claimed in `recordings`."""
        self.ties = LandmarkTies()
        """Which target is which landmark: the search's last outcome, the hand-chosen ties."""
        self.truth: np.ndarray | None = None
        """The sequence's ground-truth boxes (0-based, one row per frame), if it has some."""
        self.truth_target: str | None = None
        """The target started from the ground truth (scored against it)."""
        self.landmark_truth: dict[str, np.ndarray] = {}
        """Landmark id -> its ground-truth boxes (groundtruth/<landmark>.txt, e.g. the demo's)."""
        self.truth_poses: TruthPoses | None = None
        """The scene's ground-truth camera poses per frame (poses_gt.tum), if known."""
        self.play_seconds = np.zeros(0)
        """Per frame: seconds from the previous played frame to this one (NaN: not played)."""
        self.file_run = False
        """Whether the run is on a sequence it can be opened again on (not a live source or a
        live recording looked through)."""
        self._played_at: float | None = None

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
        run, selected = self.run, self.selected
        return None if run is None or selected is None else run.targets.get(selected)

    @property
    def frame_size(self) -> tuple[int, int]:
        """(width, height) of the open sequence's frames."""
        return self.require_run().frames.frame_size

    # -- opening sequences --------------------------------------------------------------------

    def open_initial(self) -> None:
        """List sequences and sessions, then open the start-up sequence (else the demo); when
        this browser recorded a session before (a reloaded page closed its tab), say how to
        pick it up again."""
        self.refresh_sequences()
        self.sessions.refresh()
        self.open(self.config.sequence or self.config.demo_dir, self.config.scene)
        self.sessions.point_to_last()

    def refresh_sequences(self) -> None:
        """List the sequences under this tab's folders."""
        found = [path for path in find_sequences(self.roots) if not self.space.hides(path)]
        self.sequence_choices = {display_name(path, self.roots): path for path in found}

    def open_listed(self, name: str) -> None:
        """Open the sequence listed as `name`."""
        path = self.sequence_choices.get(name)
        if path is None:
            raise InputError("choose a sequence from the list first")
        self.open(path, None)

    def open_typed(self, text: str) -> None:
        """Open a sequence path typed by the user (it must lie under the allowed folders)."""
        self.open(self.resolve_path(text), None)

    def use_scene(self, text: str) -> None:
        """Reopen the sequence with the scene file typed by the user (empty: no scene)."""
        if self.sequence_path is None:
            raise InputError("open a sequence first")
        scene = self.resolve_path(text.strip()) if text.strip() else None
        self.open(self.sequence_path, scene, scene_given=True)

    def resolve_path(self, text: str) -> Path:
        """A path the user typed (or a session names), under this tab's folders and not in
        another browser's space (app/owners.py)."""
        return resolve_user_path(text, self.roots, hides=self.space.hides)

    def choose_preset(self, name: str) -> None:
        """Use tracker preset `name` from the next target on (app/tracker_choice.py)."""
        self.tracker.choose(name)

    @property
    def preset_pending(self) -> bool:
        """Whether the chosen preset differs from the one the open run's targets track with."""
        return self.tracker.pending

    def restart_with_preset(self) -> None:
        """Open the sequence again with the chosen preset, on the current frame."""
        self.tracker.restart()

    def open_upload(self, file_name: str, content: bytes | Path) -> None:
        """Store an uploaded video or zip of images (bytes or a received file) safely, then
        open it."""
        limits, quota_root = self.config.upload_limits, self.config.upload_dir
        path = store_upload(
            file_name, content, self.space.upload_dir, limits, quota_root=quota_root
        )
        try:
            self.open(path, None)
        except Exception:  # not a readable video or image set: not kept, nor listed
            shutil.rmtree(path if path.is_dir() else path.parent, ignore_errors=True)
            raise
        finally:
            self.refresh_sequences()

    def open(self, path: Path, scene_path: Path | None, *, scene_given: bool = False) -> None:
        """Open a sequence (and its scene: `scene_path`, else a scene.json beside it unless
        `scene_given`) with the chosen preset, closing the current run and its recording."""
        frames, scene, scene_path = self.load_frames(path, scene_path, scene_given=scene_given)
        run = self.new_run(frames, scene, self.new_recording(path, scene_path))
        self.install_run(run, path, scene_path, preset_name=self.preset_name)
        self.file_run = True

    def new_run(
        self,
        frames: FrameSource,
        scene: Scene | None,
        recording: Recording | None,
        session: Session | None = None,
    ) -> Pipeline:
        """A run on `frames` with the chosen preset (or continuing `session` with its own), this
        server's tracker threads and pose options; the frames are closed when it fails."""
        options = {"scene": scene, "recording": recording, **self.tracker_options()}
        try:
            if session is None:
                params, tracker = tracker_params(self.preset_name), self.preset_name
                return Pipeline(frames, params, tracker=tracker, **options, **POSE_OPTIONS)
            return Pipeline.resume(session, frames, **options, **POSE_OPTIONS)
        except Exception:
            frames.close()
            raise

    def tracker_options(self) -> dict:
        """The Pipeline's tracker threads, processes and worker pool for this server."""
        threads, processes = self.config.tracker_concurrency
        return {
            "tracker_threads": threads,
            "tracker_processes": processes,
            "worker_pool": self.worker_pool,
        }

    def load_frames(
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

    def new_recording(self, path: Path, scene_path: Path | None) -> Recording:
        """A new session file in the sessions folder, created at the first box."""
        return Recording(source=str(path), directory=self.space.sessions_dir, scene_path=scene_path)

    def install_run(
        self, run: Pipeline, path: Path, scene_path: Path | None, preset_name: str | None = None
    ) -> None:
        """Make `run` (on the sequence `path`) this tab's run, replacing the current one; the
        Tracker choice shows `preset_name`, by default the run's own (a reopened session's)."""
        self.close_run()
        self.run = run
        self.file_run = False  # open() and reopen() say when the run can be opened again
        self.suggested_session = None
        self.ground_truth = ground_truth_positions(scene_path)
        self.sequence_path, self.scene_path = path, scene_path
        self.preset_name = preset_name or run.tracker_name
        boxes = (path if path.is_dir() else path.parent) / "boxes.json"
        self.boxes_path = boxes if boxes.is_file() and run.scene is not None else None
        self.cursor, self.selected, self.ties = 0, None, LandmarkTies()
        self.play_seconds = np.full(run.frame_count, np.nan)
        self.truth = load_truth(path, run.frame_count)
        landmarks = () if run.scene is None else run.scene.landmark_ids
        self.landmark_truth = load_landmark_truth(path, run.frame_count, landmarks)
        self.truth_poses = load_truth_poses(scene_path, run.frame_count, run.fps)
        self.truth_target = None
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
        run, finished = self.run, self.recording_path
        self.run, self.recording_path, self.boxes_path, self.truth = None, None, None, None
        self.landmark_truth, self.truth_poses = {}, None
        try:
            run.close()  # may raise (a full disk): the file and the frames are let go anyway
        finally:
            run.frames.close()
            if finished is not None:
                self.recordings.release(finished)
                self.sessions.refresh()  # the finished session is listed at once

    def claim_recording(self) -> None:
        """Register the run's session file (created at the first edit) as this tab's."""
        path = None if self.run is None else self.run.session_path
        if path is not None and path != self.recording_path:
            self.recordings.claim(path, self.tab_id)
            self.recording_path = path
            self.sessions.refresh()  # the new session file is listed from its first box

    # -- targets ------------------------------------------------------------------------------

    def place_box(self, box: Box) -> None:
        """A box drawn or typed on the current frame: a new target, or the selected target's
        box redrawn (a correction when it was tracked there; it re-tracks from here). A new box
        on top of a target's box corrects that target instead. With a scene, new targets are
        tied to landmarks by the correspondence search once four boxes are on the frame."""
        self.stop_playing()
        target_id = self.selected or overlapped_target(self.targets(), self.cursor, box)
        if target_id is None:
            self.tracker.follow()
        run = self.require_run()
        if target_id is None:
            if len(run.targets) >= self.config.max_targets:
                raise InputError(
                    f"already {len(run.targets)} targets (the maximum): choose a target in "
                    "'Drag draws' to redraw its box, or delete one first"
                )
            target_id = run.add_target(self.cursor, box, None)
            self.message = f"{target_id} drawn at frame {self.cursor + 1}. {self.tracker.note()}"
            self._search_landmarks()
        else:
            corrected = self.cursor in run.targets[target_id].results
            run.place_box(target_id, self.cursor, box)
            verb = "corrected" if corrected else "drawn"
            why = "" if self.selected else " (the new box lies on it)"
            self.message = (
                f"{target_id} {verb}{why} at frame {self.cursor + 1}; it re-tracks from here."
            )
        self.claim_recording()

    def _search_landmarks(self) -> None:
        """Tie the targets on this frame to landmarks (see LandmarkTies.search) and say how."""
        run = self.require_run()
        self.message += search_message(run, self.ties.search(run, self.cursor))

    def start_from_truth(self) -> None:
        """Start (or restart) targets from the current frame's ground truth (one target's
        box, or every landmark's: app/truth_commands.py); they are scored against it."""
        start_from_truth(self)

    @property
    def has_truth(self) -> bool:
        """Whether the sequence carries ground-truth boxes (one target's, or per landmark)."""
        return self.truth is not None or bool(self.landmark_truth)

    def select(self, target_id: str | None) -> None:
        """Choose the target a drag redraws (None: drags make new targets)."""
        if target_id is not None and (self.run is None or target_id not in self.run.targets):
            raise InputError(f"no target {target_id!r}")
        self.selected = target_id

    def assign_landmark(self, landmark_id: str | None) -> None:
        """Tie the selected target to `landmark_id` by hand (None: to no landmark); a target
        holding that landmark takes the selected one's old landmark."""
        run = self.require_run()
        if self.selected is None:
            return
        if run.targets[self.selected].landmark_id == landmark_id:
            return
        swapped = self.ties.tie_by_hand(run, self.selected, landmark_id, self.cursor)
        swap = "" if swapped is None else f"; {swapped} takes its old landmark"
        self.message = f"{self.selected} tied to {landmark_id or 'no landmark'} by hand{swap}."

    def delete_selected(self) -> None:
        """Delete the selected target with its results."""
        run = self.require_run()
        if self.selected is None:
            raise InputError("choose the target to delete in 'Drag draws' first")
        run.delete_target(self.selected, self.cursor)
        self.ties.forget(self.selected)
        self.message = f"Deleted {self.selected}."
        self.selected = None

    def load_boxes_json(self) -> None:
        """Place the sequence's boxes.json on frame 1, one target per landmark (app/landmarks.py)."""
        load_boxes_json(self)

    # -- playback -----------------------------------------------------------------------------

    def toggle_play(self) -> None:
        """Play from the current frame, or pause."""
        if self.playing:
            self.stop_playing()
            return
        run = self.require_run()
        if self.cursor >= run.frame_count - 1:  # not an error: a Pause pressed as it ended
            self.message = f"At the last frame ({run.frame_count}): step back to play again."
            return
        self.playing = True

    def stop_playing(self) -> None:
        """Pause (nothing happens when not playing)."""
        self.playing = False
        self._played_at = None

    def play_step(self) -> None:
        """While playing: show (tracking it first) the next frame; stop at the last."""
        run = self.run
        if run is None or self.cursor >= run.frame_count - 1:
            self.stop_playing()
            return
        self.visit(self.cursor + 1, playing=True)
        now = time.perf_counter()
        if self._played_at is not None:
            self.play_seconds[self.cursor] = now - self._played_at
        self._played_at = now
        if self.cursor >= run.frame_count - 1:
            self.stop_playing()

    def visit(self, frame_index: int, *, playing: bool = False) -> None:
        """Show `frame_index`, tracking there first when it is the frame after the current.
        `playing`: the frames after it follow, so the trackers' child processes may start on
        the next one while this one is shown (undone, bit for bit, by a pause and an edit)."""
        run = self.require_run()
        if frame_index == self.cursor + 1:
            run.track_to(frame_index - 1)
            run.advance(frame_index, horizon=run.frame_count - 1 if playing else frame_index)
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

    def export(self, what: str) -> tuple[str, bytes]:
        """(file name, content) of a download: 'tracks', 'poses' or 'mcap' (autotrack_studio.exports)."""
        name, content = exports.build(self.require_run(), what)
        self.message = f"Sent {name} ({len(content) / 1024:.0f} kB)."
        return name, content

    # -- what the display shows ---------------------------------------------------------------

    def snapshot(self) -> FrameView | None:
        """Everything the display shows for the current frame (None without a run)."""
        if self.run is None:
            return None
        truths = truth_views(self)
        charted = charted_view(truths, (self.selected, self.truth_target)) if truths else None
        return frame_view(
            self.run,
            self.cursor,
            self.selected,
            self.message,
            self.play_seconds,
            charted,
            truths=truths,
            truth_poses=self.truth_poses,
            playing=self.playing,
        )

    def close(self) -> None:
        """Stop playing and close the run (finishing its recording)."""
        self.stop_playing()
        try:
            self.close_run()
        finally:
            self.space.release()
