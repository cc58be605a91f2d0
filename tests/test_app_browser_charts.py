"""What only the browser shows, in headless Chromium: the signal charts made once and as wide
as their panel, readable axes (a flat theta, the log η axis by decades), gaps where frames have
no value, and playback that stops at the last frame with the button back to Play.

Reads uPlot's own state in the page (viser registers each chart under
window.__viserTestpoints; `_values`, `_splits` and `_paths` are uPlot's drawn ticks, labels
and line gaps). Needs /usr/bin/chromium and playwright, as tests/test_app_browser.py.
"""

from __future__ import annotations

import math
import time

import pytest

from tests.test_app_browser import (
    SAME_CHARTS_JS,
    _wait_for,
    studio,  # noqa: F401 (the fixture)
    studio_page,
)

pytestmark = pytest.mark.browser

CHART_STATE_JS = """() => Object.values(window.__viserTestpoints?.uplots ?? {}).map((entry) => {
    const chart = entry.chart;
    const panel = chart.root.closest(".uplot-container").getBoundingClientRect().width;
    return {title: chart.root.querySelector(".u-title")?.textContent ?? "",
        width: chart.width, panel: panel, frames: chart.data[0].length,
        x_first: chart.data[0][0], x_labels: chart.axes[0]._values ?? [],
        now_x: chart.data[0][chart.data[chart.data.length - 1].findIndex((v) => v != null)],
        y_labels: chart.axes[1]._values ?? [], y_splits: chart.axes[1]._splits ?? [],
        y_min: chart.scales.y.min, y_max: chart.scales.y.max,
        labels: chart.series.map((s) => s.label),
        gaps: chart.series.map((s) => (s._paths?.gaps ?? []).length)};
})"""
WATCH_WIDTHS_JS = """() => {
    window.__narrowest = Infinity;
    const watch = () => {
        for (const entry of Object.values(window.__viserTestpoints?.uplots ?? {})) {
            const box = entry.chart.root.closest(".uplot-container");
            if (box && box.offsetParent !== null) {
                const ratio = entry.chart.width / box.getBoundingClientRect().width;
                window.__narrowest = Math.min(window.__narrowest, ratio);
            }
        }
        requestAnimationFrame(watch);
    };
    watch();
}"""
"""Records, every frame the page draws, the narrowest chart (as a fraction of its panel)."""


def load_demo_boxes(page, tab) -> None:
    """Press Load boxes.json and wait for the demo's four targets."""
    page.get_by_role("button", name="Load boxes.json").click()
    _wait_for(lambda: len(tab.controller.run.targets) == 4, what="the boxes", tab=tab)


def _charts(page) -> dict[str, dict]:
    return {row["title"]: row for row in page.evaluate(CHART_STATE_JS)}


def test_charts_are_made_once_as_wide_as_their_panel_and_readable(studio, tmp_path) -> None:  # noqa: F811
    from autotrack_studio.plots import CHART_TITLES, decade_label

    with studio_page(studio, tmp_path / "profile") as (page, tab):
        controller = tab.controller
        _wait_for(lambda: sorted(_charts(page)) == sorted(CHART_TITLES), what="the charts")
        page.evaluate(SAME_CHARTS_JS)  # the chart elements before any target
        # A chart is mounted 0 px wide and widened when viser's size hook first measures its
        # panel (a frame or more later on a loaded machine): watch from the first full width.
        _wait_for(
            lambda: all(row["width"] >= 0.98 * row["panel"] > 0 for row in _charts(page).values()),
            what="the charts at their panel's width",
        )
        page.evaluate(WATCH_WIDTHS_JS)
        for row in _charts(page).values():  # empty charts count frames, not dates of 1970
            assert row["x_labels"] and not any(":" in str(v) for v in row["x_labels"]), row
        load_demo_boxes(page, tab)
        theta = CHART_TITLES[2]
        _wait_for(  # theta is 0 on the first frame: a flat signal
            lambda: (
                _charts(page)[theta]["labels"][1] == "T1 θref"
                and _charts(page)[theta]["y_min"] <= -1.0
            ),
            what="the flat theta chart",
            tab=tab,
        )
        flat = _charts(page)[theta]
        assert len(set(flat["y_labels"])) == len(flat["y_labels"]) >= 3, flat["y_labels"]

        # Play, step over two frames (not played: no in-app rate), play on.
        tab.panels.playback.unlimited.value = True
        page.get_by_role("button", name="Play").click()
        _wait_for(lambda: controller.cursor >= 8, what="frames played", tab=tab)
        page.get_by_role("button", name="Pause").click()
        assert tab.wait_idle()
        for _ in range(2):
            page.get_by_role("button", name="Step forward").click()
            assert tab.wait_idle()
        # Played frames after the stepped ones (the pause may land frames after it was asked
        # for on a loaded machine, so count from where the steps ended).
        stepped = controller.cursor
        page.get_by_role("button", name="Play").click()
        _wait_for(lambda: controller.cursor >= stepped + 6, what="more frames", tab=tab)
        page.get_by_role("button", name="Pause").click()
        assert tab.wait_idle()
        last = controller.cursor
        _wait_for(
            lambda: all(row["frames"] == last + 3 for row in _charts(page).values()),
            what="the charts with every frame",
            tab=tab,
        )
        time.sleep(0.5)  # a few more frames drawn by the page
        charts = _charts(page)
        assert page.evaluate(SAME_CHARTS_JS), "the charts were made again"
        narrowest = page.evaluate("() => window.__narrowest")
        assert narrowest > 0.98, f"a chart was drawn at {narrowest:.0%} of its panel"
        for row in charts.values():
            assert abs(row["width"] - row["panel"]) <= 2.0, row
            # One frame numbering: the x axis (and its hover) counts frames as the slider does.
            assert row["x_first"] == 1 and math.floor(row["now_x"]) == last + 1, row
            assert tab.panels.playback.frame.value == last + 1

        eta = charts[CHART_TITLES[1]]  # one labelled line per decade
        exponents = [math.log10(split) for split in eta["y_splits"]]
        assert len(exponents) >= 2 and all(abs(e - round(e)) < 1e-9 for e in exponents)
        assert eta["y_labels"] == [decade_label(round(e)) for e in exponents], eta

        speed = charts[CHART_TITLES[3]]
        in_app = speed["labels"].index("in-app fps")
        assert speed["gaps"][in_app] >= 1, speed  # the stepped frames: a gap, not a line
        page.screenshot(path=str(tmp_path / "charts.png"))


def test_playing_to_the_end_stops_at_the_last_frame_in_chromium(studio, tmp_path) -> None:  # noqa: F811

    with studio_page(studio, tmp_path / "profile") as (page, tab):
        controller = tab.controller
        last = controller.run.frame_count - 1
        load_demo_boxes(page, tab)
        tab.panels.playback.unlimited.value = True
        page.get_by_role("button", name="Play").click()
        _wait_for(lambda: controller.cursor == last, what="the last frame", tab=tab)
        play, pause = (page.get_by_role("button", name=n, exact=True) for n in ("Play", "Pause"))
        _wait_for(lambda: play.count() == 1 and pause.count() == 0, what="Play in the page")
        time.sleep(1.0)  # nothing moves after the end
        assert controller.cursor == last and not controller.playing and tab.wait_idle()
        assert play.count() == 1 and pause.count() == 0
        assert tab.panels.playback.frame.value == last + 1
        assert "error" not in controller.message.lower(), controller.message
