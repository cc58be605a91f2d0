"""Who may talk to the server: a per-server secret token plus `Host` and `Origin` checks.

Any web page the user visits can open a websocket to 127.0.0.1, and a DNS-rebinding page can
even read HTTP answers; binding to loopback alone keeps out other machines, not other pages.
So, as Jupyter does, the server makes a random token at start and prints it in its URL:

- the page (`GET /?token=...`) is served only with the right token, and its answer sets a
  `SameSite=Strict`, `HttpOnly` cookie holding the token (one name per port), so the page's
  websocket (whose URL has no query) and its later requests carry it;
- every request, the websocket handshake included, needs the token (query or cookie);
- a request carrying an `Origin` header must come from the server's own origin (`Origin`
  equal to `Host`): another site's page is refused even with the cookie;
- `Host` must name this server (a loopback name, or the address it was bound to) unless it
  listens on every interface, where the token alone decides: a rebinding name is refused.

The page's answer also sets `autotrack_browser_PORT`, a random id naming the browser (same
flags, kept a year), by which tabs of one browser share sessions and uploads and do not see
other browsers' (`app/owners.py`).

viser builds its websockets server inside `ViserServer.__init__` and offers no hook, so
`app/viser_private.py`'s `guard_handshakes` puts `AccessGuard.wrap` in front of viser's own
`process_request` while the server starts. If viser stops starting its server that way the
check is not installed and the server refuses to start (`AccessGuard.installed`).
"""

from __future__ import annotations

import hmac
import http
import secrets
from collections.abc import Callable
from http.cookies import CookieError, SimpleCookie
from urllib.parse import parse_qs, urlsplit

from websockets.datastructures import Headers
from websockets.http11 import Request, Response

LOOPBACK_NAMES = frozenset({"127.0.0.1", "localhost", "::1"})
"""Host names that mean this machine."""
WILDCARD_HOSTS = frozenset({"0.0.0.0", "::", ""})
"""Bind addresses meaning every interface."""

ProcessRequest = Callable[[object, Request], Response | None]


def new_token() -> str:
    """A fresh random token (192 bits, URL-safe)."""
    return secrets.token_urlsafe(24)


def _same_secret(given: str, token: str) -> bool:
    """Whether `given` is the token, in constant time (any text: compared as UTF-8 bytes)."""
    return hmac.compare_digest(given.encode("utf-8", "surrogateescape"), token.encode("utf-8"))


def _host_name(netloc: str) -> str:
    """The host part of `host[:port]` or `[v6]:port`, lower-cased."""
    try:
        return (urlsplit(f"//{netloc}").hostname or "").lower()
    except ValueError:  # e.g. an unclosed IPv6 bracket
        return ""


class AccessGuard:
    """The check made on every HTTP request and websocket handshake."""

    def __init__(self, token: str | None, bound_host: str) -> None:
        self.token = token
        """The secret (None: no token asked, the server was started with `--no-token`)."""
        self.bound_host = bound_host
        self.port = 0
        """The port the server listens on (set once bound; it names the cookie)."""
        self.installed = False
        """True once the check sits in front of the server's handshakes."""
        self.refused = 0
        """Requests refused so far."""

    @property
    def cookie_name(self) -> str:
        """The cookie carrying the token (per port: cookies do not separate ports)."""
        return f"autotrack_token_{self.port}"

    @property
    def browser_cookie_name(self) -> str:
        """The cookie naming the browser (whose sessions and uploads are whose: app/owners.py)."""
        return f"autotrack_browser_{self.port}"

    def _cookie(self, headers: Headers, name: str) -> str | None:
        cookie = SimpleCookie()
        try:
            cookie.load("; ".join(headers.get_all("Cookie")))
        except CookieError:
            return None
        morsel = cookie.get(name)
        return None if morsel is None else morsel.value

    def browser_id(self, headers: Headers) -> str | None:
        """The browser a request (the websocket handshake) came from, if its cookie is set."""
        value = self._cookie(headers, self.browser_cookie_name)
        return value if value and len(value) <= 64 and value.isalnum() else None

    def host_allowed(self, host_header: str) -> bool:
        """Whether a request's `Host` names this server."""
        if self.bound_host in WILDCARD_HOSTS:
            return True
        name = _host_name(host_header)
        return name in LOOPBACK_NAMES or name == self.bound_host.strip("[]").lower()

    def _token_given(self, request: Request) -> tuple[bool, bool]:
        """(the request carries the token, it came in the query string)."""
        if self.token is None:
            return True, False
        query = parse_qs(urlsplit(request.path).query).get("token", [])
        if any(_same_secret(value, self.token) for value in query):
            return True, True
        value = self._cookie(request.headers, self.cookie_name)
        return value is not None and _same_secret(value, self.token), False

    def problem(self, request: Request) -> str | None:
        """Why `request` is refused, or None when it may go on."""
        hosts = request.headers.get_all("Host")
        origins = request.headers.get_all("Origin")
        if len(hosts) > 1 or len(origins) > 1:
            return "a request may carry one Host and at most one Origin header"
        host = hosts[0] if hosts else ""
        if not self.host_allowed(host):
            return f"Host {host[:100]!r} does not name this server"
        origin = origins[0] if origins else None
        if origin is not None and urlsplit(origin).netloc.lower() != host.lower():
            return f"requests from {origin[:100]!r} are not accepted"
        if not self._token_given(request)[0]:
            return "the access token is missing or wrong: open the URL `autotrack app` printed"
        return None

    def wrap(self, inner: ProcessRequest | None) -> ProcessRequest:
        """`inner` (viser's page server) behind the check; a good token in the query also
        sets the cookie on the page's answer."""
        self.installed = True

        def process_request(connection: object, request: Request) -> Response | None:
            try:
                reason = self.problem(request)
            except ValueError:  # a header no check can read (a malformed URL)
                reason = "the request's headers are malformed"
            if reason is not None:
                self.refused += 1
                return Response(
                    http.HTTPStatus.FORBIDDEN,
                    "Forbidden",
                    Headers({"Content-Type": "text/plain; charset=utf-8"}),
                    f"Forbidden: {reason}\n".encode(),
                )
            response = None if inner is None else inner(connection, request)
            if response is not None and self._token_given(request)[1]:
                response.headers["Set-Cookie"] = (
                    f"{self.cookie_name}={self.token}; Path=/; HttpOnly; SameSite=Strict"
                )
            page = urlsplit(request.path).path in ("/", "/index.html")
            if response is not None and page and self.browser_id(request.headers) is None:
                response.headers["Set-Cookie"] = (
                    f"{self.browser_cookie_name}={secrets.token_hex(16)}; Path=/; "
                    "Max-Age=31536000; HttpOnly; SameSite=Strict"
                )
            return response

        return process_request
