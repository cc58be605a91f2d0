"""Results depend on the code and the input only: the same boxes, byte for byte, whatever the
state of any cache (empty, warm, unusable, read-only), and with threads or child processes."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from autotrack.params import preset
from autotrack.tracker.parallel.multi import MultiTracker
from tests import test_multi
from tests.conftest import needs_sequences, shared_sequence_dir
from tests.test_target_process import assert_identical

landmarks_sequence = test_multi.landmarks_sequence  # a generated sequence (session fixture)

CACHE_VARIABLES = ("AUTOTRACK_CACHE_DIR", "NUMBA_CACHE_DIR", "XDG_CACHE_HOME")


def _track(sequence: Path, out: Path, caches: dict[str, str]) -> bytes:
    """`autotrack track SEQUENCE --out OUT` in a fresh process with `caches` in its environment;
    returns the bytes of the boxes it wrote."""
    env = {key: value for key, value in os.environ.items() if key not in CACHE_VARIABLES}
    env.update(caches)
    command = [sys.executable, "-m", "autotrack.cli", "track", str(sequence)]
    done = subprocess.run(
        [*command, "--out", str(out), "--quiet"], env=env, capture_output=True, text=True
    )
    assert done.returncode == 0, done.stderr[-2000:]
    return out.read_bytes()


@pytest.mark.slow
@needs_sequences
def test_boxes_are_byte_identical_with_empty_warm_unusable_and_read_only_caches(tmp_path):
    sequence = shared_sequence_dir("DTB70", "Gull1")
    fresh = {name: str(tmp_path / "fresh" / name) for name in CACHE_VARIABLES}
    for folder in fresh.values():
        Path(folder).mkdir(parents=True)
    blocker = tmp_path / "a-file"  # no folder can be made below a file (even by root)
    blocker.write_text("")
    unusable = {name: str(blocker / name) for name in CACHE_VARIABLES}
    unusable["AUTOTRACK_FFTW_WISDOM"] = str(blocker / "wisdom.json")

    empty = _track(sequence, tmp_path / "empty.txt", fresh)
    warm = _track(sequence, tmp_path / "warm.txt", fresh)
    broken = _track(sequence, tmp_path / "unusable.txt", unusable)
    for folder in fresh.values():
        for path in [Path(folder), *Path(folder).rglob("*")]:
            path.chmod(0o555 if path.is_dir() else 0o444)
    try:
        read_only = _track(sequence, tmp_path / "read-only.txt", fresh)
    finally:
        for folder in fresh.values():
            for path in [Path(folder), *Path(folder).rglob("*")]:
                path.chmod(0o755 if path.is_dir() else 0o644)

    truth = (sequence / "groundtruth_rect.txt").read_text().splitlines()
    assert len(empty.splitlines()) == len(truth)
    assert warm == empty
    assert broken == empty
    assert read_only == empty


def test_threads_and_child_processes_give_identical_results(landmarks_sequence):
    frames, boxes, _ = landmarks_sequence
    params = preset("autotrack")
    with (
        MultiTracker(params, boxes, threads=3) as threaded,
        MultiTracker(params, boxes, processes=3) as spread,
    ):
        by_threads = test_multi.run(threaded, frames, boxes)
        by_processes = test_multi.run(spread, frames, boxes)
    for a, b in zip(by_threads, by_processes, strict=True):
        assert_identical(a, b)
