"""A tab's session commands: list the recorded sessions, reopen one (continuing it into a new
session file, or looking through a live run's recording on its own frames).

`SessionCommands` is a part of `app.controller.TabController` (its base class), kept apart
because the controller holds the rest of a tab's commands; it uses the controller's state and
opening helpers (`_load`, `_new_run`, `_recording`, `install_run`, `close_run`).
"""

from __future__ import annotations

from pathlib import Path

from autotrack.errors import InputError
from autotrack.localization.scene import load_scene
from autotrack.sessions import open_session
from autotrack.sessions.frames import EmbeddedFrames


class SessionCommands:
    """The Session panel's list and reopening (see the module docstring)."""

    def refresh_sessions(self) -> None:
        """List the recorded sessions this tab's browser may see (app/owners.py), newest first."""
        self.session_choices = {path.name: path for path in self.space.session_files()}

    def reopen(self, name: str) -> None:
        """Reopen the session listed as `name` and continue it into a new session file, with
        the tracker parameters it was recorded with."""
        path = self.session_choices.get(name)
        if path is None:
            raise InputError("choose a session from the list first (Refresh sessions)")
        writer = self.recordings.writer_of(path)
        if writer not in (None, self.tab_id):
            raise InputError(f"{path.name} is being recorded by another tab; reopen it later")
        if writer == self.tab_id:  # this tab's own recording: finished first, then reopened
            self.close_run()
        session = open_session(path)
        if session.image_count:  # a live run's recording: its own frames, to look through
            return self.review_session(path)
        source = self.resolve_path(session.source)
        scene_path = self.resolve_path(session.scene_path) if session.scene_path else None
        frames, scene, scene_path = self._load(source, scene_path, scene_given=True)
        run = self._new_run(frames, scene, self._recording(source, scene_path), session)
        self.install_run(run, source, scene_path)
        self.file_run = True
        self.cursor = run.resume_frame
        self.claim_recording()
        note = " (the file was cut short)" if session.truncated else ""
        self.message = (
            f"Reopened {path.name}{note}: {len(run.targets)} targets, continuing from frame "
            f"{self.cursor + 1}; recording to a new session file."
        )

    def review_session(self, path: Path) -> None:
        """Open a session that embeds its frames (a live run's recording) to look through, on
        those frames and with no new recording: its source cannot be replayed past them."""
        session = open_session(path)
        scene_path = session.scene_path and self.resolve_path(session.scene_path)
        scene = load_scene(scene_path) if scene_path else None
        frames = EmbeddedFrames(session)
        run = self._new_run(frames, scene, None, session)
        self.install_run(run, path, scene_path or None)
        self.cursor = run.resume_frame
        recorded, name = len(frames.recorded_indices), path.name
        self.message = f"Reopened {name}: {recorded} frames recorded live (dropped ones repeat)."
