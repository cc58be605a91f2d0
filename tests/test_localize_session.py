"""`autotrack localize --session FILE` round-trips through `autotrack session info/export`."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from autotrack.cli import main
from autotrack.io.otb_boxes import read_boxes
from autotrack.io.tum import read_tum
from autotrack.sessions import open_session

DEMO = Path(__file__).resolve().parents[1] / "static" / "demo"


def test_localize_session_round_trips_to_the_same_tracks_and_poses(tmp_path, capsys):
    session = tmp_path / "demo.mcap"
    poses = tmp_path / "poses.tum"
    tracks_csv = tmp_path / "tracks.csv"
    argv = ["localize", str(DEMO), "--out", str(poses), "--tracks", str(tracks_csv)]
    assert main([*argv, "--session", str(session), "--quiet"]) == 0
    assert session.is_file()
    # A second run never overwrites the recording.
    assert main([*argv, "--session", str(session), "--quiet"]) == 2
    assert "exists" in capsys.readouterr().err

    assert main(["session", "info", str(session)]) == 0
    info = capsys.readouterr().out
    assert "60" in info and "4" in info

    exported = tmp_path / "export"
    command = ["session", "export", str(session), "--tracks", str(exported / "tracks")]
    command += ["--poses", str(exported / "poses.tum")]
    assert main(command) == 0

    # Same poses as localize wrote directly.
    direct, replayed = read_tum(poses), read_tum(exported / "poses.tum")
    for a, b in zip(direct, replayed, strict=True):
        np.testing.assert_allclose(a, b, atol=1e-6)
    # Same per-frame boxes as the localize CSV, per landmark (targets are T1.., each with the
    # landmark it localises).
    columns = np.genfromtxt(tracks_csv, delimiter=",", names=True, dtype=None, encoding="utf-8")
    target_of = {lm: target for target, lm in open_session(session).landmark_ids.items()}
    assert sorted(target_of) == ["A", "B", "C", "D"]
    for landmark, target in target_of.items():
        boxes = read_boxes(exported / "tracks" / f"{target}.txt")
        expected = np.stack([columns[f"{landmark}_{k}"] for k in "xywh"], axis=1)
        np.testing.assert_allclose(boxes, expected, atol=0.01)
