"""Server memory over a churn of browser tabs: open, four boxes, play, close, repeat (issue 42).

Starts the app's server in this process on a ping-pong copy of the embedded demo (its 60
frames forward, back, forward, ... so a tab can play as many frames as asked), then for each
tab: a websocket opens it as a browser would (tests/browser_socket.py), the demo's four boxes
are drawn on frame 1, the tab tracks `frames / tabs` frames and its websocket closes. After each
close it waits for the Tab to be freed and prints the server's RSS, the live Tab objects and
the count of Python objects; at the end the RSS growth since the first tab closed. glibc's
per-thread malloc arenas keep freed pages scattered: the server caps them as `autotrack app`
does (`limit_malloc_arenas`); `--default-arenas` leaves glibc's default to see their share.

    python benchmarks/tab_churn.py [--tabs 8] [--frames 3000]
"""

from __future__ import annotations

import argparse
import gc
import shutil
import sys
import tempfile
import time
import weakref
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))  # tests/ holds the websocket browser and the drag helper

from autotrack_studio.config import AppConfig  # noqa: E402
from autotrack_studio.memory import limit_malloc_arenas, release_freed_memory  # noqa: E402
from autotrack_studio.server import StudioServer  # noqa: E402
from tests.browser_socket import SocketBrowser  # noqa: E402
from tests.test_app import DEMO, _draw_demo_boxes  # noqa: E402


def ping_pong_demo(folder: Path, frames: int) -> Path:
    """The demo's frames forward and back until `frames` long, with its scene and boxes."""
    source = sorted((DEMO / "img").iterdir())
    cycle = source + source[-2:0:-1]
    (folder / "img").mkdir(parents=True)
    for index in range(frames):
        shutil.copy(cycle[index % len(cycle)], folder / "img" / f"{index + 1:05d}.jpg")
    for name in ("scene.json", "boxes.json"):
        shutil.copy(DEMO / name, folder / name)
    return folder


def rss_mb() -> float:
    """This process's resident memory (MB)."""
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
    raise RuntimeError("no VmRSS in /proc/self/status")


def wait(predicate, timeout: float = 300.0) -> None:  # noqa: ANN001
    """Wait until `predicate()` holds (raises after `timeout` seconds)."""
    deadline = time.monotonic() + timeout
    while not predicate():
        if time.monotonic() > deadline:
            raise TimeoutError("the server never got there")
        time.sleep(0.05)


def one_tab(server: StudioServer, frames: int) -> weakref.ref:
    """Open a tab over a websocket, draw the four boxes, track `frames` frames, close it."""
    known = set(server.tabs)
    browser = SocketBrowser(server.port, token=server.config.token)
    wait(lambda: set(server.tabs) - known)
    (tab_id,) = set(server.tabs) - known
    tab = server.tabs[tab_id]
    if not tab.wait_idle(300):
        raise TimeoutError("the tab never opened its sequence")
    _draw_demo_boxes(tab)
    tab.worker.submit(tab.seek, frames - 1)
    if not tab.wait_idle(3600) or tab.controller.cursor != frames - 1:
        raise RuntimeError(
            f"the tab stopped at frame {tab.controller.cursor}: {tab.controller.message}"
        )
    reference = weakref.ref(tab)
    del tab
    browser.close()
    wait(lambda: tab_id not in server.tabs)
    return reference


def main() -> None:
    """Run the churn and print RSS per closed tab."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--tabs", type=int, default=8)
    parser.add_argument("--frames", type=int, default=3000, help="frames over all tabs")
    parser.add_argument(
        "--default-arenas", action="store_true", help="glibc's arenas, not the server's cap"
    )
    args = parser.parse_args()
    capped = not args.default_arenas and limit_malloc_arenas()
    per_tab = args.frames // args.tabs
    with tempfile.TemporaryDirectory() as scratch:
        sequence = ping_pong_demo(Path(scratch) / "pingpong", per_tab)
        server = StudioServer(
            AppConfig(
                port=0,
                sequence=sequence,
                sessions_dir=Path(scratch) / "sessions",
                tracker_threads=1,
                token="churn",
            )
        )
        server.warm_up.join()
        arenas = "malloc arenas capped" if capped else "glibc's default arenas"
        print(
            f"{args.tabs} tabs x {per_tab} frames, four targets, {arenas}; "
            f"start RSS {rss_mb():.1f} MB"
        )
        references: list[weakref.ref] = []
        first = None
        try:
            for cycle in range(args.tabs):
                references.append(one_tab(server, per_tab))
                wait(lambda: gc.collect() >= 0 and references[-1]() is None, timeout=120)
                release_freed_memory()
                rss = rss_mb()
                first = rss if first is None else first
                alive = sum(reference() is not None for reference in references)
                objects = len(gc.get_objects())
                print(
                    f"tab {cycle + 1}: RSS {rss:.1f} MB ({rss - first:+.1f}), live tabs {alive}, "
                    f"Python objects {objects}"
                )
        finally:
            server.stop()
        print(f"growth after the first tab: {rss - first:+.1f} MB over {args.tabs - 1} tabs")


if __name__ == "__main__":
    main()
