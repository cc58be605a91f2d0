"""What the tracker reports for each frame: the box and the signals inside the filter."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class TrackResult:
    """One frame of one target.

    Boxes are `(x, y, w, h)` in 0-based pixel coordinates (the top-left pixel is (0, 0)); add 1
    to x and y for the benchmarks' 1-based convention. Maps are float32 on the filter's cell grid, centred: the map's centre element is
    the search-region centre (zero displacement).
    """

    frame_index: int
    """0-based index of the frame in the sequence the tracker was fed."""
    box: tuple[float, float, float, float]
    """Estimated target box (x, y, w, h), 0-based pixels."""
    peak_score: float
    """Maximum of the response map (NaN in the first frame, where nothing is detected)."""
    response_map: np.ndarray | None
    """Detection response on the cell grid, centred (None in the first frame)."""
    local_variation: np.ndarray | None
    """Local response variation Pi (paper eq. 2), centred; None before the third frame."""
    global_variation: float
    """Global variation eta = ||Pi||_2 / 1e4 (spectral norm, release scaling); NaN before frame 3."""
    theta_ref: float
    """Reference temporal penalty (eq. 4); the fixed theta when ATR is off."""
    theta: float
    """Temporal penalty used by the last ADMM iteration of this frame (eq. 13)."""
    aberrant: bool
    """True when eta >= phi: the filter was not updated this frame (aberrance stop)."""
    scale_factor: float
    """Current scale relative to the first frame's target size."""
    search_box: tuple[float, float, float, float]
    """Image region (x, y, w, h, 0-based pixels) the response map covers."""

    @property
    def center(self) -> tuple[float, float]:
        """Box centre (cx, cy) in 0-based pixels."""
        x, y, w, h = self.box
        return (x + w / 2.0, y + h / 2.0)

    def box_array(self) -> np.ndarray:
        """The box as a float64 array [x, y, w, h]."""
        return np.asarray(self.box, dtype=np.float64)
