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
    from app.plots import CHART_TITLES

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
