"""A recording stays readable across a full disk and its recovery (issue 42 item 3): the first
failed write stops the recording, the file keeps every frame flushed before it, and nothing is
written after, even when space comes back."""

from __future__ import annotations

import errno
import io
import json
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader

import autotrack.sessions.recorder
from autotrack.cli import main
from autotrack.result import TrackResult
from autotrack.sessions import SessionRecorder, SessionWriteError, open_session
from autotrack.sessions.snapshot import finished_copy


class _FillingDisk(io.FileIO):
    """A file on a disk that fills after `room` bytes (a short write, then ENOSPC) until
    `recover()` gives the space back."""

    def __init__(self, path: Path, room: int) -> None:
        super().__init__(path, "xb")
        self.room = room
        self.refused = 0
        self.written_after_recovery = 0
        self.recovered = False

    def recover(self) -> None:
        self.recovered = True

    def write(self, data) -> int:
        if self.recovered:
            self.written_after_recovery += len(data)
            return super().write(data)
        if self.room <= 0:
            self.refused += 1
            raise OSError(errno.ENOSPC, "No space left on device")
        accepted = super().write(bytes(data[: self.room]))
        self.room -= accepted
        return accepted


def _result(frame_index: int) -> TrackResult:
    rng = np.random.default_rng(frame_index)
    response = rng.random((40, 40)).astype(np.float32)
    return TrackResult(
        frame_index=frame_index,
        box=(10.0 + frame_index, 20.0, 30.0, 40.0),
        peak_score=float(response.max()),
        response_map=response,
        local_variation=None,
        global_variation=0.5,
        theta_ref=12.0,
        theta=11.0,
        aberrant=False,
        scale_factor=1.0,
        search_box=(0.0, 0.0, 80.0, 80.0),
    )


@pytest.fixture
def filling_disk(monkeypatch: pytest.MonkeyPatch) -> list[_FillingDisk]:
    """Every session file the recorder creates sits on a disk with 60 kB free."""
    files: list[_FillingDisk] = []

    def create(path: Path) -> _FillingDisk:
        files.append(_FillingDisk(path, room=60_000))
        return files[-1]

    monkeypatch.setattr(autotrack.sessions.recorder, "_create_file", create)
    return files


def test_a_full_disk_stops_the_recording_and_keeps_every_frame_flushed_before(
    tmp_path: Path, filling_disk: list[_FillingDisk], capsys: pytest.CaptureFixture
) -> None:
    path = tmp_path / "s.mcap"
    recorder = SessionRecorder(path, source="generated", tracker_params={}, fps=10.0)
    flushed = []
    with pytest.raises(SessionWriteError, match="No space left on device") as failure:
        for frame_index in range(1000):
            recorder.log_target("T1", _result(frame_index))
            recorder.flush()  # one chunk per frame, as a slow source gets
            flushed.append(frame_index)
    assert "recording stopped" in str(failure.value)
    disk = filling_disk[0]
    assert recorder.write_error is not None and recorder.write_error.errno == errno.ENOSPC
    assert 10 < len(flushed) < 1000
    size_at_failure = path.stat().st_size

    disk.recover()  # space comes back while the recorder is still open
    with pytest.raises(SessionWriteError):
        recorder.log_target("T1", _result(len(flushed) + 1))
    with pytest.raises(SessionWriteError):
        recorder.log_event("box_drawn", 0, "T1", (1.0, 2.0, 3.0, 4.0))
    recorder.close()  # the failure was reported: close does not raise again
    recorder.close()
    assert disk.written_after_recovery == 0
    assert path.stat().st_size <= size_at_failure

    session = open_session(path)  # no "corrupted": a session cut short
    assert session.truncated
    assert session.frame_count == len(flushed)
    for frame_index in flushed:
        assert session.tracks["T1"][frame_index][0] == pytest.approx(10.0 + frame_index)
    # A finished copy of it is a valid MCAP file for any reader.
    copy = tmp_path / "copy.mcap"
    copy.write_bytes(finished_copy(path))
    with copy.open("rb") as handle:
        messages = list(make_reader(handle, validate_crcs=True).iter_messages())
    signals = [json.loads(m.data) for _, c, m in messages if c.topic == "/targets/T1/signals"]
    assert [row["frame_index"] for row in signals] == flushed
    assert main(["session", "info", str(path)]) == 0
    assert "cut short" in capsys.readouterr().out


def test_a_disk_full_at_close_leaves_the_file_readable(
    tmp_path: Path, filling_disk: list[_FillingDisk]
) -> None:
    path = tmp_path / "s.mcap"
    recorder = SessionRecorder(path, source="generated", tracker_params={}, fps=10.0)
    recorder.log_target("T1", _result(0))
    recorder.flush()
    filling_disk[0].room = 0  # the summary and footer find no space
    with pytest.raises(SessionWriteError):
        recorder.close()
    recorder.close()
    session = open_session(path)
    assert session.truncated and session.frame_count == 1
