"""The viser server: one `Tab` per browser tab, and the little state the tabs share.

Shared: the configuration (allowed roots, sessions folder, limits) and the registry of session
files being recorded right now (app/recordings.py), so no tab reopens a file another tab is
still writing. Everything else (sequence, targets, trackers, results, poses, the session file,
playback, GUI and 3-D scene) belongs to one tab (app/controller.py holds it).
"""

from __future__ import annotations

import logging
import threading

import viser

from autotrack.errors import AutoTrackError
from autotrack.tracker.parallel.target_process import WorkerPool
from autotrack_studio.access import AccessGuard
from autotrack_studio.channel import ClientChannel, ViserClientChannel
from autotrack_studio.config import AppConfig
from autotrack_studio.memory import release_freed_memory
from autotrack_studio.owners import BrowserSpace, browser_tag
from autotrack_studio.recordings import RecordingRegistry
from autotrack_studio.startup import KernelWarmUp
from autotrack_studio.tab import Tab
from autotrack_studio.uploads import UploadReceiver
from autotrack_studio.viser_private import check_viser_version, guard_handshakes, handshake_headers

LOG = logging.getLogger(__name__)


class StudioServer:
    """A running app: the viser server plus one `Tab` per connected browser tab."""

    def __init__(self, config: AppConfig) -> None:
        check_viser_version()
        self.config = config
        config.sessions_dir.mkdir(parents=True, exist_ok=True)
        self.roots = config.browsable_roots()
        self.recordings = RecordingRegistry()
        self.worker_pool = WorkerPool()
        """Tracking child processes lent to every tab's runs (started once per server)."""
        self.uploads = UploadReceiver(config.incoming_dir, config.upload_dir, config.upload_limits)
        self._lock = threading.Lock()
        self.tabs: dict[int, Tab] = {}
        """Open tabs by id (guarded by a lock: tabs connect and leave on viser's threads)."""
        self.access = AccessGuard(config.token, config.host)
        with guard_handshakes(self.access.wrap):
            self.viser = viser.ViserServer(
                host=config.host, port=config.port, label="AutoTrack Studio", verbose=False
            )
        if not self.access.installed:
            self.viser.stop()
            raise RuntimeError("the access check could not be installed in viser's server")
        self.access.port = self.viser.get_port()
        self.viser.gui.configure_theme(control_width="large")
        # Docked, the panel does not cover the canvas, so the whole frame stays drawable.
        self.viser.gui.main_panel.dock_right()
        self.viser.on_client_connect(self._connect)
        self.viser.on_client_disconnect(lambda client: self.close_tab(client.client_id))
        # Compile the tracker's kernels now, so the first box drawn answers at once; every
        # tab shows how it goes meanwhile (app/startup.py).
        self.warm_up = KernelWarmUp()

    @property
    def port(self) -> int:
        """The port actually bound (viser silently moves past a taken one)."""
        return self.viser.get_port()

    @property
    def url(self) -> str:
        """Address to open in a browser (with the access token, unless started without)."""
        host = self.config.host
        shown = "127.0.0.1" if host in ("0.0.0.0", "::", "") else host
        if ":" in shown:
            shown = f"[{shown}]"
        query = "" if self.config.token is None else f"/?token={self.config.token}"
        return f"http://{shown}:{self.port}{query}"

    def _connect(self, client: viser.ClientHandle) -> None:
        self.open_tab(
            ViserClientChannel(client),
            client.gui,
            client.scene,
            tab_id=client.client_id,
            browser_id=self._browser_of(client.client_id),
        )

    def _browser_of(self, client_id: int) -> str | None:
        """The browser cookie of a client's websocket handshake (None if it sent none).

        viser does not pass the handshake on (app/viser_private.py reads it); a client without
        one gets a space of its own (nothing is shared by mistake)."""
        headers = handshake_headers(self.viser, client_id)
        return None if headers is None else self.access.browser_id(headers)

    def open_tab(
        self,
        channel: ClientChannel,
        gui: viser.GuiApi,
        scene: viser.SceneApi,
        *,
        tab_id: int,
        browser_id: str | None = None,
    ) -> Tab:
        """Build a tab on the given GUI and scene handles (a client's, or the server's in
        tests) and open the start-up sequence in it. `browser_id` names the browser (its
        cookie): tabs of one browser share sessions and uploads (None: a space of its own)."""
        config = self.config
        space = BrowserSpace(
            config.sessions_dir,
            config.upload_dir,
            browser_tag(browser_id),
            shared=config.share_sessions,
        )
        roots = config.browsable_roots(space.upload_roots())
        tab = Tab(
            config,
            roots,
            self.recordings,
            channel,
            gui,
            scene,
            tab_id=tab_id,
            space=space,
            worker_pool=self.worker_pool,
            warm_up=self.warm_up,
        )
        self.uploads.attach(
            gui,
            tab.panels.sequence.upload,
            tab_id,
            tab.receive_upload_file,
            tab.refuse_upload,
            browser=space.tag,
        )
        with self._lock:
            self.tabs[tab_id] = tab
        tab.open_initial()
        return tab

    def close_tab(self, tab_id: int) -> None:
        """Close a tab (its browser went away), finishing its recording; the memory it held
        goes back to the system."""
        with self._lock:
            tab = self.tabs.pop(tab_id, None)
        self.uploads.forget_tab(tab_id)
        if tab is not None:
            _close(tab)
            del tab
            release_freed_memory()

    def stop(self) -> None:
        """Close every tab (finishing their recordings) and stop the server."""
        with self._lock:
            tabs = list(self.tabs.values())
            self.tabs.clear()
        for tab in tabs:
            _close(tab)
        self.worker_pool.close()
        self.viser.stop()


def _close(tab: Tab) -> None:
    """Close a tab; a failure to finish its files (a full disk) is logged in one line, the tab
    is let go all the same (its recording released, app/controller.py close_run)."""
    try:
        tab.close()
    except (OSError, AutoTrackError) as error:
        LOG.warning("tab %s closed with an error: %s", tab.tab_id, error)
