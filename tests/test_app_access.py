"""Only the app's own pages may talk to it: token, Origin and Host checks (issue 17)."""

from __future__ import annotations

import subprocess
import sys
import urllib.error
import urllib.request
from pathlib import Path

import pytest
import viser
import websockets.sync.client as ws_client
from websockets.exceptions import InvalidStatus

from autotrack_studio.config import AppConfig
from tests.browser_socket import SocketBrowser

DEMO = Path(__file__).resolve().parents[1] / "static" / "demo"


@pytest.fixture
def studio(tmp_path: Path):
    from autotrack_studio.server import StudioServer

    (tmp_path / "demo").mkdir()
    server = StudioServer(
        AppConfig(port=0, sessions_dir=tmp_path / "sessions", demo_dir=tmp_path / "demo")
    )
    yield server
    server.stop()


def _get(url: str, headers: dict[str, str] | None = None) -> tuple[int, dict[str, str], bytes]:
    request = urllib.request.Request(url, headers=headers or {})
    try:
        with urllib.request.urlopen(request, timeout=30) as answer:
            return answer.status, dict(answer.headers), answer.read()
    except urllib.error.HTTPError as error:
        return error.code, dict(error.headers), error.read()


def _websocket(studio, *, token: str | None, origin: str | None, cookie: str | None = None):
    query = "" if token is None else f"?token={token}"
    headers = {} if cookie is None else {"Cookie": cookie}
    return ws_client.connect(
        f"ws://127.0.0.1:{studio.port}/{query}",
        subprotocols=[f"viser-v{viser.__version__}"],
        origin=origin,
        additional_headers=headers,
        open_timeout=30,
    )


def test_printed_url_carries_the_token_and_sets_the_cookie(studio) -> None:
    assert studio.url == f"http://127.0.0.1:{studio.port}/?token={studio.config.token}"
    status, headers, page = _get(studio.url)
    assert status == 200 and b"<html" in page.lower()
    cookie = headers["Set-Cookie"]
    assert cookie.startswith(f"autotrack_token_{studio.port}={studio.config.token};")
    assert "HttpOnly" in cookie and "SameSite=Strict" in cookie
    # The page's later requests carry the cookie instead of the query.
    assert _get(f"http://127.0.0.1:{studio.port}/", {"Cookie": cookie.split(";")[0]})[0] == 200


@pytest.mark.parametrize(
    "url_end", ["/", "/?token=wrong", "/index.html", "/..%2f..%2fetc%2fpasswd", "/favicon.ico"]
)
def test_pages_without_the_token_are_forbidden(studio, url_end: str) -> None:
    status, _, body = _get(f"http://127.0.0.1:{studio.port}{url_end}")
    assert status == 403 and b"<html" not in body.lower()


def test_a_rebinding_host_name_is_forbidden_even_with_the_token(studio) -> None:
    status, _, _ = _get(studio.url, {"Host": f"attacker.example:{studio.port}"})
    assert status == 403
    assert studio.access.refused == 1


@pytest.mark.parametrize(
    ("token", "origin"),
    [
        (None, None),  # a script without the token
        ("wrong", None),
        (None, "http://evil.example"),  # another site's page (its cookie is never sent)
        ("right", "http://evil.example"),  # even knowing the token, another origin
        ("right", "null"),  # a sandboxed frame or a file:// page
    ],
)
def test_a_foreign_websocket_gets_nothing_and_opens_no_tab(studio, token, origin) -> None:
    token = studio.config.token if token == "right" else token
    with pytest.raises(InvalidStatus) as refused:
        _websocket(studio, token=token, origin=origin)
    assert refused.value.response.status_code == 403
    assert studio.tabs == {}


def test_the_apps_own_page_connects_with_its_cookie(studio) -> None:
    _, headers, _ = _get(studio.url)
    cookie = headers["Set-Cookie"].split(";")[0]
    origin = f"http://127.0.0.1:{studio.port}"
    with _websocket(studio, token=None, origin=origin, cookie=cookie) as connection:
        assert len(connection.recv(timeout=30)) > 0  # the GUI and scene arrive


def test_no_token_serves_without_it(tmp_path: Path) -> None:
    from autotrack_studio.server import StudioServer

    (tmp_path / "demo").mkdir()
    studio = StudioServer(
        AppConfig(port=0, sessions_dir=tmp_path / "s", demo_dir=tmp_path / "demo", token=None)
    )
    try:
        assert studio.url == f"http://127.0.0.1:{studio.port}"
        assert _get(studio.url)[0] == 200
        # Still no other site's page.
        with pytest.raises(InvalidStatus):
            _websocket(studio, token=None, origin="http://evil.example")
    finally:
        studio.stop()


def test_unbindable_host_exits_with_one_line(tmp_path: Path) -> None:
    done = subprocess.run(
        [sys.executable, "-m", "autotrack.cli", "app", "--host", "203.0.113.7", "--port", "0"],
        capture_output=True,
        text=True,
        timeout=120,
        cwd=tmp_path,
    )
    assert done.returncode == 2
    assert done.stderr.count("\n") == 1 and "--host 203.0.113.7" in done.stderr
    assert "Traceback" not in done.stderr


def test_the_page_names_the_browser_and_its_websocket_carries_the_name(studio) -> None:
    """The page's answer sets a random browser cookie; the server reads it back from the
    websocket handshake of that browser's tabs (whose sessions and uploads are whose)."""
    cookies = [
        value.split(";")[0] for key, value in _all_headers(studio.url) if key == "Set-Cookie"
    ]
    names = dict(cookie.split("=", 1) for cookie in cookies)
    browser = names[f"autotrack_browser_{studio.port}"]
    assert len(browser) == 32 and browser.isalnum()
    token_cookie = f"autotrack_token_{studio.port}={studio.config.token}"
    # A page that already has its name keeps it.
    again = _all_headers(
        f"http://127.0.0.1:{studio.port}/",
        {"Cookie": f"{token_cookie}; autotrack_browser_{studio.port}={browser}"},
    )
    assert not any("autotrack_browser" in value for key, value in again if key == "Set-Cookie")

    def browser_of_new_tab(browser_cookie: str | None) -> str | None:
        """The browser the server reads from the handshake of a new tab's websocket."""
        known = set(studio.tabs)
        with SocketBrowser(studio.port, token=studio.config.token, browser=browser_cookie) as tab:
            tab.wait_for(lambda: set(studio.tabs) - known)
            (tab_id,) = set(studio.tabs) - known
            return studio._browser_of(tab_id)

    assert browser_of_new_tab(browser) == browser
    assert browser_of_new_tab(None) is None  # no browser cookie


def _all_headers(url: str, headers: dict[str, str] | None = None) -> list[tuple[str, str]]:
    request = urllib.request.Request(url, headers=headers or {})
    with urllib.request.urlopen(request, timeout=30) as answer:
        return list(answer.headers.items())
