"""Measured FFTW plans kept as wisdom on disk: one plan per shape for every process of a machine.

Each case runs fresh Python processes (FFTW's wisdom is process-wide) on a wisdom file of its
own, planning a (channels, rows, cols) grid and printing what it did as JSON.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time

import numpy as np

from autotrack.tracker import dcf, fft_plans
from autotrack.tracker.fft_plans import PLANNING_EFFORT, WISDOM_ENV

_PLAN_SCRIPT = """
import hashlib, json, sys, time
import numpy as np
from autotrack.tracker import dcf, fft_plans
channels, rows, cols, start_at = int(sys.argv[1]), int(sys.argv[2]), int(sys.argv[3]), float(sys.argv[4])
maps = np.random.default_rng(7).standard_normal((channels, rows, cols)).astype(np.float32)
time.sleep(max(0.0, start_at - time.time()))
transform = dcf.SpectrumTransform(channels, (rows, cols))
spectrum = transform.forward(maps)
back = transform.inverse_scratch(spectrum.copy())
print(json.dumps({
    "effort": transform.effort,
    "measured_seconds": fft_plans.last_measure_seconds(),
    "spectrum": hashlib.sha256(spectrum.tobytes()).hexdigest(),
    "round_trip": float(np.max(np.abs(back - maps))),
}))
"""


def _plan_in_processes(wisdom, shape, count=1, together=False) -> list[dict]:
    """Run `count` fresh processes planning `shape` with `wisdom` as the wisdom file, one after
    the other, or all starting to plan at the same moment (`together`)."""
    env = dict(os.environ, **{WISDOM_ENV: str(wisdom)})
    start_at = time.time() + 8.0 if together else 0.0
    command = [sys.executable, "-c", _PLAN_SCRIPT, *map(str, shape), str(start_at)]
    if not together:
        runs = [subprocess.run(command, env=env, capture_output=True, text=True, check=True)]
        for _ in range(count - 1):
            runs.append(
                subprocess.run(command, env=env, capture_output=True, text=True, check=True)
            )
        return [json.loads(run.stdout) for run in runs]
    processes = [
        subprocess.Popen(command, env=env, stdout=subprocess.PIPE, text=True) for _ in range(count)
    ]
    outputs = [process.communicate(timeout=120)[0] for process in processes]
    assert all(process.returncode == 0 for process in processes)
    return [json.loads(output) for output in outputs]


def test_a_second_process_plans_from_the_first_ones_wisdom(tmp_path):
    wisdom = tmp_path / "cache" / "wisdom.json"
    first, second = _plan_in_processes(wisdom, (42, 50, 50), count=2)
    assert first["effort"] == second["effort"] == PLANNING_EFFORT
    assert first["measured_seconds"] > 0.0  # the first process measured the new shape
    assert second["measured_seconds"] == 0.0  # the second one read it from the file
    assert first["spectrum"] == second["spectrum"]  # the same plan: bit for bit
    assert first["round_trip"] < 1e-4
    assert json.loads(wisdom.read_text())["format"] == 1


def test_concurrent_planners_of_a_new_shape_end_with_one_plan(tmp_path):
    wisdom = tmp_path / "wisdom.json"
    runs = _plan_in_processes(wisdom, (42, 48, 48), count=3, together=True)
    assert [run["measured_seconds"] > 0.0 for run in runs].count(True) == 1
    assert len({run["spectrum"] for run in runs}) == 1
    assert all(run["effort"] == PLANNING_EFFORT for run in runs)


_MEASURED_WISDOM_SCRIPT = """
import sys
from pathlib import Path
from autotrack.tracker import fft_plans
fft_plans._make_plans(tuple(int(side) for side in sys.argv[2:]), ("FFTW_MEASURE",))
fft_plans._save_file(Path(sys.argv[1]))
"""


def test_a_shape_only_measured_by_an_older_version_is_searched_again(tmp_path):
    """Wisdom files written before the patient search hold FFTW_MEASURE plans, which do not
    satisfy a patient request: the first process searches the shape and updates the file, and
    the next one plans from it."""
    wisdom = tmp_path / "wisdom.json"
    shape = (42, 50, 50)
    command = [sys.executable, "-c", _MEASURED_WISDOM_SCRIPT, str(wisdom), *map(str, shape)]
    subprocess.run(command, check=True, capture_output=True)
    measured_only = wisdom.read_text()
    first, second = _plan_in_processes(wisdom, shape, count=2)
    assert first["effort"] == second["effort"] == PLANNING_EFFORT
    assert first["measured_seconds"] > 0.0 and second["measured_seconds"] == 0.0
    assert first["spectrum"] == second["spectrum"]
    assert wisdom.read_text() != measured_only


def test_a_corrupt_wisdom_file_gives_estimated_plans_and_is_left_alone(tmp_path):
    wisdom = tmp_path / "wisdom.json"
    wisdom.write_text('{"format": 1, "wisdom": ["(fftw-3.3.5 fftw_wisdom #x1 #x2 truncated')
    (run,) = _plan_in_processes(wisdom, (32, 40, 40))
    assert run["effort"] == "FFTW_ESTIMATE"
    assert run["measured_seconds"] == 0.0
    assert run["round_trip"] < 1e-4
    assert wisdom.read_text().endswith("truncated")


def test_a_wisdom_file_from_another_fftw_gives_estimated_plans(tmp_path):
    wisdom = tmp_path / "wisdom.json"
    foreign = "(fftw-0.0 fftwf_wisdom #x1 #x2 #x3 #x4\n)\n"
    wisdom.write_text(json.dumps({"format": 1, "wisdom": [foreign] * 3}))
    (run,) = _plan_in_processes(wisdom, (32, 40, 40))
    assert run["effort"] == "FFTW_ESTIMATE"
    assert run["round_trip"] < 1e-4


def test_an_unwritable_wisdom_place_gives_estimated_plans(tmp_path):
    blocker = tmp_path / "not-a-folder"
    blocker.write_text("a file where the cache folder should be")
    (run,) = _plan_in_processes(blocker / "wisdom.json", (32, 40, 40))
    assert run["effort"] == "FFTW_ESTIMATE"
    assert run["round_trip"] < 1e-4
    assert blocker.read_text().startswith("a file")


def test_odd_sides_and_large_prime_factors_go_to_pocketfft():
    assert [side for side in range(38, 51) if fft_plans.prefers_pocketfft(side)] == [
        38, 39, 41, 43, 45, 46, 47, 49,
    ]  # fmt: skip
    assert fft_plans.largest_prime_factor(46) == 23
    assert dcf.SpectrumTransform(3, (47, 40)).effort == "pocketfft"
    assert dcf.SpectrumTransform(3, (40, 40)).effort != "pocketfft"


def test_both_backends_compute_the_same_transforms():
    rng = np.random.default_rng(3)
    for grid in ((47, 47), (38, 40), (40, 40)):
        maps = rng.standard_normal((4, *grid)).astype(np.float32)
        transform = dcf.SpectrumTransform(4, grid)
        spectrum = transform.forward(maps)
        expected = np.fft.rfft2(maps.astype(np.float64))
        np.testing.assert_allclose(spectrum, expected, rtol=0, atol=2e-4 * np.abs(expected).max())
        gain = rng.uniform(0.1, 1.0, grid).astype(np.float32)
        projected = transform.project(spectrum, spectrum * 0.5, 2.0, gain)
        spatial = np.fft.irfft2(3.0 * expected, s=grid) * gain
        np.testing.assert_allclose(
            projected, np.fft.rfft2(spatial), rtol=0, atol=2e-4 * np.abs(expected).max()
        )


_WARM_UP_SCRIPT = """
import json
from autotrack.params import TrackerParams
from autotrack.tracker import fft_plans
from autotrack.tracker.warmup import search_grid_sides, warm_up
warm_up()
print(json.dumps({
    "planned": [[*shape, effort] for shape, effort in fft_plans.planned_shapes().items()],
    "sides": list(search_grid_sides(TrackerParams())),
}))
"""


def test_warm_up_plans_every_search_grid_so_a_first_box_never_searches(tmp_path):
    """The app's warm-up plans the square grids of every search region size (38-50 cells) for
    colour and grey features, in a process new to them; a tracker started after it plans its
    grid from the wisdom (no search on the user's first box)."""
    env = dict(os.environ, **{WISDOM_ENV: str(tmp_path / "wisdom.json")})
    run = subprocess.run(
        [sys.executable, "-c", _WARM_UP_SCRIPT], env=env, capture_output=True, text=True
    )
    assert run.returncode == 0, run.stderr
    report = json.loads(run.stdout.strip().splitlines()[-1])
    assert report["sides"] == list(range(38, 51))
    planned = {(c, r, k): effort for c, r, k, effort in report["planned"]}
    channel_counts = {c for c, _, _ in planned}
    assert len(channel_counts) == 2  # colour and grey features
    for channels in channel_counts:
        for side in report["sides"]:
            if not fft_plans.prefers_pocketfft(side):
                assert planned[(channels, side, side)] == PLANNING_EFFORT
    first_box = _plan_in_processes(tmp_path / "wisdom.json", (max(channel_counts), 48, 48))
    assert first_box[0]["measured_seconds"] == 0.0
