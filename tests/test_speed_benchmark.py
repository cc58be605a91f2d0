"""benchmarks/speed.py's user-command section and its "Done when" lines (issue 41), on small
commands and constructed figures; the timings themselves are not asserted."""

from __future__ import annotations

import sys

import pytest

from tests.conftest import REPO

sys.path.insert(0, str(REPO / "benchmarks"))
import speed  # noqa: E402


def test_targets_print_pass_fail_and_what_was_not_measured(capsys):
    speed.print_targets({"localize": 44.9, "hybrid": 25.0}, {"autotrack+": 4.1})
    lines = capsys.readouterr().out.splitlines()
    verdicts = {line.split(":")[0].strip(): line for line in lines[1:]}
    assert verdicts["default `localize`, one thread, frames/s"].endswith("FAIL")
    assert verdicts["`hybrid`, one thread, frames/s"].endswith("PASS")
    assert verdicts["`autotrack+` / CSRT, one thread"].endswith("PASS")
    assert "not measured" in verdicts["faithful AutoTrack / CSRT, one thread"]


def test_ratios_to_csrt_are_medians_of_per_sequence_ratios():
    fps = {
        "autotrack": {"a": [100.0, 120.0], "b": [50.0], "c": [400.0]},
        "csrt": {"a": [20.0], "b": [25.0], "c": [40.0]},
    }
    # per sequence: a 110 / 20 = 5.5, b 2.0, c 10.0 -> median 5.5
    assert speed.single_target_ratios({"fps": fps}) == {"autotrack": pytest.approx(5.5)}
    assert speed.single_target_ratios({"fps": {"autotrack": fps["autotrack"]}}) == {}


def test_user_command_rates_fall_back_to_cpu_time_on_a_busy_machine(capsys):
    quiet = [{"wall": 10.0, "cpu": 9.5}]
    busy = [{"wall": 40.0, "cpu": 10.0}, {"wall": 20.0, "cpu": 12.0}]
    rates = speed.print_user_commands({"localize": (300, quiet, None), "hybrid": (600, busy, None)})
    assert rates["localize"] == pytest.approx(30.0)  # end to end: it had its core
    assert rates["hybrid"] == pytest.approx(600 / 11.0)  # per CPU second (median CPU time)
    assert "frames per CPU second" in capsys.readouterr().out


def test_whole_process_counts_the_childs_cpu_time():
    run = speed.whole_process([sys.executable, "-c", "sum(range(3_000_000))"])
    assert run["wall"] > 0.0 and run["cpu"] > 0.0
    with pytest.raises(Exception, match="returned non-zero"):
        speed.whole_process([sys.executable, "-c", "raise SystemExit(3)"])


def test_linked_root_is_a_benchmark_of_the_1280x720_sequences(tmp_path):
    from autotrack.evaluation.datasets import load_sequences

    root = speed.linked_root(tmp_path / "root", [speed.RATIO_SEQUENCE])
    sequences = load_sequences(root)
    assert [s.name for s in sequences] == [speed.RATIO_SEQUENCE]
    with sequences[0].frames() as frames:
        assert frames.read(0).shape == (720, 1280, 3)


def test_the_autotrack_command_is_this_environments():
    command = speed.autotrack_command()
    run = speed.whole_process([*command, "--help"])
    assert run["wall"] > 0.0


_THREADS_SCRIPT = """
import os, sys
import cv2
from autotrack.evaluation.datasets import load_otb_sequence
from autotrack.evaluation.runs import single_thread
from autotrack.io.frames import read_image
from autotrack.nanotrack import NanoTrack
sequence = load_otb_sequence(sys.argv[1])[0]
frames = [read_image(path) for path in sequence.frame_paths[:4]]
with single_thread():
    if sys.argv[2] != "1":
        cv2.setNumThreads(int(sys.argv[2]))
    before = len(os.listdir("/proc/self/task"))
    tracker = NanoTrack()
    tracker.init(frames[0], sequence.init_box)
    for frame in frames[1:]:
        tracker.update(frame)
    print(len(os.listdir("/proc/self/task")) - before)
"""


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="counts threads in /proc")
def test_nanotrack_runs_its_networks_on_the_benchmarks_one_thread():
    """Under `runs.single_thread` (how `bench` and speed.py track) cv2.dnn starts no worker
    thread for NanoTrack's networks; with two OpenCV threads it does (the check can fail)."""
    import subprocess

    sequence = str(speed.UAV123 / speed.RATIO_SEQUENCE)

    def new_threads(opencv_threads: int) -> int:
        command = [sys.executable, "-c", _THREADS_SCRIPT, sequence, str(opencv_threads)]
        done = subprocess.run(command, capture_output=True, text=True, check=True)
        return int(done.stdout.split()[-1])

    assert new_threads(1) == 0
    assert new_threads(2) > 0
