"""The viser server: one `Tab` per browser tab, and the little state the tabs share.

Shared (guarded by `StudioServer.lock`): the configuration (allowed roots, sessions folder,
limits) and the set of session files being recorded right now, so no tab reopens a file
another tab is still writing. Everything else (sequence, targets, trackers, results, poses,
the session file, playback, GUI and 3-D scene) belongs to one tab.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass, field
from pathlib import Path

import viser

from app.channel import ClientChannel, ViserClientChannel
from app.paths import UploadLimits, normalise_roots
from app.tab import Tab

DEMO_DIR = Path(__file__).resolve().parents[1] / "static" / "demo"
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
    sessions_dir: Path = Path("sessions")
    """Where session recordings (and uploads, under uploads/) are written."""
    allowed_roots: tuple[Path, ...] = ()
    """Folders a browser user may open sequences and scenes from (plus the demo and uploads)."""
    demo_dir: Path = DEMO_DIR
    """The embedded demo."""
    tracker_preset: str = "autotrack"
    """Tracker preset of new runs (autotrack, strcf, strcf+asr, strcf+atr, autotrack+)."""
    tracker_threads: int = 2
    """Threads each multi-target tracker may use."""
    canvas_fps: float = 5.0
    """Initial cap on frames per second sent to the 3-D canvas background (software WebGL
    draws only a few per second; the GUI video panel is not capped)."""
    upload_limits: UploadLimits = field(default_factory=UploadLimits)
    """Bounds on uploads."""

    @property
    def upload_dir(self) -> Path:
        """Folder receiving uploaded videos and unpacked zips."""
        return self.sessions_dir / "uploads"

    def browsable_roots(self) -> tuple[Path, ...]:
        """Every folder a tab may open things from: the allowed roots, the demo, the uploads."""
        self.upload_dir.mkdir(parents=True, exist_ok=True)
        extra = [root for root in (self.demo_dir, self.upload_dir) if root.is_dir()]
        return normalise_roots([*self.allowed_roots, *extra])


class StudioServer:
    """A running app: the viser server plus one `Tab` per connected browser tab."""

    def __init__(self, config: AppConfig) -> None:
        self.config = config
        config.sessions_dir.mkdir(parents=True, exist_ok=True)
        self.roots = config.browsable_roots()
        self.lock = threading.Lock()
        """Guards `tabs` and `recording` (the state tabs share)."""
        self.tabs: dict[int, Tab] = {}
        self.recording: dict[Path, int] = {}
        """Session files being written now -> the id of the tab writing each."""
        self.viser = viser.ViserServer(
            host=config.host, port=config.port, label="AutoTrack Studio", verbose=False
        )
        self.viser.gui.configure_theme(control_width="large")
        # Docked, the panel does not cover the canvas, so the whole frame stays drawable.
        self.viser.gui.main_panel.dock_right()
        self.viser.on_client_connect(self._connect)
        self.viser.on_client_disconnect(self._disconnect)

    @property
    def port(self) -> int:
        """The port actually bound (viser silently moves past a taken one)."""
        return self.viser.get_port()

    @property
    def url(self) -> str:
        """Address to open in a browser."""
        host = self.config.host
        shown = "127.0.0.1" if host in ("0.0.0.0", "") else host
        if ":" in shown:
            shown = f"[{shown}]"
        return f"http://{shown}:{self.port}"

    def _connect(self, client: viser.ClientHandle) -> None:
        self.open_tab(ViserClientChannel(client), client.gui, client.scene, tab_id=client.client_id)

    def _disconnect(self, client: viser.ClientHandle) -> None:
        with self.lock:
            tab = self.tabs.pop(client.client_id, None)
        if tab is not None:
            tab.close()

    def open_tab(
        self,
        channel: ClientChannel,
        gui: viser.GuiApi,
        scene: viser.SceneApi,
        *,
        tab_id: int,
    ) -> Tab:
        """Build a tab on the given GUI and scene handles (a client's, or the server's in
        tests) and open the start-up sequence in it."""
        tab = Tab(self, channel, gui, scene, tab_id=tab_id)
        with self.lock:
            self.tabs[tab_id] = tab
        tab.open_initial()
        return tab

    def claim_recording(self, path: Path, tab_id: int) -> None:
        """Note that `tab_id` writes the session file `path`."""
        with self.lock:
            self.recording[path.resolve()] = tab_id

    def release_recording(self, path: Path) -> None:
        """The session file `path` is closed."""
        with self.lock:
            self.recording.pop(path.resolve(), None)

    def recorded_by(self, path: Path) -> int | None:
        """The tab writing `path` right now, if any."""
        with self.lock:
            return self.recording.get(path.resolve())

    def stop(self) -> None:
        """Close every tab (finishing their recordings) and stop the server."""
        with self.lock:
            tabs = list(self.tabs.values())
            self.tabs.clear()
        for tab in tabs:
            tab.close()
        self.viser.stop()
