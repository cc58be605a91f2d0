"""A server that runs for weeks for many users (issue 42): closed tabs freed, odd file names,
read-only and full disks, stalled uploads. Tabs are driven over real websockets
(tests/browser_socket.py), so viser's own connect and disconnect paths run."""

from __future__ import annotations

import gc
import time
import weakref
from pathlib import Path

import pytest

from app.config import AppConfig
from tests.browser_socket import SocketBrowser
from tests.test_app import DEMO, _draw_demo_boxes


@pytest.fixture
def studio(tmp_path: Path):
    if not (DEMO / "img").is_dir():
        pytest.skip("static/demo is missing")
    from app.server import StudioServer

    server = StudioServer(
        AppConfig(
            port=0,
            sessions_dir=tmp_path / "sessions",
            demo_dir=DEMO,
            tracker_threads=1,
            token="secret-token",
        )
    )
    server.warm_up.join()
    yield server
    server.stop()


def _wait(predicate, timeout: float = 120.0) -> None:
    deadline = time.monotonic() + timeout
    while not predicate():
        assert time.monotonic() < deadline, "condition not reached"
        time.sleep(0.05)


def open_socket_tab(studio, **options):  # noqa: ANN001, ANN003, ANN201
    """A tab opened over a websocket: (the browser, the server's Tab for it)."""
    known = set(studio.tabs)
    browser = SocketBrowser(studio.port, token=studio.config.token, **options)
    _wait(lambda: set(studio.tabs) - known)
    (tab_id,) = set(studio.tabs) - known
    tab = studio.tabs[tab_id]
    assert tab.wait_idle()
    return browser, tab


def _live(references: list[weakref.ref]) -> int:
    gc.collect()
    return sum(reference() is not None for reference in references)


def test_closed_tabs_are_freed_with_their_controller_and_results(studio) -> None:
    """Each tab opens the demo, tracks four targets a few frames and is closed; afterwards no
    Tab, controller or run of them is alive (issue 42 item 1: the upload receiver kept each
    client's connection, which held the tab through its scene callbacks)."""
    references: list[weakref.ref] = []
    for _ in range(3):
        browser, tab = open_socket_tab(studio)
        _draw_demo_boxes(tab)
        tab.worker.submit(tab.seek, 4)
        assert tab.wait_idle()
        assert tab.controller.cursor == 4 and tab.controller.run.targets
        references += [weakref.ref(tab), weakref.ref(tab.controller)]
        references.append(weakref.ref(tab.controller.run))
        del tab
        browser.close()
        _wait(lambda: not studio.tabs)
    _wait(lambda: _live(references) == 0)
