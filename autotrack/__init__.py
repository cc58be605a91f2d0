"""AutoTrack (CVPR 2020) correlation-filter tracking for UAV footage.

>>> from autotrack import AutoTrack, preset
>>> tracker = AutoTrack(preset("autotrack"))
>>> result = tracker.init(first_frame_rgb, (x, y, w, h))   # doctest: +SKIP
>>> result = tracker.update(next_frame_rgb)                 # doctest: +SKIP

The layout (tracker/, localization/, sessions/, evaluation/, synthetic/, io/, pipeline/) is
described in docs/architecture.md.
"""

from importlib import import_module
from importlib.metadata import PackageNotFoundError, version

from autotrack.errors import AutoTrackError, BoxError, InputError, SceneError, SessionError
from autotrack.params import PRESETS, TrackerParams, preset
from autotrack.result import PoseEstimate, TrackResult

# Loaded on first use: the tracker pulls in numba-compiled features, the localiser OpenCV and
# SciPy, sessions MCAP; `import autotrack` and its light modules stay quick to import.
_LAZY = {
    "AutoTrack": "autotrack.tracker.tracker",
    "CvAutoTrack": "autotrack.tracker.tracker",
    "MultiTracker": "autotrack.tracker.parallel.multi",
    "Localizer": "autotrack.localization.localizer",
    "LocalizerParams": "autotrack.localization.localizer",
    "Scene": "autotrack.localization.scene",
    "load_scene": "autotrack.localization.scene",
    "SessionRecorder": "autotrack.sessions.recorder",
    "open_session": "autotrack.sessions.reader",
    "Pipeline": "autotrack.pipeline.pipeline",
    "Recording": "autotrack.pipeline.recording",
    "localize_sequence": "autotrack.pipeline.localize",
    "open_frames": "autotrack.io.frames",
}


def __getattr__(name: str):
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module 'autotrack' has no attribute {name!r}")
    return getattr(import_module(module), name)


try:
    __version__ = version("autotrack-studio")
except PackageNotFoundError:  # running from a source tree that is not installed
    __version__ = "0.0.0+unknown"

__all__ = [
    "PRESETS",
    "AutoTrack",
    "AutoTrackError",
    "BoxError",
    "CvAutoTrack",
    "InputError",
    "Localizer",
    "LocalizerParams",
    "MultiTracker",
    "Pipeline",
    "PoseEstimate",
    "Recording",
    "Scene",
    "SceneError",
    "SessionError",
    "SessionRecorder",
    "TrackResult",
    "TrackerParams",
    "__version__",
    "load_scene",
    "localize_sequence",
    "open_frames",
    "open_session",
    "preset",
]
