"""A tab's Tracker choice and when it takes effect: before the run's first target the run is
made again with the chosen tracker (so the session records the tracker and parameters the
targets really track with); once targets track with another tracker the page says so, and
`restart` opens the sequence again with it on the current frame.

The choices are the AutoTrack presets, `nanotrack` and `hybrid` (`autotrack.hybrid.factory`);
choosing NanoTrack or the hybrid loads NanoTrack's model files once, so files that cannot be
loaded are refused at the choice, in one line, and the tab keeps its tracker.

`TrackerChoice` is a collaborator of `autotrack_studio.controller.TabController`, using its public
interface only (`run`, `preset_name`, `message`, `cursor`, `file_run`, `sequence_path`,
`scene_path`, `open`, `require_run`).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from autotrack.errors import InputError
from autotrack.hybrid.factory import SIAMESE_TRACKERS, TRACKERS, make_tracker

if TYPE_CHECKING:
    from autotrack_studio.controller import TabController


class TrackerChoice:
    """The Tracker choice of one tab (see the module docstring)."""

    def __init__(self, controller: TabController) -> None:
        self.controller = controller

    def choose(self, name: str) -> None:
        """Use tracker `name` from the next target on: a run without targets is made again
        with it at once; a run whose targets track with another tracker says so, and
        `restart` opens the sequence again with it."""
        controller = self.controller
        if name not in TRACKERS:
            raise InputError(f"unknown tracker {name!r}; choose one of {', '.join(TRACKERS)}")
        if name in SIAMESE_TRACKERS:
            make_tracker(name)  # NanoTrack's model files load, or the choice is refused here
        controller.preset_name = name
        if controller.run is None or controller.run.tracker_name == name:
            controller.message = f"Tracker: {name}."
        elif self.follow():
            controller.message = f"Tracker: {name}, for the targets drawn from now on."
        else:
            controller.message = self.note()

    @property
    def pending(self) -> bool:
        """Whether the chosen tracker differs from the one the open run's targets track with."""
        controller = self.controller
        return controller.run is not None and controller.run.tracker_name != controller.preset_name

    def note(self) -> str:
        """What the page says while the chosen tracker waits for a restart ('' when none)."""
        controller = self.controller
        if not self.pending:
            return ""
        used, chosen = controller.require_run().tracker_name, controller.preset_name
        if not controller.file_run:
            return (
                f"This run tracks with {used}: {chosen} applies to the next sequence opened "
                "(a live source's run cannot be restarted)."
            )
        return (
            f"This run's targets track with {used}: {chosen} applies only after "
            f"*Sequence → Restart with {chosen}* (opens this sequence again on this frame; "
            "the session recorded so far is kept)."
        )

    def follow(self) -> bool:
        """Before the run's first target: make the run again with the chosen tracker if it has
        another (the session then records the tracker the targets really use). True when the
        run uses the chosen tracker afterwards."""
        controller = self.controller
        run = controller.require_run()
        if run.tracker_name == controller.preset_name:
            return True
        if run.targets or not controller.file_run or controller.sequence_path is None:
            return False
        cursor, message = controller.cursor, controller.message
        controller.open(controller.sequence_path, controller.scene_path, scene_given=True)
        controller.cursor, controller.message = (
            min(cursor, controller.require_run().frame_count - 1),
            message,
        )
        return True

    def restart(self) -> None:
        """Open the sequence again with the chosen tracker, on the current frame (the targets
        are dropped; the session recorded so far is finished and kept)."""
        controller = self.controller
        run = controller.require_run()
        if not self.pending:
            raise InputError(f"this run already tracks with {run.tracker_name}")
        if not controller.file_run or controller.sequence_path is None:
            raise InputError(self.note())
        cursor = controller.cursor
        controller.open(controller.sequence_path, controller.scene_path, scene_given=True)
        controller.cursor = min(cursor, controller.require_run().frame_count - 1)
        controller.message = (
            f"Restarted with {controller.preset_name} on frame {controller.cursor + 1}: draw "
            "the targets again (or Start from ground truth)."
        )
