"""Zoom in headless Chromium: the frame canvas at zoom 4, a click (no Shift) centres it on a
landmark, and a shift-drag around the landmark's box at the zoomed scale draws that box in frame
pixels. Screenshot: test-artifacts/app-zoomed.png. Needs /usr/bin/chromium and playwright, as
tests/test_app_browser.py."""

from __future__ import annotations

import json

import numpy as np
import pytest

from tests.test_app_browser import (
    ARTIFACTS,
    DEMO,
    _shift_drag,
    _wait_for,
    studio,  # noqa: F401 (the fixture)
    studio_page,
)

pytestmark = pytest.mark.browser


def test_a_box_drawn_on_the_zoomed_canvas_lands_on_the_frame_pixels(studio, tmp_path) -> None:  # noqa: F811
    ARTIFACTS.mkdir(exist_ok=True)
    x, y, w, h = json.loads((DEMO / "boxes.json").read_text())["C"]
    with studio_page(studio, tmp_path / "profile") as (page, tab):
        display = tab.display
        _wait_for(lambda: display.mapping is not None, what="the frame on the canvas", tab=tab)
        warning_close = page.locator(".mantine-Notification-closeButton")
        if warning_close.count():
            warning_close.first.click()
        canvas = max(
            (c.bounding_box() for c in page.query_selector_all("canvas")),
            key=lambda b: b["width"] * b["height"],
        )

        def page_point(px: float, py: float) -> tuple[float, float]:
            u, v = display.mapping.frame_to_screen(px, py)
            return (canvas["x"] + u * canvas["width"], canvas["y"] + v * canvas["height"])

        tab.panels.display.zoom.value = 4.0
        _wait_for(lambda: display.mapping.window.width == 240, what="the zoomed canvas", tab=tab)
        # Centre the zoom on landmark C (inside the first zoomed window).
        page.mouse.click(*page_point(x + w / 2, y + h / 2))
        _wait_for(
            lambda: (
                display.zoom_centre is not None
                and abs(display.zoom_centre[0] - (x + w / 2)) < 3.0
                and display.mapping.window.x < 300
            ),
            what="the view centred on C",
            tab=tab,
        )
        page.wait_for_timeout(1000)  # the page draws the new background
        _shift_drag(page, page_point(x, y), page_point(x + w, y + h))
        _wait_for(lambda: len(tab.controller.run.targets) == 1, what="the box", tab=tab)
        drawn = tab.controller.run.targets["T1"].results[0].box
        np.testing.assert_allclose(drawn, (x, y, w, h), atol=1.0)  # the pixel grid's start
        page.wait_for_timeout(1000)
        page.screenshot(path=str(ARTIFACTS / "app-zoomed.png"))
