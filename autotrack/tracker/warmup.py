"""Compiling the tracker's kernels before the first box: a few frames of a synthetic target."""

from __future__ import annotations

import math
import time

import cv2
import numpy as np

from autotrack.params import TrackerParams
from autotrack.tracker import dcf, fft_plans
from autotrack.tracker.tracker import AutoTrack


def warm_up(params: TrackerParams | None = None) -> float:
    """Compile (or load from numba's cache) every kernel the tracker runs, by tracking a small
    synthetic target for four frames in colour and in grey, and plan the FFTs of every search
    grid the parameters allow (`plan_search_grids`); returns the seconds it took.

    The first box a user draws then answers at once instead of waiting for the compiler or,
    on a machine new to these shapes, for FFTW's plan search.
    """
    started = time.perf_counter()
    params = params or TrackerParams()
    rng = np.random.default_rng(0)
    frame = rng.integers(0, 64, (120, 160, 3), dtype=np.uint8)
    frame[40:70, 60:90] = (230, 180, 40)
    channel_counts = set()
    for image in (frame, cv2.cvtColor(frame, cv2.COLOR_RGB2GRAY)):
        tracker = AutoTrack(params)
        tracker.init(image, (60.0, 40.0, 30.0, 30.0))
        for shift in (1, 2, 3):
            tracker.update(np.roll(image, shift, axis=1))
        channel_counts.add(int(tracker.transform.input_maps.shape[0]))
    for channels in sorted(channel_counts):
        plan_search_grids(params, channels)
    return time.perf_counter() - started


def search_grid_sides(params: TrackerParams) -> range:
    """The grid sides (cells) a search region can have: its side is sqrt(w h
    search_area_scale) brought within [min_image_sample_size, max_image_sample_size] (as areas),
    rounded to whole cells (38-50 with the release's 150^2-200^2 px and 4 px cells)."""
    cell = params.cell_size
    smallest = dcf.matlab_round(math.sqrt(params.min_image_sample_size) / cell)
    largest = dcf.matlab_round(math.sqrt(params.max_image_sample_size) / cell)
    return range(int(smallest), int(largest) + 1)


def plan_search_grids(params: TrackerParams, channels: int) -> None:
    """Plan the transforms of every square search grid of `channels` channels: from the wisdom
    file, or searched once on a machine new to them (0.2-1.1 s a shape, `fft_plans`). The
    largest grid first: every target whose search region reaches the largest size has it (13
    of the 18 dev sequences), and a box drawn meanwhile waits at most for the shape at hand."""
    for side in reversed(search_grid_sides(params)):
        fft_plans.plans_for(channels, (side, side))
