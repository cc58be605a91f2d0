"""Crash safety: a recording process killed with SIGKILL leaves a session that reads back.

A child process tracks two targets of a generated sequence with AutoTrack and records every
frame, printing after each frame the boxes it recorded and the frame the recorder reports as
saved. The test reads the file while it grows, kills the child with SIGKILL mid-run, then checks
that everything the recorder had flushed is in the file, bit for bit, and that nothing logged
more than 1.5 s (of the child's own clock) before its last frame was lost.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import IO

import numpy as np
import pytest

from autotrack.cli import main
from autotrack.errors import SessionError
from autotrack.sessions import open_session
from tests.conftest import REPO

MIN_MESSAGES = 60
MIN_RECORDING_S = 3.0
MAX_LOSS_S = 1.5

CHILD = r"""
import json, math, sys, time
import numpy as np
from autotrack.params import TrackerParams
from autotrack.sessions import SessionRecorder
from autotrack.tracker.tracker import AutoTrack

path = sys.argv[1]
rng = np.random.default_rng(3)
background = rng.integers(0, 255, (240, 320, 3), dtype=np.uint8)
patches = {"a": rng.integers(0, 255, (32, 32, 3), dtype=np.uint8),
           "b": rng.integers(0, 255, (30, 40, 3), dtype=np.uint8)}
starts = {"a": (60, 70), "b": (170, 130)}


def frame_at(k):
    # Two textured patches moving smoothly over a textured background.
    frame = background.copy()
    for target_id, patch in patches.items():
        x = int(starts[target_id][0] + 20 * math.sin(0.05 * k))
        y = int(starts[target_id][1] + 10 * math.cos(0.04 * k))
        frame[y : y + patch.shape[0], x : x + patch.shape[1]] = patch
    return frame


class Pose:
    # The attributes of autotrack.localize.PoseEstimate the recorder reads.
    def __init__(self, k):
        self.frame_index, self.valid, self.reason = k, True, ""
        self.position = np.array([0.01 * k, 1.0, 5.0])
        self.rotation = np.eye(3)
        self.reprojection_errors = {"L1": 0.5, "L2": 0.25}
        self.used_landmarks = ("L1", "L2")

    def quaternion_xyzw(self):
        return np.array([0.0, 0.0, 0.0, 1.0])


params = TrackerParams()
trackers = {target_id: AutoTrack(params) for target_id in patches}
with SessionRecorder(path, source="generated", tracker_params=params, fps=30.0) as recorder:
    k = 0
    while True:
        frame = frame_at(k)
        boxes = {}
        for target_id, tracker in trackers.items():
            if k == 0:
                h, w = patches[target_id].shape[:2]
                x, y = starts[target_id][0], starts[target_id][1] + 10
                result = tracker.init(frame, (float(x), float(y), float(w), float(h)))
            else:
                result = tracker.update(frame)
            recorder.log_target(target_id, result)
            boxes[target_id] = [float(v) for v in result.box]
        recorder.log_pose(Pose(k))
        report = {"frame": k, "t": time.monotonic(), "boxes": boxes}
        print(json.dumps(report), flush=True)
        k += 1
