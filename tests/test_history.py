"""A target's results as columns (`ResultHistory`): the same answers as the dict of
`TrackResult`s it replaces, over a really tracked sequence."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from autotrack import AutoTrack
from autotrack.params import preset
from autotrack.pipeline.history import SCALAR_COLUMNS, ResultHistory
from autotrack.result import TrackResult
from autotrack.synthetic.drift import DriftingTexture, DriftSettings

FRAMES = 40
MAP_FIELDS = ("response_map", "local_variation", "spatial_window")


@pytest.fixture(scope="module")
def tracked() -> dict[int, TrackResult]:
    """Every frame's result of one target tracked over a drifting texture, maps included."""
    frames = DriftingTexture(DriftSettings(frames=FRAMES, period_frames=24))
    tracker = AutoTrack(preset("autotrack"))
    results = {0: tracker.init(frames.read(0), frames.boxes(1)[0])}
    for index in range(1, FRAMES):
        result = tracker.update(frames.read(index))
        results[index] = dataclasses.replace(result, frame_index=index)
    return results


def _filled(results: dict[int, TrackResult], window: int, capacity: int = 4) -> ResultHistory:
    history = ResultHistory(capacity)
    for result in results.values():
        history.put(result, window)
    return history


def _same_result(got: TrackResult, expected: TrackResult, with_maps: bool) -> None:
    for field in dataclasses.fields(TrackResult):
        value, wanted = getattr(got, field.name), getattr(expected, field.name)
        if field.name in MAP_FIELDS:
            if with_maps:
                assert value is wanted, field.name
            else:
                assert value is None, field.name
        else:
            np.testing.assert_array_equal(value, wanted, err_msg=field.name)
            assert type(value) is type(wanted) or isinstance(value, float), field.name


@pytest.mark.parametrize("window", [0, 1, 7, FRAMES])
def test_the_history_answers_as_the_dict_of_results_did(tracked, window) -> None:
    history = _filled(tracked, window)
    assert len(history) == len(tracked) and list(history) == list(tracked)
    assert history.first_frame == 0 and history.last_frame == FRAMES - 1
    assert 5 in history and FRAMES not in history and -1 not in history and "5" not in history
    assert history.get(FRAMES) is None
    with pytest.raises(KeyError):
        history[FRAMES]
    assert history.maps_from == FRAMES - window
    for index, expected in tracked.items():
        kept = index >= FRAMES - window
        _same_result(history[index], expected, with_maps=kept)
        assert (history[index] is expected) == kept  # the window's results are kept whole
    # Rebuilt results compare equal to each other (NaN fields included) and to a dict's copy.
    assert history == dict(history) and dict(history.items()) == history
    np.testing.assert_array_equal(history.frames, list(tracked))
    np.testing.assert_array_equal(history.boxes, [r.box for r in tracked.values()])
    np.testing.assert_array_equal(history.search_boxes, [r.search_box for r in tracked.values()])
    np.testing.assert_array_equal(history.aberrant, [r.aberrant for r in tracked.values()])
    for name in SCALAR_COLUMNS:
        np.testing.assert_array_equal(
            history.column(name), [getattr(r, name) for r in tracked.values()]
        )
    with pytest.raises(ValueError):
        history.boxes[0, 0] = 1.0  # the columns are views, read-only


def test_the_columns_grow_past_their_initial_capacity(tracked) -> None:
    history = ResultHistory(capacity=2)
    sizes = []
    for result in tracked.values():
        history.put(result, 3)
        sizes.append(history.nbytes)
    assert sizes[-1] == sizes[0] * 32  # 2 -> 64 rows, doubled five times
    assert len(set(sizes)) == 6  # grown only when full: amortised
    assert [history[k].box for k in history] == [r.box for r in tracked.values()]


def test_truncation_drops_the_later_frames_and_re_tracking_refills_them(tracked) -> None:
    history = _filled(tracked, 5)
    assert history.truncate_after(29) == list(range(30, FRAMES))
    assert list(history) == list(range(30)) and history.last_frame == 29
    assert 30 not in history and history.get(31) is None and history.get(FRAMES - 1) is None
    # A correction at frame 29 restarts there: its maps are kept again from there on.
    corrected = dataclasses.replace(tracked[29], box=(1.0, 2.0, 3.0, 4.0))
    history.put(corrected, 5)
    assert history.maps_from == 29 and history[29] is corrected
    assert history[28].response_map is None and history[28].box == tracked[28].box
    for index in range(30, FRAMES):
        history.put(tracked[index], 5)
    assert history.maps_from == FRAMES - 5
    assert [k for k in history if history[k].has_maps] == list(range(FRAMES - 5, FRAMES))
    assert history.truncate_after(-1) == list(range(FRAMES))
    assert len(history) == 0 and history.last_frame == -1 and not history


def test_frames_with_gaps_and_out_of_order_stay_in_frame_order(tracked) -> None:
    history = ResultHistory(capacity=2)
    for index in (0, 2, 5, 9, 3):  # a live source's dropped frames; one filled in late
        history.put(tracked[index], 0)
    assert list(history) == [0, 2, 3, 5, 9]
    assert 4 not in history and 1 not in history
    for index in (0, 2, 3, 5, 9):
        assert history[index].box == tracked[index].box
    history.put(dataclasses.replace(tracked[5], box=(5.0, 5.0, 5.0, 5.0)), 0)  # overwritten
    assert len(history) == 5 and history[5].box == (5.0, 5.0, 5.0, 5.0)
    assert history[9].box == tracked[9].box
