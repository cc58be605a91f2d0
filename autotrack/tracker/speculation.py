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
    """The children's targets are being tracked into `frame` (the uint8 copy every tracker
    reads) of the caller's array `given`; `owners`: the children (1, 2, ...) that received
    the speculative update."""

    given: object
    frame: np.ndarray
    owners: tuple[int, ...]

    def matches(self, frame: object) -> bool:
        """Whether `frame` is the frame speculated: the same array object, or an array of equal
        values (values equal to the uint8 copy convert to that very copy)."""
        if frame is self.given:
            return True
        return (
            isinstance(frame, np.ndarray)
            and frame.shape == self.frame.shape
            and bool(np.array_equal(frame, self.frame))
        )
