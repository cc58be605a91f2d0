"""The demo's ground truth in headless Chromium: *Start from ground truth* starts the four
landmarks' targets from their groundtruth/ boxes, the Ground truth tab scores each, and the
3-D view's legend gives the camera's error against poses_gt.tum (ATE, RPE per second).
Screenshots: test-artifacts/app-truth-scores.png, app-truth-3d.png. Needs /usr/bin/chromium
and playwright, as tests/test_app_browser.py."""

from __future__ import annotations

import pytest

from tests.test_app_browser import (
    ARTIFACTS,
    _wait_for,
    studio,  # noqa: F401 (the fixture)
    studio_page,
)

pytestmark = pytest.mark.browser


def test_the_demo_ground_truth_is_scored_and_the_pose_error_shown(studio, tmp_path) -> None:  # noqa: F811
    from autotrack_studio.panels import CANVAS_3D

    ARTIFACTS.mkdir(exist_ok=True)
    with studio_page(studio, tmp_path / "profile") as (page, tab):
        controller = tab.controller
        page.get_by_role("button", name="Start from ground truth").click()
        _wait_for(lambda: len(controller.run.targets) == 4, what="the four targets", tab=tab)
        tab.panels.playback.unlimited.value = True
        page.get_by_role("button", name="Play").click()
        _wait_for(lambda: controller.cursor >= 14, what="15 frames played", tab=tab)
        page.get_by_role("button", name="Pause").click()
        assert tab.wait_idle()
        page.get_by_role("tab", name="Ground truth").click()
        scores = page.get_by_text("GT A", exact=True)
        _wait_for(lambda: scores.count() >= 1, what="the scores table", tab=tab)
        _wait_for(lambda: page.get_by_text("ATE").count() >= 1, what="the pose error", tab=tab)
        page.screenshot(path=str(ARTIFACTS / "app-truth-scores.png"))
        tab.panels.display.canvas.value = CANVAS_3D
        _wait_for(
            lambda: tab.display.view3d.segments_sent > 0, what="the trajectory drawn", tab=tab
        )
        legend = page.get_by_text("ground truth (dashed)")
        _wait_for(lambda: legend.count() >= 1, what="the 3-D legend", tab=tab)
        page.wait_for_timeout(1500)  # the software renderer draws the scene
        page.screenshot(path=str(ARTIFACTS / "app-truth-3d.png"))
