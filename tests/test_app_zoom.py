"""Zoom and pan on the frame canvas: the window shown, drags on the zoomed canvas mapped back to
frame pixels exactly, the window sent at its own resolution, and a tab zoomed, panned and drawn
on through its widgets (no browser)."""

from __future__ import annotations

import numpy as np
import pytest
import viser

from autotrack_studio.canvas import letterbox_image
from autotrack_studio.zoom import MAX_ZOOM, ZoomWindow, canvas_mapping, zoom_window
from tests.test_app import _click, _open_tab, _set, _wait_for, studio  # noqa: F401


def test_the_zoom_window_is_centred_and_kept_inside_the_frame() -> None:
    assert zoom_window((1280, 720), 1.0) == ZoomWindow(0, 0, 1280, 720)
    assert zoom_window((1280, 720), 4.0) == ZoomWindow(480, 270, 320, 180)
    assert zoom_window((1280, 720), 4.0, (1000.0, 600.0)) == ZoomWindow(840, 510, 320, 180)
    assert zoom_window((1280, 720), 4.0, (1000.0, 700.0)) == ZoomWindow(840, 540, 320, 180)
    assert zoom_window((1280, 720), 4.0, (-50.0, 5.0)) == ZoomWindow(0, 0, 320, 180)
    assert zoom_window((1280, 720), 100.0).width == round(1280 / MAX_ZOOM)


@pytest.mark.parametrize("canvas", [(1600, 900), (900, 900), (700, 1000)])
def test_a_drag_on_the_zoomed_canvas_maps_back_to_frame_pixels(canvas) -> None:
    window = zoom_window((1280, 720), 4.0, (1000.0, 600.0))
    mapping = canvas_mapping((1280, 720), canvas, window)
    box = (905.25, 561.5, 24.0, 19.75)  # a 24 px target: ~100 screen pixels at zoom 4
    corner_a = mapping.frame_to_screen(box[0], box[1])
    corner_b = mapping.frame_to_screen(box[0] + box[2], box[1] + box[3])
    assert mapping.rect_to_box(corner_b, corner_a) == pytest.approx(box, abs=1e-9)
    assert mapping.rect_inside(corner_a, corner_b)
    # Past the window's edge the drag is cut there, in frame pixels.
    outside = mapping.frame_to_screen(window.x + window.width + 30.0, box[1] + box[3])
    cut = mapping.rect_to_box(corner_a, outside)
    assert cut[0] + cut[2] == pytest.approx(window.x + window.width)
    assert not mapping.rect_inside(corner_a, outside)
    # Screen width of the box: zoom 4 makes it four times what the whole frame gives it.
    whole = canvas_mapping((1280, 720), canvas)
    zoomed_width = corner_b[0] - corner_a[0]
    whole_width = whole.frame_to_screen(box[0] + box[2], 0)[0] - whole.frame_to_screen(box[0], 0)[0]
    assert zoomed_width == pytest.approx(4.0 * whole_width, rel=0.02)


def test_the_zoomed_window_is_sent_at_its_own_resolution_where_the_mapping_says() -> None:
    frame = np.zeros((720, 1280, 3), np.uint8)
    frame[600, 1000] = (255, 255, 255)  # one marked pixel
    window = zoom_window((1280, 720), 4.0, (1000.0, 600.0))
    mapping = canvas_mapping((1280, 720), (1600, 900), window)
    image = letterbox_image(window.crop(frame), mapping.letterbox, 1280)
    assert image.shape[:2] == (mapping.letterbox.padded_height, mapping.letterbox.padded_width)
    assert image.shape[1] <= 1280 and image.shape[1] < 1280 / 2  # not the whole frame's pixels
    u, v = mapping.frame_to_screen(1000.5, 600.5)  # the pixel's centre
    row, column = int(v * image.shape[0]), int(u * image.shape[1])
    assert tuple(image[row, column]) == (255, 255, 255)


def test_a_tab_zooms_pans_and_draws_on_the_zoomed_frame(studio) -> None:  # noqa: F811
    tab, _ = _open_tab(studio)
    stats = tab.display.stats
    _wait_for(lambda: stats.canvas_frames >= 1)
    drawn = stats.canvas_frames
    _set(tab.panels.display.zoom, 4.0)
    _wait_for(lambda: tab.display.mapping is not None and tab.display.mapping.window.width == 240)
    assert stats.canvas_frames > drawn
    # A click (no Shift) on the zoomed frame centres it there.
    mapping = tab.display.mapping
    tab.clicked(
        viser.SceneClickEvent(
            client=None,
            client_id=0,
            ray_origin=(0.0, 0.0, 0.0),
            ray_direction=(0.0, 0.0, 1.0),
            screen_pos=mapping.frame_to_screen(300.0, 170.0),
            modifier=None,
        )
    )
    assert tab.wait_idle()
    panned = zoom_window((960, 540), 4.0, (300.0, 170.0))
    assert (panned.x, panned.width, panned.height) == (180, 240, 135)
    _wait_for(lambda: tab.display.mapping.window == panned)
    assert tab.display.zoom_centre == pytest.approx((300.0, 170.0))
    # A shift-drag on the zoomed frame: a box in frame pixels.
    mapping = tab.display.mapping
    box = (290.0, 160.0, 30.0, 24.0)
    tab.rect_selected(
        viser.SceneRectSelectEvent(
            client=None,
            client_id=0,
            screen_min=mapping.frame_to_screen(box[0], box[1]),
            screen_max=mapping.frame_to_screen(box[0] + box[2], box[1] + box[3]),
            modifier="shift",
        )
    )
    assert tab.wait_idle()
    target = tab.controller.run.targets["T1"]
    assert target.results[0].box == pytest.approx(box, abs=1.0)  # its start on the pixel grid
