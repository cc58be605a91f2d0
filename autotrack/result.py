"""What the pipeline reports for each frame: a target's box and the signals inside its filter
(`TrackResult`), and the camera pose with the reason when there is none to trust
(`PoseEstimate`)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

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
    spatial_window: np.ndarray | None = None
    """The spatial regularisation weights u the filter was trained with on this frame (eq. 3
    with ASR), centred like the maps; None when the filter was not trained (aberrant)."""

    @property
    def center(self) -> tuple[float, float]:
        """Box centre (cx, cy) in 0-based pixels."""
        x, y, w, h = self.box
        return (x + w / 2.0, y + h / 2.0)

    def box_array(self) -> np.ndarray:
        """The box as a float64 array [x, y, w, h]."""
        return np.asarray(self.box, dtype=np.float64)

    @property
    def has_maps(self) -> bool:
        """True when the result carries any map (response, local variation, spatial window)."""
        return any(
            values is not None
            for values in (self.response_map, self.local_variation, self.spatial_window)
        )

    def renumbered(self, frame_index: int) -> TrackResult:
        """The same result on frame `frame_index` (a tracker counts its frames from the one
        it started on; its owner numbers them its own way). Itself when already numbered so:
        a result is immutable, and the copy is per target and frame."""
        if self.frame_index == frame_index:
            return self
        return replace(self, frame_index=frame_index)

    def without_maps(self) -> TrackResult:
        """The same result with its maps dropped (boxes and scalar signals kept): what a long
        run keeps of a frame outside its map window (the session recording has the maps)."""
        if not self.has_maps:
            return self
        return replace(self, response_map=None, local_variation=None, spatial_window=None)


@dataclass(frozen=True)
class PoseEstimate:
    """Camera pose of one frame, or the reason there is none to trust."""

    frame_index: int
    """0-based index of the frame."""
    valid: bool
    """True when the pose passed every check; False poses carry NaN rotation and position."""
    rotation: np.ndarray
    """Camera-to-world rotation (3x3): columns are the camera axes in world coordinates."""
    position: np.ndarray
    """Camera centre in world coordinates (3,), metres."""
    reprojection_errors: dict[str, float]
    """Distance (px) between each landmark's reprojection and its box centre, NaN if unused."""
    used_landmarks: tuple[str, ...]
    """Landmarks the pose was solved from."""
    reason: str = ""
    """Empty when valid, else why the frame is not trusted."""
    rms_error_px: float = math.nan
    """RMS reprojection error over the landmarks used (px)."""
    position_std_m: float = math.nan
    """Predicted 1-sigma uncertainty of the camera position (metres, all axes together)."""
    excluded_landmarks: dict[str, str] = field(default_factory=dict)
    """Landmarks left out of the solve and why (lost, low peak score, aberrant, outlier)."""

    def quaternion_xyzw(self) -> np.ndarray:
        """The rotation as a unit quaternion (qx, qy, qz, qw), TUM order; NaN when invalid."""
        if not np.all(np.isfinite(self.rotation)):
            return np.full(4, np.nan)
        # scipy's rotations load on first use: `import autotrack` stays light.
        from scipy.spatial.transform import Rotation

        return Rotation.from_matrix(self.rotation).as_quat(canonical=True)
