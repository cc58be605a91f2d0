"""In-app playback against the trackers alone: four targets on the demo (boxes.json), played
as fast as tracking goes in a tab of the app, against the same `Pipeline` (scene, poses,
recording, the app's tracker threads and processes) advanced over the same frames with nothing
else. Runs alternate (app, alone, app, alone, ...); prints each run's frames per second and the
median in-app / trackers-alone ratio.

With --browser, the tab is a headless Chromium page (/usr/bin/chromium, playwright), which
draws the canvas, video and charts on the same machine as a user's would; without, the tab's
display thread sends to a browser-less channel (the server's own costs only).

python benchmarks/app_playback.py
python benchmarks/app_playback.py --repeats 3 --browser
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import tempfile
import time
from contextlib import nullcontext
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from autotrack.io.boxes_json import read_boxes_json  # noqa: E402
from autotrack.io.frames import open_frames  # noqa: E402
from autotrack.localization.pnp import boxes_by_landmark  # noqa: E402
from autotrack.localization.scene import load_scene  # noqa: E402
from autotrack.params import preset  # noqa: E402
from autotrack.pipeline import Pipeline, Recording  # noqa: E402
from autotrack.tracker.parallel.warmup import warm_up  # noqa: E402
from autotrack_studio.config import AppConfig  # noqa: E402
from autotrack_studio.controller import POSE_OPTIONS  # noqa: E402

DEMO = REPO / "static" / "demo"


def trackers_alone(config: AppConfig, sessions: Path) -> float:
    """Frames per second of the app's pipeline over the demo with nothing else running."""
    scene = load_scene(DEMO / "scene.json")
    boxes = boxes_by_landmark(read_boxes_json(DEMO / "boxes.json"), scene)
    threads, processes = config.tracker_concurrency
    frames = open_frames(DEMO)
    recording = Recording(source=str(DEMO), directory=sessions, scene_path=DEMO / "scene.json")
    with Pipeline(
        frames,
        preset("autotrack"),
        scene=scene,
        recording=recording,
        tracker_threads=threads,
        tracker_processes=processes,
        **POSE_OPTIONS,
    ) as run:
        run.add_targets(0, boxes)
        last = run.frame_count - 1
        started = time.perf_counter()
        for index in range(1, last + 1):
            run.advance(index, horizon=last)
        seconds = time.perf_counter() - started
    frames.close()
    return last / seconds


def chromium_cpu_seconds() -> float:
    """CPU seconds the machine's running Chromium processes have used (Linux /proc; 0 where
    there is none)."""
    ticks = os.sysconf("SC_CLK_TCK")
    total = 0.0
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            text = stat.read_text()
        except OSError:  # the process ended meanwhile
            continue
        if text[text.index("(") + 1 : text.rindex(")")].startswith("chromium"):
            fields = text[text.rindex(")") + 2 :].split()  # from field 3 (state) on
            total += (int(fields[11]) + int(fields[12])) / ticks  # utime + stime
    return total


def in_app(config: AppConfig, browser: bool, profile: Path) -> tuple[float, float]:
    """Frames per second of a tab playing the demo with its four boxes, as fast as it goes,
    and the cores Chromium used meanwhile (0 without a browser)."""
    from autotrack_studio.server import StudioServer

    server = StudioServer(config)
    server.warm_up.join()
    try:
        with _tab(server, browser, profile) as tab:
            tab.worker.submit(tab.controller.load_boxes_json)
            assert tab.wait_idle()
            tab.panels.playback.unlimited.value = True
            controller = tab.controller
            last = controller.run.frame_count - 1
            tab.worker.submit(controller.toggle_play)
            _wait(lambda: controller.cursor >= 1)
            started, first = time.perf_counter(), controller.cursor
            browser_cpu = chromium_cpu_seconds()
            _wait(lambda: controller.cursor >= last)
            seconds = time.perf_counter() - started
            browser_cpu = chromium_cpu_seconds() - browser_cpu
            assert tab.wait_idle()
            return (last - first) / seconds, browser_cpu / seconds
    finally:
        server.stop()


def _wait(predicate, timeout: float = 600.0) -> None:
    deadline = time.monotonic() + timeout
    while not predicate():
        if time.monotonic() > deadline:
            raise TimeoutError("playback did not get there")
        time.sleep(0.005)


def _tab(server, browser: bool, profile: Path):
    if browser:
        sys.path.insert(0, str(REPO))
        from tests.test_app_browser import studio_page

        return _page_tab(studio_page(server, profile))
    from tests.test_app import RecordingChannel

    tab = server.open_tab(
        RecordingChannel(), server.viser.gui, server.viser.scene, tab_id=1, browser_id="bench"
    )
    assert tab.wait_idle()
    return nullcontext(tab)


class _page_tab:
    def __init__(self, page_context) -> None:
        self._context = page_context

    def __enter__(self):
        _page, tab = self._context.__enter__()
        return tab

    def __exit__(self, *exc) -> None:
        self._context.__exit__(*exc)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=2, help="runs of each (default 2)")
    parser.add_argument("--browser", action="store_true", help="a headless Chromium tab")
    args = parser.parse_args()
    warm_up()
    with tempfile.TemporaryDirectory() as folder:
        root = Path(folder)
        config = AppConfig(port=0, sessions_dir=root / "sessions", demo_dir=DEMO)
        config.sessions_dir.mkdir()
        app_rates, alone_rates, browser_cores = [], [], []
        for repeat in range(args.repeats):
            rate, cores = in_app(config, args.browser, root / f"profile{repeat}")
            app_rates.append(rate)
            browser_cores.append(cores)
            alone_rates.append(trackers_alone(config, config.sessions_dir))
            browser_use = f" (Chromium {cores:.2f} cores)" if args.browser else ""
            print(
                f"run {repeat + 1}: in app {app_rates[-1]:.1f} frames/s{browser_use}, "
                f"trackers alone {alone_rates[-1]:.1f} frames/s",
                flush=True,
            )
    ratios = [a / b for a, b in zip(app_rates, alone_rates, strict=True)]
    where = "a headless Chromium tab" if args.browser else "a tab without a browser"
    print(
        f"in-app / trackers-alone: {statistics.median(ratios):.2f} (median of {len(ratios)}, "
        f"{where}; four targets on the demo, {statistics.median(app_rates):.1f} vs "
        f"{statistics.median(alone_rates):.1f} frames/s)"
    )
    if args.browser:
        print(
            f"Chromium used {statistics.median(browser_cores):.2f} of the machine's "
            f"{os.cpu_count()} cores while the tab played (median; docs/app.md says where)"
        )


if __name__ == "__main__":
    main()
