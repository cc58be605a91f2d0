"""The per-update glue gives the values of its definitions on real sequences: the global
variation is LAPACK's largest singular value (`np.linalg.norm(ord=2)`), the search region is
computed once per scale, the scale filter's clamp works on Python floats."""

from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.linalg

from autotrack import AutoTrack, preset
from autotrack.evaluation.datasets import load_otb_sequence
from autotrack.io.frames import read_image
from autotrack.tracker import dcf, regularization
from tests.conftest import shared_sequence_dir

SEQUENCES = [("DTB70", "Surfing06"), ("UAV123_10fps", "boat5")]


def _run(dataset: str, name: str, frames: int, preset_name: str = "autotrack"):
    """(tracker, results) of `frames` frames of a real sequence."""
    sequence = load_otb_sequence(shared_sequence_dir(dataset, name))[0]
    tracker = AutoTrack(preset(preset_name))
    results = [tracker.init(read_image(sequence.frame_paths[0]), sequence.init_box)]
    for path in sequence.frame_paths[1:frames]:
        results.append(tracker.update(read_image(path)))
    return tracker, results


def _recorded(monkeypatch, owner, name: str) -> list:
    """The positional arguments of every call of owner.name during the test."""
    calls = []
    original = getattr(owner, name)

    def recording(*args, **kwargs):
        calls.append(tuple(np.array(a) if isinstance(a, np.ndarray) else a for a in args))
        return original(*args, **kwargs)

    monkeypatch.setattr(owner, name, recording)
    return calls


@pytest.mark.parametrize(("dataset", "name"), SEQUENCES)
def test_global_variation_equals_svdvals_on_real_variations(monkeypatch, dataset, name):
    calls = _recorded(monkeypatch, regularization, "global_variation")
    _run(dataset, name, 12)
    monkeypatch.undo()
    assert len(calls) == 10  # from the third frame on
    finite = [v for (v,) in calls if np.isfinite(v).all()]
    assert len(finite) >= 5
    for (variation,) in calls:
        if not np.isfinite(variation).all():  # a blow-up: an aberrant frame
            assert regularization.global_variation(variation) == math.inf
            continue
        singular = scipy.linalg.svdvals(variation.astype(np.float64), check_finite=False)
        expected = float(singular[0]) * regularization.GLOBAL_VARIATION_SCALE
        got = regularization.global_variation(variation)
        assert got > 0.0
        assert got == pytest.approx(expected, rel=1e-14, abs=0.0)
        blown = variation.copy()
        blown[3, 4] = np.inf
        assert regularization.global_variation(blown) == math.inf
        blown[3, 4] = np.nan
        assert regularization.global_variation(blown) == math.inf


def _fresh_search_box(tracker: AutoTrack) -> tuple[float, float, float, float]:
    """The search box from the tracker's window, scale and position, computed afresh."""
    region = dcf.matlab_round(tracker.window_size * tracker.scale)
    row, col = tracker.position
    top = math.floor(row) - int(region[0]) // 2
    left = math.floor(col) - int(region[1]) // 2
    return (float(left), float(top), float(region[1]), float(region[0]))


@pytest.mark.parametrize("preset_name", ["autotrack", "autotrack+"])
def test_search_region_follows_scale_and_reinit(preset_name):
    """The search region, kept while the scale does not change, is the one computed afresh
    after every update (the scale changes along the run) and after `init` on another target
    (a new window at the same scale)."""
    sequence = load_otb_sequence(shared_sequence_dir("DTB70", "Surfing06"))[0]
    frames = [read_image(path) for path in sequence.frame_paths[:15]]
    tracker = AutoTrack(preset(preset_name))
    assert tracker.init(frames[0], sequence.init_box).search_box == _fresh_search_box(tracker)
    scales = set()
    for frame in frames[1:]:
        tracker.update(frame)
        scales.add(tracker.scale)
        assert tracker._search_box() == _fresh_search_box(tracker)
    assert len(scales) > 1
    x, y = sequence.init_box[:2]
    for side in (32.0, 38.0, 32.0):  # scale 1 for each: only the window changes
        result = tracker.init(frames[0], (x, y, side, side))
        assert tracker.scale == 1.0 and tracker.window_size[0] == 4 * round(side * 5 / 4)
        assert result.search_box == _fresh_search_box(tracker)
        tracker.update(frames[1])
        assert tracker._search_box() == _fresh_search_box(tracker)
