"""How the app server was started, and the folders a browser may open things from."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from autotrack.userdirs import default_sessions_dir
from autotrack_studio.access import new_token
from autotrack_studio.paths import UploadLimits, normalise_roots


def _embedded_demo() -> Path:
    """The demo inside the installed package (the wheel maps the repository's static/demo to
    the package's demo/, pyproject.toml), else the source tree's static/demo."""
    package = Path(__file__).resolve().parent
    installed = package / "demo"
    return installed if installed.is_dir() else package.parent / "static" / "demo"


DEMO_DIR = _embedded_demo()
"""The embedded demo sequence (img/, scene.json, boxes.json, poses_gt.tum)."""


@dataclass(frozen=True)
class AppConfig:
    """How the app server was started."""

    sequence: Path | None = None
    """Sequence each new tab opens (None: the embedded demo)."""
    scene: Path | None = None
    """Scene file for `sequence` (None: a scene.json beside the sequence, if any)."""
    host: str = "127.0.0.1"
    """Interface to bind; 127.0.0.1 keeps the app local to this machine."""
    port: int = 8080
    """Port to try first (viser moves on to the next free one)."""
    sessions_dir: Path = field(default_factory=default_sessions_dir)
    """Where session recordings (and uploads, under uploads/) are written (default: the user's
    data folder, `autotrack.userdirs`)."""
    allowed_roots: tuple[Path, ...] = ()
    """Folders a browser user may open sequences and scenes from (plus the demo and uploads)."""
    demo_dir: Path = DEMO_DIR
    """The embedded demo."""
    tracker_preset: str = "autotrack"
    """Tracker of new runs: an AutoTrack preset (autotrack, strcf, strcf+asr, strcf+atr,
    autotrack+), nanotrack or hybrid (`autotrack.hybrid.factory.TRACKERS`)."""
    tracker_threads: int | None = None
    """Threads each multi-target tracker may use (None: see `tracker_concurrency`)."""
    tracker_processes: int | None = None
    """Processes each multi-target tracker spreads its targets over (None: see
    `tracker_concurrency`)."""
    max_targets: int = 4
    """Most targets a tab may have at once (four landmarks with the demo's scene)."""
    canvas_fps: float = 5.0
    """Initial cap on frames per second sent to the 3-D canvas background (software WebGL
    draws only a few per second; the GUI video panel is not capped)."""
    token: str | None = field(default_factory=new_token)
    """Secret every request must carry (in the URL, then a cookie); None: no token (warned)."""
    allow_live: bool = False
    """Whether browser users may open live sources (cameras, rtsp/http streams, videos played
    in real time): `autotrack app --allow-live`."""
    upload_limits: UploadLimits = field(default_factory=UploadLimits)
    """Bounds on uploads."""
    share_sessions: bool = False
    """List every browser's sessions and uploads to every tab (default: each browser sees its
    own and those the operator put in the sessions folder; app/owners.py)."""

    @property
    def tracker_concurrency(self) -> tuple[int, int]:
        """(threads, processes) of each run's trackers: as chosen, else the library's default
        for `max_targets` targets (one thread and two processes on two cores or more; a child
        process starts only when a second target is drawn)."""
        from autotrack.tracker.parallel.multi import chosen_concurrency

        return chosen_concurrency(self.tracker_threads, self.tracker_processes, self.max_targets)

    @property
    def upload_dir(self) -> Path:
        """Folder receiving uploaded videos and unpacked zips."""
        return self.sessions_dir / "uploads"

    @property
    def incoming_dir(self) -> Path:
        """Folder receiving uploads while they arrive (outside every folder a tab may open)."""
        return self.sessions_dir / ".incoming"

    def browsable_roots(self, uploads: tuple[Path, ...] | None = None) -> tuple[Path, ...]:
        """Every folder a tab may open things from: the allowed roots, the demo, the uploads
        (`uploads`: the upload folders of the tab's browser; default: the whole folder)."""
        self.upload_dir.mkdir(parents=True, exist_ok=True)
        upload_roots = (self.upload_dir,) if uploads is None else uploads
        allowed = normalise_roots(self.allowed_roots)
        # The demo and the uploads need not exist: a closing tab of the same browser removes
        # its empty upload folder (BrowserSpace.release) while a reloaded page's tab opens.
        extra = [Path(root).resolve() for root in (self.demo_dir, *upload_roots) if root.is_dir()]
        return allowed + tuple(dict.fromkeys(root for root in extra if root not in allowed))
