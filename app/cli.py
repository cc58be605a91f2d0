"""`autotrack app [SEQUENCE]`: the browser app (viser) to annotate, track and debug.

The library's `autotrack` command finds this sub-command through the `autotrack.commands`
entry-point group (pyproject.toml), so the library never imports the app. This module imports
only the library and the standard library: `autotrack --help` works on a core install, and
`autotrack app` there says which extra to install.
"""

from __future__ import annotations

import argparse
import signal
import socket
import sys
import threading
from dataclasses import replace
from pathlib import Path

from autotrack.cli.checks import add_tracker_argument
from autotrack.errors import InputError
from autotrack.extras import require_extra
from autotrack.hybrid.factory import SIAMESE_TRACKERS, make_tracker
from autotrack.userdirs import default_sessions_dir

LOOPBACK_HOSTS = ("127.0.0.1", "localhost", "::1")


def add_parser(subparsers: argparse._SubParsersAction) -> None:
    """Add `autotrack app` to the `autotrack` command line."""
    parser = subparsers.add_parser(
        "app",
        help="open the browser app: draw boxes, watch AutoTrack, see the camera trajectory",
        description=(
            "Start the AutoTrack Studio web app (viser) and print its URL. Without SEQUENCE it "
            "opens the embedded demo (four landmarks, a scene and its ground-truth trajectory). "
            "Browser users may only open sequences and scenes under SEQUENCE's folder, the "
            "--allow-root folders, the demo and their own uploads."
        ),
    )
    parser.add_argument(
        "sequence",
        type=Path,
        nargs="?",
        default=None,
        help="folder of images, video, or benchmark sequence folder (default: the demo)",
    )
    parser.add_argument("--scene", type=Path, default=None, help="scene file for SEQUENCE")
    parser.add_argument(
        "--host",
        default="127.0.0.1",
        help="interface to listen on (default 127.0.0.1: this machine only; 0.0.0.0: everyone)",
    )
    parser.add_argument(
        "--no-token",
        action="store_true",
        help=(
            "serve without the access token in the URL (unsafe: any web page you visit, and "
            "on a non-loopback --host anyone on the network, can then drive the app)"
        ),
    )
    parser.add_argument("--port", type=int, default=8080, help="port to try first (default 8080)")
    parser.add_argument(
        "--sessions",
        type=Path,
        metavar="DIR",
        help="folder for session recordings and uploads (default: the user's data folder, "
        "$XDG_DATA_HOME/autotrack/sessions or ~/.local/share/autotrack/sessions)",
    )
    parser.add_argument(
        "--share-sessions",
        action="store_true",
        help=(
            "list every browser's sessions and uploads to every browser (default: a browser "
            "sees its own, plus the session files put directly in --sessions)"
        ),
    )
    parser.add_argument(
        "--allow-root",
        dest="allow_roots",
        type=Path,
        action="append",
        default=[],
        metavar="DIR",
        help="a folder whose sequences browser users may open (repeatable)",
    )
    add_tracker_argument(parser)  # the tracker of new runs
    parser.add_argument(
        "--canvas-fps",
        type=float,
        default=5.0,
        help="initial cap on frames/s drawn on the 3-D canvas (software WebGL is slow)",
    )
    parser.add_argument(
        "--max-targets",
        type=int,
        default=4,
        help="most targets a tab may have at once (default 4: the demo scene's landmarks)",
    )
    parser.add_argument(
        "--allow-live",
        action="store_true",
        help="let browser users open live sources: a camera index, an rtsp:// or http(s):// "
        "stream, or a video under the allowed folders played in real time (off by default)",
    )
    parser.set_defaults(func=run)


def startup_roots(sequence: Path | None, scene: Path | None, allow_roots: list[Path]) -> list[Path]:
    """The folders a browser may open: the --allow-root folders plus the folders holding the
    start-up sequence and scene. Each must exist."""
    roots: list[Path] = []
    for root in allow_roots:
        if not root.is_dir():
            raise InputError(f"--allow-root {root} is not an existing folder")
        roots.append(root.resolve())
    if sequence is not None:
        if not sequence.exists():
            raise InputError(f"no such sequence: {sequence}")
        roots.append(sequence.resolve() if sequence.is_dir() else sequence.resolve().parent)
    if scene is not None:
        if not scene.is_file():
            raise InputError(f"no such scene file: {scene}")
        roots.append(scene.resolve().parent)
    return roots


PORT_ATTEMPTS = 20
"""A taken --port moves on to the next one, this many ports at most (viser would try 1000 and
then wait forever, or pass 65535 and wait forever)."""


