"""The helper process of `autotrack.tracker.backend.compile_ahead`: compiles a tracker's
fast-backend kernels in the reverse order of their first use, so that a first process on a cold
cache and this helper meet in the middle (issue 39 item 5). Run as
`python -m autotrack.tracker.compile_helper` with (params, colour) pickled on stdin.
"""

from __future__ import annotations

import pickle
import sys
from dataclasses import replace

import cv2
import numpy as np

from autotrack.params import TrackerParams
from autotrack.tracker.backend import fast_features, fast_fhog, gradients
from autotrack.tracker.backend.fast import FastBackend
from autotrack.tracker.features import feature_dim
from autotrack.tracker.scale import scale_sizes
from autotrack.tracker.tracker import AutoTrack


class _FirstCalls:
    """Kernels replaced by their Python functions in some modules, recording the arguments of
    each kernel's first call from Python (not from inside another kernel): what the compiled
    code would be called with, without compiling it."""

    def __init__(self, modules) -> None:
        self.modules, self.calls, self.depth, self.saved = modules, {}, 0, []

    def __enter__(self) -> dict:
        for module in self.modules:
            for name, value in list(vars(module).items()):
                if hasattr(value, "py_func") and hasattr(value, "signatures"):
                    self.saved.append((module, name, value))
                    setattr(module, name, self._recorded(value))
        return self.calls

    def __exit__(self, *exc) -> None:
        for module, name, value in self.saved:
            setattr(module, name, value)

    def _recorded(self, kernel):
        def run(*args):
            if self.depth == 0 and kernel not in self.calls:
                self.calls[kernel] = tuple(_as_called(arg) for arg in args)
            self.depth += 1
            try:
                return kernel.py_func(*args)
            finally:
                self.depth -= 1

        return run


def _as_called(arg):
    """A writeable contiguous array copied (the run may later write it, or make it read-only:
    another type to numba); other arguments as they are (a view keeps its layout)."""
    if isinstance(arg, np.ndarray) and arg.flags.writeable and arg.flags.c_contiguous:
        return arg.copy()
    return arg


def compile_in_reverse(params: TrackerParams, colour: bool) -> None:
    """Call every fast-backend kernel of a tracker's first three frames, last used first: each
    call compiles the kernel, or loads it if already cached. The detection, variation, training
    and sampling kernels are called on what a reference-backend tracker (numpy only, nothing
    to compile) computed for a small synthetic target; the feature kernels, which the first
    frame calls one after the other, on the arguments a run of their Python functions on a
    small patch recorded, in the reverse order of that run."""
    rng = np.random.default_rng(0)
    frame = rng.integers(0, 64, (120, 160, 3), dtype=np.uint8)
    frame[40:70, 60:90] = (230, 180, 40)
    if not colour:
        frame = cv2.cvtColor(frame, cv2.COLOR_RGB2GRAY)
    reference = AutoTrack(replace(params, backend="reference"))
    reference.init(frame, (60.0, 40.0, 30.0, 30.0))
    first = reference.filter_f
    reference.update(np.roll(frame, 1, axis=1))
    detected = reference.previous_response, reference.previous_displacement
    reference.update(np.roll(frame, 2, axis=1))
    response = reference.previous_response

    channels = feature_dim(params, colour)
    fast = FastBackend(params, reference.colour_table, channels, reference.grid_size)
    scales = reference.scale_filter
    position, window = reference.position, reference.cos_window
    sizes = scale_sizes(scales.base_target_size_hw, reference.scale * scales.scale_steps)
    patch_size = (int(reference.window_size[0]), int(reference.window_size[1]))
    patch = reference.backend.search_patch(frame, position, patch_size, patch_size)
    zf = reference.backend.feature_spectrum(patch, window)

    small = patch[:24, :24]  # 6 x 6 cells: the Python functions' run takes milliseconds
    cells = (6, 6)
    with _FirstCalls((gradients, fast_fhog, fast_features)) as feature_kernels:
        maps = np.empty((channels, *cells), np.float32)  # as the transform's input buffer
        fast_features.feature_maps(
            small, params, reference.colour_table, np.ascontiguousarray(window[:6, :6]), maps
        )
        fast_features.scale_features(np.stack([small] * 3), scales.window[:3])

    # Third frame, second, first: the variation, detection, scale samples, training, features,
    # sampling.
    fast.local_variation(response, reference.previous_displacement, *detected)
    fast.peak(response, params.newton_iterations)
    fast.response(first, zf)
    fast.sized_patches(frame, position, sizes, scales.model_size_hw)
    fast.train(zf, reference.label_f, first, reference.spatial_window, 0.0)
    for kernel, args in reversed(feature_kernels.items()):
        kernel(*args)
    fast.search_patch(frame, position, patch_size, patch_size)


def main() -> None:
    """The helper: (params, colour) pickled on stdin by `arm`'s listener."""
    params, colour = pickle.load(sys.stdin.buffer)
    compile_in_reverse(params, colour)


if __name__ == "__main__":
    main()
