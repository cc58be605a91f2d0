"""AutoTrack (CVPR 2020) correlation-filter tracking for UAV footage.

>>> from autotrack import AutoTrack, preset
>>> tracker = AutoTrack(preset("autotrack"))
>>> result = tracker.init(first_frame_rgb, (x, y, w, h))   # doctest: +SKIP
>>> result = tracker.update(next_frame_rgb)                 # doctest: +SKIP
"""

from importlib.metadata import PackageNotFoundError, version

from autotrack.compile_cache import configure_numba_cache
from autotrack.errors import AutoTrackError, BoxError, InputError, SceneError, SessionError
from autotrack.params import PRESETS, TrackerParams, preset
from autotrack.result import TrackResult

configure_numba_cache()  # before numba is imported: compiled kernels need a writable cache


def __getattr__(name: str):
    # The tracker pulls in numba-compiled features: import it on first use only, so that
    # `autotrack.frames`, `autotrack.evaluation` etc. stay light to import.
    if name in ("AutoTrack", "CvAutoTrack"):
        from autotrack import tracker

        return getattr(tracker, name)
    raise AttributeError(f"module 'autotrack' has no attribute {name!r}")


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
    "SceneError",
    "SessionError",
    "TrackResult",
    "TrackerParams",
    "__version__",
    "preset",
]
