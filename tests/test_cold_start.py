"""A fresh install's first process (benchmarks/cold_start.py): what it compiles.

Compile time is machine speed, so it is not asserted; what makes it long is: a kernel compiled
for a second signature (a strided view where a contiguous array was meant, another dtype), or
a kernel calling another heavy kernel, whose code numba then compiles again into the caller.
"""

from __future__ import annotations

import sys

import pytest

from tests.conftest import REPO

sys.path.insert(0, str(REPO / "benchmarks"))
import cold_start  # noqa: E402

FHOG_STAGES = (
    "gradients:planar_float32",
    "gradients:_rgb_gradients",
    "gradients:gradient_histogram",
    "fast_fhog:_cell_factor_planes",
    "fast_fhog:_normalised_channels",
)
"""The fHOG kernels, each called from Python: no kernel of the tracker calls them."""


@pytest.mark.skipif(not cold_start.GULL1.is_dir(), reason="shared data not available")
def test_a_fresh_process_compiles_each_tracker_kernel_once(tmp_path):
    figures = cold_start.run(tmp_path, frames=3, helper=False)
    ours = {
        name.removeprefix("autotrack.tracker.backend."): count
        for name, count in figures["compilations"].items()
        if name.startswith("autotrack.")
    }
    assert set(FHOG_STAGES) <= set(ours), sorted(ours)
    assert {name: count for name, count in ours.items() if count != 1} == {}
    # Compiled as kernels of their own only: a kernel calling one compiles it in as a callee
    # first, nested in the caller's compile events, which `run` counts apart from its own.
    for stage in FHOG_STAGES:
        assert figures["nested"].get(f"autotrack.tracker.backend.{stage}", 0) == 0, stage
    # A colour video takes the RGB kernels only: the general crop and gradients are not compiled.
    assert "area_resample:_area_crop_gathered" not in ours
    assert "gradients:_any_channel_gradients" not in ours
