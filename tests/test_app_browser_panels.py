"""What only the page shows of the panels, in headless Chromium: the Targets table's header
reads on one line at the default panel width, and the chart legends list only the targets
that exist (the charts themselves are made once, with a series per target number)."""

from __future__ import annotations

import json
import time

import pytest

from tests.test_app_browser import (
    DEMO,
    _wait_for,
    studio,  # noqa: F401 (the fixture)
    studio_page,
)
from tests.test_app_browser_charts import load_demo_boxes

pytestmark = pytest.mark.browser

TABLE_HEADER_JS = """() => Array.from(document.querySelectorAll("table th"))
    .filter((cell) => !cell.closest(".uplot")).map((cell) => {
    const range = document.createRange();
    range.selectNodeContents(cell);
    const lines = new Set(Array.from(range.getClientRects()).map((r) => Math.round(r.top)));
    return {text: cell.textContent, lines: lines.size};
})"""
"""Each header cell of the tables in the panel (not the charts' legends) with the number of lines its text takes."""
LEGENDS_JS = """() => Object.values(window.__viserTestpoints?.uplots ?? {}).map((entry) =>
    Array.from(entry.chart.root.querySelectorAll(".u-legend .u-series"))
        .filter((row) => getComputedStyle(row).display !== "none")
        .map((row) => row.querySelector(".u-label").textContent))"""
"""The legend entries each chart shows."""


def _targets_in_legends(page) -> set[str]:
    labels = [label for legend in page.evaluate(LEGENDS_JS) for label in legend]
    return {label.split()[0] for label in labels if label[:1] == "T" and label[1:2].isdigit()}


def test_the_targets_table_header_reads_on_one_line(studio, tmp_path) -> None:  # noqa: F811
    with studio_page(studio, tmp_path / "profile") as (page, tab):
        load_demo_boxes(page, tab)
        _wait_for(lambda: len(page.evaluate(TABLE_HEADER_JS)) > 0, what="the table")
        page.locator("table").first.scroll_into_view_if_needed()
        page.screenshot(path=str(tmp_path / "targets-table.png"))
        header = page.evaluate(TABLE_HEADER_JS)
        assert all(cell["lines"] == 1 for cell in header), header


def test_chart_legends_list_only_the_targets_that_exist(studio, tmp_path) -> None:  # noqa: F811
    from autotrack_studio.plots import CHART_TITLES

    with studio_page(studio, tmp_path / "profile") as (page, tab):
        _wait_for(lambda: len(page.evaluate(LEGENDS_JS)) == len(CHART_TITLES), what="charts")
        time.sleep(0.5)  # the page has drawn what the server sent first
        assert _targets_in_legends(page) == set()
        assert any("φ" in legend for legend in page.evaluate(LEGENDS_JS))  # the rest stays
        boxes = json.loads((DEMO / "boxes.json").read_text())
        for count, landmark_id in enumerate("ABCD", start=1):
            tab.panels.targets.box.value = ", ".join(map(str, boxes[landmark_id]))
            page.get_by_role("button", name="Apply typed box").click()
            _wait_for(lambda n=count: len(tab.controller.run.targets) == n, tab=tab)
            if count == 1:
                _wait_for(lambda: _targets_in_legends(page) == {"T1"}, what="T1 only")
        everyone = {"T1", "T2", "T3", "T4"}
        _wait_for(lambda: _targets_in_legends(page) == everyone, what="four in the legends")
        theta = page.evaluate(LEGENDS_JS)[CHART_TITLES.index("θ_ref (dots) and θ")]
        assert "T4 θref" in theta and "T4 θ" in theta


def test_a_shift_click_says_how_to_draw_and_delete_says_what_enables_it(
    studio,  # noqa: F811
    tmp_path,
) -> None:
    """A shift-click with no drag draws nothing (viser reports it as a click, not a box): the
    page tells the user to drag. The greyed Delete button says what enables it."""
    from autotrack_studio.tab import DRAW_HINT

    with studio_page(studio, tmp_path / "profile") as (page, tab):
        _wait_for(lambda: tab.display.letterbox is not None, what="the frame", tab=tab)
        delete = page.get_by_role("button", name="Delete target (none yet)")
        assert delete.is_disabled()
        canvas = max(
            (c.bounding_box() for c in page.query_selector_all("canvas")),
            key=lambda b: b["width"] * b["height"],
        )
        page.keyboard.down("Shift")
        page.mouse.click(canvas["x"] + canvas["width"] / 2, canvas["y"] + canvas["height"] / 2)
        page.keyboard.up("Shift")
        hint = page.get_by_text(DRAW_HINT)
        _wait_for(lambda: hint.count() >= 2, what="the hint as a note and in the status")
        page.screenshot(path=str(tmp_path / "shift-click.png"))
        assert tab.controller.run.targets == {}
        load_demo_boxes(page, tab)
        _wait_for(
            lambda: (
                page.get_by_role("button", name="Delete target (choose it in Drag draws)").count()
                == 1
            ),
            what="the Delete button's hint",
        )
        page.get_by_label("Drag draws", exact=True).click()
        page.get_by_role("option", name="T2").click()
        delete = page.get_by_role("button", name="Delete T2")
        _wait_for(lambda: delete.count() == 1 and delete.is_enabled(), what="Delete T2")
        delete.click()
        _wait_for(lambda: "T2" not in tab.controller.run.targets, what="T2 deleted", tab=tab)
