"""The per-update work taken out of numpy / scipy wrappers (rounds 10 and 20) gives their values
on real sequences: the spectral norm within a few units in the last place of LAPACK's (its own
kernel since round 20), and bit for bit the h-step's gain in one kernel, the search region
computed once per scale, the scale filter's clamp on Python floats."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
import scipy.linalg

from autotrack import AutoTrack, preset
from autotrack.evaluation.datasets import load_otb_sequence
from autotrack.io.frames import read_image
from autotrack.tracker import admm_kernels, dcf, regularization
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


@pytest.mark.parametrize(("dataset", "name"), SEQUENCES)
def test_h_step_gain_equals_numpy_on_real_windows(monkeypatch, dataset, name):
    """The kernel's gain against the numpy expression it replaces, on the spatial windows
    (ASR, eq. 3) and the gamma sequence of real trainings, bit for bit."""
    calls = _recorded(monkeypatch, dcf, "_h_step_gain")
    tracker, _ = _run(dataset, name, 8)
    monkeypatch.undo()
    assert len(calls) >= 2 * 7
    lam = tracker.admm.lambda_spatial
    cells = tracker.grid_size[0] * tracker.grid_size[1]
    windows = {window.tobytes(): window for window, *_ in calls}
    assert len(windows) > 2  # the ASR window changes from frame to frame
    rng = np.random.default_rng(5)  # and windows whose values vary more than u's few levels
    shape = next(iter(windows.values())).shape
    windows["uniform"] = rng.uniform(1e-3, 1e5, shape).astype(np.float32)
    for window in windows.values():
        for gamma, lam_used in itertools.product((1.0, 10.0, 100.0, 0.7312, 13), (lam, 0.0137)):
            expected = (cells / (lam_used * window**2 + gamma * cells)).astype(np.float32)
            got = np.full(window.shape, np.nan, np.float32)
            admm_kernels.h_step_gain(window, lam_used, float(gamma), cells, got)
            np.testing.assert_array_equal(got.view(np.uint32), expected.view(np.uint32))


def test_h_step_with_numpy_scalars_keeps_numpys_promotion(monkeypatch):
    """A float64 numpy lambda makes numpy compute the gain in float64 (then round once): the
    kernel, whose Python numbers act as float32, is not used for it."""
    calls = _recorded(monkeypatch, dcf, "train_filter")
    _run("DTB70", "Surfing06", 4)
    monkeypatch.undo()
    xf, _, g_f, window, _, _, transform, *_ = calls[-1]
    l_f = (xf - g_f) * np.float32(0.37)  # a multiplier of the spectra's size and scale
    for lam in (np.float64(0.0137), 0.0137):
        got = np.array(dcf.solve_h_step(g_f, l_f, window, 10.0, lam, transform))
        cells = transform.grid_size[0] * transform.grid_size[1]
        gain = (cells / (lam * window**2 + 10.0 * cells)).astype(np.float32)
        maps = transform.inverse_scratch(np.float32(10.0) * (g_f + l_f))
        maps *= gain
        np.testing.assert_array_equal(got, transform.forward(maps))


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
