"""The slow start shown: while the tracker's kernels compile, every tab shows what is happening
and the seconds elapsed (a box drawn meanwhile says what it waits for), and the notice goes
once they are ready. In headless Chromium too (test-artifacts/app-startup-notice.png)."""

from __future__ import annotations

import threading
import time
from pathlib import Path

import pytest
import viser

from autotrack_studio.config import AppConfig
from autotrack_studio.startup import KernelWarmUp
from tests.test_app import DEMO, _free_port, _wait_for


class FakeClock:
    def __init__(self) -> None:
        self.now = 100.0

    def __call__(self) -> float:
        return self.now


def test_the_notice_counts_the_seconds_until_the_kernels_are_ready() -> None:
    release, clock, shown = threading.Event(), FakeClock(), []
    warm_up = KernelWarmUp(release.wait, clock)
    stop = warm_up.subscribe(shown.append)
    assert warm_up.running and "compiling its kernels… 0 s so far" in shown[-1]
    assert "~12-60 s" in shown[-1] and "12 s so far" not in warm_up.box_wait()
    clock.now += 12.0
    _wait_for(lambda: "12 s so far" in shown[-1], timeout=10)  # ticked once a second
    assert "12 s so far" in warm_up.box_wait()
    release.set()
    _wait_for(lambda: shown[-1] == "", timeout=10)
    assert not warm_up.running and warm_up.notice() == "" and warm_up.box_wait() == ""
    assert warm_up.elapsed() == pytest.approx(12.0)
    stop()


def test_a_failed_warm_up_ends_the_notice_and_says_why() -> None:
    def broken() -> None:
        raise RuntimeError("no compiler")

    warm_up = KernelWarmUp(broken)
    warm_up.join(10)
    assert not warm_up.running and warm_up.error == "RuntimeError: no compiler"


@pytest.fixture
def slow_studio(tmp_path: Path, monkeypatch):
    """A server whose kernel warm-up runs until the test releases it."""
    from autotrack_studio import startup
    from autotrack_studio.server import StudioServer

    release = threading.Event()
    monkeypatch.setattr(startup, "warm_up", release.wait)
    config = AppConfig(
        port=_free_port(), sessions_dir=tmp_path / "sessions", demo_dir=DEMO, tracker_threads=1
    )
    server = StudioServer(config)
    yield server, release
    release.set()
    server.stop()


def test_a_tab_shows_the_warm_up_and_a_box_drawn_meanwhile_says_why_it_waits(slow_studio) -> None:
    from tests.test_app import RecordingChannel, _demo_boxes

    server, release = slow_studio
    tab = server.open_tab(
        RecordingChannel(), server.viser.gui, server.viser.scene, tab_id=1, browser_id="a"
    )
    assert tab.wait_idle()
    startup = tab.panels.startup
    assert startup.visible and "Preparing the tracker" in startup.content
    _wait_for(lambda: "1 s so far" in startup.content or "2 s so far" in startup.content)
    letterbox = tab.display.canvas_mapping(tab.controller.frame_size)
    x, y, w, h = _demo_boxes()["A"]
    busy: list[str] = []
    original = tab._busy
    tab._busy = lambda what: (busy.append(what), original(what))
    tab.rect_selected(
        viser.SceneRectSelectEvent(
            client=None,
            client_id=0,
            screen_min=letterbox.frame_to_screen(x, y),
            screen_max=letterbox.frame_to_screen(x + w, y + h),
            modifier="shift",
        )
    )
    assert "waiting for the tracker's kernels to compile" in busy[-1]
    release.set()
    _wait_for(lambda: not startup.visible and startup.content == "")
    assert tab.wait_idle() and list(tab.controller.run.targets) == ["T1"]


@pytest.mark.browser
def test_the_page_shows_the_warm_up_notice(slow_studio, tmp_path: Path) -> None:
    from tests.test_app_browser import ARTIFACTS, CHROMIUM, studio_page

    if not CHROMIUM.exists():
        pytest.skip("/usr/bin/chromium is not installed (apt-get install chromium)")
    pytest.importorskip("playwright.sync_api")
    server, release = slow_studio
    ARTIFACTS.mkdir(exist_ok=True)
    with studio_page(server, tmp_path / "profile") as (page, _tab):
        notice = page.get_by_text("Preparing the tracker")
        _wait_for(lambda: notice.count() == 1, timeout=30)
        time.sleep(2.5)  # the seconds count on in the page
        assert page.get_by_text("s so far (the first run on a machine").count() == 1
        page.screenshot(path=str(ARTIFACTS / "app-startup-notice.png"))
        release.set()
        _wait_for(lambda: notice.count() == 0, timeout=30)
