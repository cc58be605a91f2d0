"""Crash safety: a recording process killed with SIGKILL leaves a session that reads back.

A child process tracks a generated sequence (the real tracker when it imports, else results
built by hand from real arrays) and records every frame, printing after each frame what it
recorded and which frame the recorder reports as saved. The test reads the file while it grows,
kills the child with SIGKILL mid-run, then checks that everything the recorder had flushed is in
the file, bit for bit, and that nothing older than ~1.5 s of the child's own clock was lost.
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

import numpy as np
import pytest

from autotrack.cli import main
from autotrack.errors import SessionError
from autotrack.sessions import open_session

REPO_ROOT = Path(__file__).resolve().parents[1]
MIN_MESSAGES = 60
MIN_RECORDING_S = 3.0
MAX_LOSS_S = 1.5

CHILD = r'''
import json, math, sys, time
import numpy as np
from autotrack.params import TrackerParams
from autotrack.result import TrackResult
from autotrack.sessions import SessionRecorder

path = sys.argv[1]
rng = np.random.default_rng(3)
background = rng.integers(0, 255, (240, 320, 3), dtype=np.uint8)
patches = {"a": rng.integers(0, 255, (32, 32, 3), dtype=np.uint8),
           "b": rng.integers(0, 255, (30, 40, 3), dtype=np.uint8)}
starts = {"a": (60.0, 70.0), "b": (170.0, 130.0)}


def frame_at(k):
    frame = background.copy()
    for target_id, patch in patches.items():
        x = int(starts[target_id][0] + 20 * math.sin(0.05 * k))
        y = int(starts[target_id][1] + 10 * math.cos(0.04 * k))
        frame[y : y + patch.shape[0], x : x + patch.shape[1]] = patch
    return frame


try:
    from autotrack.tracker import AutoTrack
except ImportError:
    AutoTrack = None


class HandBuilt:
    """Results built from real arrays: a correlation response of the target patch."""

    def __init__(self, target_id):
        self.target_id = target_id
        self.previous = None

    def step(self, k, frame):
        x = starts[self.target_id][0] + 20 * math.sin(0.05 * k)
        y = starts[self.target_id][1] + 10 * math.cos(0.04 * k)
        patch = patches[self.target_id].astype(np.float32).mean(axis=2)
        window = frame[int(y) - 25 : int(y) + 25, int(x) - 25 : int(x) + 25].astype(np.float32)
        spectrum = np.fft.rfft2(window.mean(axis=2)) * np.conj(np.fft.rfft2(patch, s=(50, 50)))
        response = np.fft.fftshift(np.fft.irfft2(spectrum, s=(50, 50))).astype(np.float32)
        response /= np.float32(np.abs(response).max() or 1.0)
        local = None if self.previous is None else np.abs(response - self.previous)
        self.previous = response
        h, w = patches[self.target_id].shape[:2]
        return TrackResult(k, (x, y, float(w), float(h)), float(response.max()), response, local,
                           math.nan if local is None else float(np.linalg.norm(local, 2) / 1e4),
                           13.0, 12.0, False, 1.0, (x - 25, y - 25, 50.0, 50.0))


class Pose:
    def __init__(self, k):
        self.frame_index, self.valid, self.reason = k, True, ""
        self.position = np.array([0.01 * k, 1.0, 5.0])
        self.rotation = np.eye(3)
        self.reprojection_errors = {"L1": 0.5, "L2": 0.25}
        self.used_landmarks = ("L1", "L2")

    def quaternion_xyzw(self):
        return np.array([0.0, 0.0, 0.0, 1.0])


params = TrackerParams()
first = frame_at(0)
trackers = {}
with SessionRecorder(path, source="generated", tracker_params=params, fps=30.0) as recorder:
    k = 0
    while True:
        frame = frame_at(k)
        boxes = {}
        for target_id in patches:
            if AutoTrack is None:
                tracker = trackers.setdefault(target_id, HandBuilt(target_id))
                result = tracker.step(k, frame)
            elif k == 0:
                h, w = patches[target_id].shape[:2]
                trackers[target_id] = AutoTrack(params)
                box = (float(int(starts[target_id][0])), float(int(starts[target_id][1] + 10)),
                       float(w), float(h))
                result = trackers[target_id].init(frame, box)
            else:
                result = trackers[target_id].update(frame)
            recorder.log_target(target_id, result)
            boxes[target_id] = [float(v) for v in result.box]
        recorder.log_pose(Pose(k))
        report = {"frame": k, "t": time.monotonic(), "saved": recorder.saved_frame_index,
                  "boxes": boxes, "tracker": "AutoTrack" if AutoTrack else "hand-built"}
        print(json.dumps(report), flush=True)
        if AutoTrack is None:
            time.sleep(0.01)
        k += 1
'''


def _collect(stream, lines: list[str]) -> None:
    for line in stream:
        lines.append(line)


def test_kill_minus_nine_keeps_everything_flushed(
    tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    script = tmp_path / "record_forever.py"
    script.write_text(CHILD)
    session_path = tmp_path / "crash.mcap"
    env = dict(os.environ, PYTHONPATH=str(REPO_ROOT))
    child = subprocess.Popen(
        [sys.executable, str(script), str(session_path)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
    )
    lines: list[str] = []
    reader = threading.Thread(target=_collect, args=(child.stdout, lines), daemon=True)
    reader.start()
    deadline = time.monotonic() + 180
    try:
        while True:
            assert child.poll() is None, f"recorder exited early: {child.stderr.read()}"
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
    saved = last["saved"]
    assert saved is not None
    # Records reach the file in logging order: every frame before `saved` is complete.
    must_have = [r for r in reports if r["frame"] < saved]
    old_enough = [r for r in reports if r["t"] <= last["t"] - MAX_LOSS_S]
    assert old_enough, "the run was too short to check the loss window"
    assert len(session.frame_indices) > max(r["frame"] for r in must_have + old_enough)
    for report in reports:
        frame = report["frame"]
        if frame >= len(session.frame_indices):
            break
        for target_id, box in report["boxes"].items():
            if np.isnan(session.tracks[target_id][frame]).all():
                assert frame >= saved and report["t"] > last["t"] - MAX_LOSS_S
                continue
            np.testing.assert_array_equal(session.tracks[target_id][frame], box)
    assert session.poses.valid[:saved].all()

    assert main(["session", "info", str(session_path)]) == 0
    assert "cut short" in capsys.readouterr().out
