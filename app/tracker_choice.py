"""A tab's Tracker choice and when it takes effect: before the run's first target the run is
made again with the chosen preset (so the session records the parameters the targets really
track with); once targets track with another preset the page says so, and `restart` opens the
sequence again with it on the current frame.

`TrackerChoice` is a collaborator of `autotrack_studio.controller.TabController`, using its public
interface only (`run`, `preset_name`, `message`, `cursor`, `file_run`, `sequence_path`,
`scene_path`, `open`, `require_run`).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from autotrack.errors import InputError
from autotrack.params import PRESETS

if TYPE_CHECKING:
    from autotrack_studio.controller import TabController


class TrackerChoice:
    """The Tracker choice of one tab (see the module docstring)."""

    def __init__(self, controller: TabController) -> None:
        self.controller = controller

    def choose(self, name: str) -> None:
        """Use tracker preset `name` from the next target on: a run without targets is made
        again with it at once; a run whose targets track with another preset says so, and
        `restart` opens the sequence again with it."""
        controller = self.controller
        if name not in PRESETS:
            raise InputError(f"unknown tracker preset {name!r}; choose one of {sorted(PRESETS)}")
        controller.preset_name = name
        if controller.run is None or controller.run.params.name == name:
            controller.message = f"Tracker: {name}."
        elif self.follow():
            controller.message = f"Tracker: {name}, for the targets drawn from now on."
        else:
            controller.message = self.note()

    @property
    def pending(self) -> bool:
        """Whether the chosen preset differs from the one the open run's targets track with."""
        controller = self.controller
        return controller.run is not None and controller.run.params.name != controller.preset_name

    def note(self) -> str:
        """What the page says while the chosen preset waits for a restart ('' when none)."""
        controller = self.controller
        if not self.pending:
            return ""
        used, chosen = controller.require_run().params.name, controller.preset_name
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
        """Before the run's first target: make the run again with the chosen preset if it has
        another (the session then records the parameters the targets really use). True when
        the run uses the chosen preset afterwards."""
        controller = self.controller
        run = controller.require_run()
        if run.params.name == controller.preset_name:
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
        """Open the sequence again with the chosen preset, on the current frame (the targets
        are dropped; the session recorded so far is finished and kept)."""
        controller = self.controller
        run = controller.require_run()
        if not self.pending:
            raise InputError(f"this run already tracks with {run.params.name}")
        if not controller.file_run or controller.sequence_path is None:
            raise InputError(self.note())
        cursor = controller.cursor
        controller.open(controller.sequence_path, controller.scene_path, scene_given=True)
        controller.cursor = min(cursor, controller.require_run().frame_count - 1)
        controller.message = (
            f"Restarted with {controller.preset_name} on frame {controller.cursor + 1}: draw "
            "the targets again (or Start from ground truth)."
        )
