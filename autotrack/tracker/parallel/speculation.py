"""What a MultiTracker speculated: the frame its children started on before it was asked.

`MultiTracker.speculate` records the caller's next frame; the next `update` collects the
children's answers only when it is given that very frame (`Speculation.matches`), else the
speculation is undone (`MultiTracker._cancel_speculation`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Speculation:
    """The children's targets are being tracked into `frame` (a read-only view of the shared
    segment they read it from) of the caller's array `given`; `owners`: the children (1, 2,
    ...) that received the speculative update."""

    given: object
    frame: np.ndarray
    owners: tuple[int, ...]

    def matches(self, frame: object) -> bool:
        """Whether `frame` is the frame speculated: the same read-only array object (as a
        pipeline's frame cache gives), or an array of values equal to what the children read
        (values equal to that uint8 frame convert to it). A writeable array is compared by its
        values even when it is the same object: its owner may have written the next frame into
        it since."""
        if frame is self.given and isinstance(frame, np.ndarray) and not frame.flags.writeable:
            return True
        return (
            isinstance(frame, np.ndarray)
            and frame.shape == self.frame.shape
            and bool(np.array_equal(frame, self.frame))
        )