"""


def _collect(stream: IO[str], lines: list[str]) -> None:
    for line in stream:
        lines.append(line)


def test_kill_minus_nine_keeps_everything_flushed(
    tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    script = tmp_path / "record_forever.py"
    script.write_text(CHILD)
    session_path = tmp_path / "crash.mcap"
    env = dict(os.environ, PYTHONPATH=str(REPO))
    stderr_path = tmp_path / "stderr.txt"
    with open(stderr_path, "w") as stderr:
        child = subprocess.Popen(
            [sys.executable, str(script), str(session_path)],
            stdout=subprocess.PIPE,
            stderr=stderr,
            text=True,
            env=env,
        )
    lines: list[str] = []
    reader = threading.Thread(target=_collect, args=(child.stdout, lines), daemon=True)
    reader.start()
    deadline = time.monotonic() + 180
    try:
        while True:
            assert child.poll() is None, f"recorder exited early: {stderr_path.read_text()}"
            assert time.monotonic() < deadline, "recorder did not record enough in 180 s"
            time.sleep(0.2)
            reports = [json.loads(line) for line in list(lines)]
            if len(reports) < 2 or reports[-1]["t"] - reports[0]["t"] < MIN_RECORDING_S:
                continue
            try:
                growing = open_session(session_path)
            except SessionError:
                continue  # e.g. not even the metadata has reached the disk yet
            if growing.message_count > MIN_MESSAGES:
                break
        os.kill(child.pid, signal.SIGKILL)
    finally:
        if child.poll() is None:
            child.kill()
        child.wait(timeout=30)
    reader.join(timeout=30)
    assert child.returncode == -signal.SIGKILL

    reports = []
    for line in lines:
        try:
            reports.append(json.loads(line))
        except json.JSONDecodeError:
            break  # the line being printed when the process was killed
    session = open_session(session_path)
    assert session.truncated
    last = reports[-1]
    old_enough = [r for r in reports if r["t"] <= last["t"] - MAX_LOSS_S]
    assert old_enough, "the run was too short to check the loss window"
    saved = len(session.frame_indices)
    assert saved > max(r["frame"] for r in old_enough)
    for report in reports:
        frame = report["frame"]
        if frame >= len(session.frame_indices):
            break
        for target_id, box in report["boxes"].items():
            if np.isnan(session.tracks[target_id][frame]).all():
                # Only the last frame read can miss a target (cut between its records).
                assert frame == saved - 1 and report["t"] > last["t"] - MAX_LOSS_S
                continue
            np.testing.assert_array_equal(session.tracks[target_id][frame], box)
    assert session.poses.valid[: saved - 1].all()

    assert main(["session", "info", str(session_path)]) == 0
    assert "cut short" in capsys.readouterr().out


def _moving_patch_frames(count: int) -> list[np.ndarray]:
    rng = np.random.default_rng(5)
    background = rng.integers(0, 255, (160, 200, 3), dtype=np.uint8)
    patch = rng.integers(0, 255, (30, 30, 3), dtype=np.uint8)
    frames = []
    for k in range(count):
        frame = background.copy()
        frame[50 + k : 80 + k, 40 + 2 * k : 70 + 2 * k] = patch
        frames.append(frame)
    return frames


class _Pose:
    """The attributes of a PoseEstimate the recorder reads."""

    def __init__(self, frame_index: int) -> None:
        self.frame_index, self.valid, self.reason = frame_index, True, ""
        self.position = np.array([0.01 * frame_index, 1.0, 5.0])
        self.rotation = np.eye(3)
        self.reprojection_errors = {"L1": 0.5}
        self.used_landmarks = ("L1",)

    def quaternion_xyzw(self) -> np.ndarray:
        return np.array([0.0, 0.0, 0.0, 1.0])


@pytest.mark.parametrize("cut_after", ["first_target", "all_targets"])
def test_info_counts_only_complete_frames_of_a_cut_recording(
    tmp_path: Path, capsys: pytest.CaptureFixture, cut_after: str
) -> None:
    """The process is "killed" (the file copied as it is on disk) after part of the last
    frame's records reached the file: that frame is not counted, the earlier ones are."""
    from autotrack.params import TrackerParams
    from autotrack.sessions import SessionRecorder
    from autotrack.tracker.tracker import AutoTrack

    frames = _moving_patch_frames(6)
    params = TrackerParams()
    trackers = {"T1": AutoTrack(params), "T2": AutoTrack(params)}
    starts = {"T1": (40.0, 50.0, 30.0, 30.0), "T2": (120.0, 20.0, 40.0, 30.0)}
    path, cut = tmp_path / "live.mcap", tmp_path / "cut.mcap"
    with SessionRecorder(path, source="generated", tracker_params=params, fps=30.0) as recorder:
        for k, frame in enumerate(frames):
            for target_id, tracker in trackers.items():
                result = tracker.init(frame, starts[target_id]) if k == 0 else tracker.update(frame)
                recorder.log_target(target_id, result)
                if k == len(frames) - 1 and (cut_after == "first_target" or target_id == "T2"):
                    break
            if k == len(frames) - 1:
                recorder.flush()
                cut.write_bytes(path.read_bytes())  # what a kill -9 here leaves
                break
            recorder.log_pose(_Pose(k))
    session = open_session(cut)
    assert session.truncated and session.partial_frame == 5
    assert session.frame_count == 5
    assert main(["session", "info", str(cut)]) == 0
    out = capsys.readouterr().out
    assert "5 tracked (frames 0-4)" in out and "frame 5 was only partly written" in out
    # The complete file (closed normally) counts every frame.
    assert open_session(path).frame_count == 6 and open_session(path).partial_frame is None
