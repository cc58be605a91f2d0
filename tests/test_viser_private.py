"""app/viser_private.py, the one module touching viser's internals: checked on the installed
viser, and refusing any version it was not checked on (issue 37 item 4)."""

from __future__ import annotations

import http
import urllib.error
import urllib.request

import numpy as np
import pytest
import viser
from websockets.http11 import Response

from autotrack_studio.viser_private import (
    CHECKED_VERSIONS,
    acknowledge_upload,
    check_viser_version,
    guard_handshakes,
    handshake_headers,
    send_uplot_data,
    take_over_uploads,
    upload_button_id,
)
from tests.browser_socket import SocketBrowser


def test_the_installed_viser_is_one_these_internals_were_checked_on() -> None:
    assert {"1.1.1"} == CHECKED_VERSIONS
    assert viser.__version__ in CHECKED_VERSIONS, (
        f"viser {viser.__version__} is installed: check every function of app/viser_private.py "
        "on it (this file's tests), then add it to CHECKED_VERSIONS"
    )
    check_viser_version()
    with pytest.raises(RuntimeError, match=r"viser 1\.2\.0 is installed.*checked on viser 1\.1\.1"):
        check_viser_version("1.2.0")


@pytest.fixture
def server():
    server = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    yield server
    server.stop()


def _connected(server: viser.ViserServer, browser: SocketBrowser) -> int:
    browser.wait_for(lambda: bool(server.get_clients()))
    (client_id,) = server.get_clients()
    return client_id


def test_chart_data_reaches_the_browser_with_its_nulls(server) -> None:
    chart = server.gui.add_uplot(
        data=(np.arange(3.0), np.ones(3)),
        series=(viser.uplot.Series(label="x"), viser.uplot.Series(label="y")),
    )
    with SocketBrowser(server.get_port()) as browser:
        _connected(server, browser)
        send_uplot_data(chart, ((0.0, 1.0, 2.0), (5.0, None, 7.0)))

        def sent() -> list:
            updates = browser.messages("GuiUpdateMessage")
            return [u["updates"]["data"] for u in updates if "data" in u["updates"]]

        browser.wait_for(lambda: bool(sent()))
        assert list(sent()[-1][1]) == [5.0, None, 7.0]
        assert chart.data[1] == (5.0, None, 7.0)
        chart.remove()
        with pytest.raises(RuntimeError, match="removed"):
            send_uplot_data(chart, ((0.0,), (1.0,)))


def _upload_messages(button: str, transfer: str, content: bytes) -> list[dict]:
    start = {
        "type": "FileTransferStartUpload",
        "source_component_uuid": button,
        "transfer_uuid": transfer,
        "filename": "clip.mp4",
        "mime_type": "video/mp4",
        "part_count": 1,
        "size_bytes": len(content),
    }
    part = {
        "type": "FileTransferPart",
        "source_component_uuid": button,
        "transfer_uuid": transfer,
        "part_index": 0,
        "content": content,
    }
    return [start, part]


def test_uploads_are_taken_over_and_given_back(server) -> None:
    button = server.gui.add_upload_button("Upload")
    button_id = upload_button_id(button)
    seen: list[tuple[str, object]] = []
    viser_got: list[bytes] = []
    button.on_upload(lambda _: viser_got.append(button.value.content))

    def on_start(handlers, client_id, message) -> None:  # noqa: ANN001
        seen.append(("start", (message.filename, message.size_bytes)))

    def on_part(handlers, client_id, message) -> None:  # noqa: ANN001
        seen.append(("part", message.content))
        acknowledge_upload(handlers, message.source_component_uuid, message.transfer_uuid, 3, 3)

    handlers = take_over_uploads(server.gui, on_start, on_part)
    with SocketBrowser(server.get_port()) as browser:
        _connected(server, browser)
        for message in _upload_messages(button_id, "t1", b"abc"):
            browser.send(message)
        browser.wait_for(lambda: bool(browser.messages("FileTransferPartAck")))
        assert seen == [("start", ("clip.mp4", 3)), ("part", b"abc")]
        (ack,) = browser.messages("FileTransferPartAck")
        assert (ack["transfer_uuid"], ack["transferred_bytes"], ack["total_bytes"]) == ("t1", 3, 3)
        assert viser_got == []  # viser's own handlers did not see it

        handlers.release()
        for message in _upload_messages(button_id, "t2", b"xyz"):
            browser.send(message)
        browser.wait_for(lambda: viser_got == [b"xyz"])
        assert len(seen) == 2


def test_the_handshake_headers_of_a_client(server) -> None:
    with SocketBrowser(server.get_port(), browser="c" * 32) as browser:
        client_id = _connected(server, browser)
        headers = handshake_headers(server, client_id)
        assert (
            headers is not None and f"autotrack_browser_{server.get_port()}=" in headers["Cookie"]
        )
    assert handshake_headers(server, 10**6) is None


def test_a_check_stands_in_front_of_every_request_viser_answers() -> None:
    wrapped = []

    def wrap(inner):  # noqa: ANN001, ANN202
        wrapped.append(inner)

        def refuse_secret(connection, request):  # noqa: ANN001, ANN202
            if "secret" in request.path:
                return Response(http.HTTPStatus.FORBIDDEN, "Forbidden", request.headers, b"no")
            return inner(connection, request)

        return refuse_secret

    with guard_handshakes(wrap):
        server = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    try:
        assert len(wrapped) == 1 and wrapped[0] is not None
        base = f"http://127.0.0.1:{server.get_port()}"
        with urllib.request.urlopen(f"{base}/", timeout=30) as answer:
            assert answer.status == 200
        with pytest.raises(urllib.error.HTTPError) as refused:
            urllib.request.urlopen(f"{base}/secret", timeout=30)
        assert refused.value.code == 403
    finally:
        server.stop()
