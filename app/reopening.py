"""A tab's session commands: list the recorded sessions, reopen one (continuing it into a new
session file, or looking through a live run's recording on its own frames), and point a new
tab of a browser to the session it recorded last (a page reload closes the tab it replaces).

`SessionList` is a collaborator of `autotrack_studio.controller.TabController`: it holds the list and uses
the controller only through its public interface (`space`, `recordings`, `tab_id`,
`resolve_path`, `load_frames`, `new_run`, `new_recording`, `install_run`, `close_run`,
`claim_recording`, `cursor`, `message`, `file_run`).
"""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

from autotrack.errors import InputError
from autotrack.localization.scene import load_scene
from autotrack.sessions import open_session
from autotrack.sessions.frames import EmbeddedFrames
from autotrack_studio.browser_text import readable
from autotrack_studio.paths import check_writable

if TYPE_CHECKING:
    from autotrack_studio.controller import TabController


class SessionList:
    """The Session panel's list and reopening for one tab (see the module docstring)."""

    def __init__(self, controller: TabController) -> None:
        self.controller = controller
        self.choices: dict[str, Path] = {}
        """Name shown in the session list -> session file, newest first."""

    def refresh(self) -> None:
        """List the recorded sessions this tab's browser may see (app/owners.py), newest first."""
        self.choices = {readable(path.name): path for path in self.controller.space.session_files()}

    def last_own(self) -> Path | None:
        """The newest session this browser recorded (in its own folder) that no tab is still
        writing: what a reloaded page left behind (None: none)."""
        controller = self.controller
        own = controller.space.sessions_dir
        for path in self.choices.values():
            if path.parent == own and controller.recordings.writer_of(path) is None:
                return path
        return None

    def point_to_last(self) -> None:
        """Choose this browser's last session for the Sessions list (a reloaded page's new
        tab) and say how to pick it up."""
        controller = self.controller
        last = self.last_own()
        controller.suggested_session = None if last is None else last.name
        if last is not None:
            controller.message += (
                f" Your last session here, {last.name}, is chosen in *Session → Sessions*: "
                "*Reopen and continue* picks it up where it stopped."
            )

    def reopen(self, name: str) -> None:
        """Reopen the session listed as `name` and continue it into a new session file, with
        the tracker parameters it was recorded with."""
        controller = self.controller
        path = self.choices.get(name)
        if path is None:
            raise InputError("choose a session from the list first (Refresh sessions)")
        writer = controller.recordings.writer_of(path)
        if writer not in (None, controller.tab_id):
            raise InputError(f"{path.name} is being recorded by another tab; reopen it later")
        check_writable(controller.space.sessions_dir, "sessions")  # the continuation's file
        if writer == controller.tab_id:  # this tab's own recording: finished first, then reopened
            controller.close_run()
        session = open_session(path)
        if session.recorded_live:  # a live run's recording: its own frames, to look through
            return self.review(path)
        source = controller.resolve_path(session.source)
        scene_path = controller.resolve_path(session.scene_path) if session.scene_path else None
        frames, scene, scene_path = controller.load_frames(source, scene_path, scene_given=True)
        recording = controller.new_recording(source, scene_path)
        run = controller.new_run(frames, scene, recording, session)
        controller.install_run(run, source, scene_path)
        controller.file_run = True
        controller.cursor = run.resume_frame
        controller.claim_recording()
        note = " (the file was cut short)" if session.truncated else ""
        controller.message = (
            f"Reopened {path.name}{note}: {len(run.targets)} targets, continuing from frame "
            f"{controller.cursor + 1}; recording to a new session file."
        )

    def review(self, path: Path) -> None:
        """Open a session that embeds its frames (a live run's recording) to look through, on
        those frames and with no new recording: its source cannot be replayed past them."""
        controller = self.controller
        session = open_session(path)
        scene_path = session.scene_path and controller.resolve_path(session.scene_path)
        scene = load_scene(scene_path) if scene_path else None
        frames = EmbeddedFrames(session)
        run = controller.new_run(frames, scene, None, session)
        controller.install_run(run, path, scene_path or None)
        controller.cursor = run.resume_frame
        recorded, name = len(frames.recorded_indices), path.name
        controller.message = (
            f"Reopened {name}: {recorded} frames recorded live (dropped ones repeat)."
        )