def check_bindable(host: str) -> None:
    """Fail at once, with a message, when `host` is no address this machine can listen on
    (viser would retry port after port and then wait forever)."""
    try:
        addresses = socket.getaddrinfo(host or None, 0, type=socket.SOCK_STREAM)
    except (socket.gaierror, UnicodeError) as error:
        raise InputError(f"--host {host}: not a known address ({error})") from error
    family, kind, proto, _name, address = addresses[0]
    try:
        with socket.socket(family, kind, proto) as probe:
            probe.bind(address)
    except OSError as error:
        raise InputError(
            f"--host {host}: cannot listen there ({error.strerror or error})"
        ) from error


def _port_is_free(host: str, port: int) -> bool:
    """Every address of `host` can listen on `port` (as asyncio binds it: SO_REUSEADDR)."""
    for family, kind, proto, _name, address in socket.getaddrinfo(
        host or None, port, type=socket.SOCK_STREAM, flags=socket.AI_PASSIVE
    ):
        try:
            with socket.socket(family, kind, proto) as probe:
                probe.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
                probe.bind(address)
        except OSError:
            return False
    return True


def free_port(host: str, first: int) -> int:
    """The first port from `first` that `host` can listen on (0: the OS picks one), trying
    PORT_ATTEMPTS ports and never past 65535; InputError when all are taken."""
    if first == 0:
        return 0
    last = min(first + PORT_ATTEMPTS - 1, 65535)
    for port in range(first, last + 1):
        if _port_is_free(host, port):
            return port
    span = f"{first}" if last == first else f"{first}-{last}"
    raise InputError(f"--port {first}: port {span} on {host} is taken; give another --port")


def run(args: argparse.Namespace) -> int:
    """Start the app and serve until Ctrl-C or SIGTERM."""
    require_extra("viser", "app", "autotrack app")
    if not 0 <= args.port <= 65535:
        raise InputError(f"--port must be 0..65535, got {args.port}")
    if not args.canvas_fps > 0:
        raise InputError(f"--canvas-fps must be positive, got {args.canvas_fps}")
    if args.max_targets < 1:
        raise InputError(f"--max-targets must be at least 1, got {args.max_targets}")
    roots = startup_roots(args.sequence, args.scene, args.allow_roots)
    check_bindable(args.host)
    if args.preset in SIAMESE_TRACKERS:
        make_tracker(args.preset)  # NanoTrack's model files load, or the app says why, in one line
    port = free_port(args.host, args.port)

    from autotrack_studio.config import (
        AppConfig,  # the app's modules (and viser) load only when it starts
    )
    from autotrack_studio.memory import limit_malloc_arenas
    from autotrack_studio.server import StudioServer

    limit_malloc_arenas()  # before the server starts any thread (app/memory.py)
    config = AppConfig(
        sequence=None if args.sequence is None else args.sequence.resolve(),
        scene=None if args.scene is None else args.scene.resolve(),
        host=args.host,
        port=port,
        sessions_dir=default_sessions_dir() if args.sessions is None else args.sessions,
        allowed_roots=tuple(roots),
        tracker_preset=args.preset,
        canvas_fps=args.canvas_fps,
        max_targets=args.max_targets,
        share_sessions=args.share_sessions,
        allow_live=args.allow_live,
    )
    if args.no_token:
        config = replace(config, token=None)
    if config.sequence is None and not config.demo_dir.is_dir():
        raise InputError(f"the embedded demo is missing from {config.demo_dir}: give a SEQUENCE")
    studio = StudioServer(config)
    print(f"AutoTrack Studio: {studio.url}", flush=True)
    if args.host not in LOOPBACK_HOSTS:
        print(
            f"listening on {args.host}: other machines can reach this app; "
            "they can open only the allowed folders",
            flush=True,
        )
    if args.no_token:
        reach = "anyone who can reach the port" if args.host not in LOOPBACK_HOSTS else ""
        print(
            "warning: --no-token: any web page open in a browser on this machine"
            + (f", and {reach}," if reach else "")
            + " can drive this app",
            file=sys.stderr,
            flush=True,
        )
    if args.allow_live:
        print(
            "--allow-live: browser users may open cameras, rtsp/http streams this machine can "
            "reach and videos under the allowed folders",
            flush=True,
        )
    print(f"sessions are recorded in {config.sessions_dir.resolve()}; Ctrl-C stops", flush=True)
    stopped = threading.Event()
    # A service manager's SIGTERM also closes the tabs, so every recording is finished.
    signal.signal(signal.SIGTERM, lambda _signum, _frame: stopped.set())
    try:
        stopped.wait()
    finally:
        studio.stop()
    return 0
