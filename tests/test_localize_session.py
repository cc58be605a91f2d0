"""`autotrack localize --session FILE` round-trips through `autotrack session info/export`."""

from __future__ import annotations

import re
from collections import Counter

import numpy as np
import pytest
from mcap.reader import make_reader

from autotrack.cli import main
from autotrack.io.otb_boxes import read_boxes
from autotrack.io.tum import read_tum
from autotrack.sessions import open_session
from tests.conftest import REPO

DEMO = REPO / "static" / "demo"
LANDMARKS = ("A", "B", "C", "D")
FRAMES = 60


def _topic_counts(path) -> Counter:
    """Messages per topic, read with the MCAP library itself (independent of our reader)."""
    with path.open("rb") as handle:
        return Counter(channel.topic for _, channel, _ in make_reader(handle).iter_messages())


def _info_fields(text: str) -> dict[str, str]:
    """`session info` lines as {label: rest}; target lines as {'target A': rest}."""
    fields = {}
    for line in text.splitlines():
        target = re.match(r"^  (\S+): (.*)$", line)
        if target:
            fields[f"target {target.group(1)}"] = target.group(2)
        else:
            label, _, rest = line.partition(" ")
            fields[label] = rest.strip()
    return fields


@pytest.mark.slow
def test_localize_session_round_trips_to_the_same_tracks_and_poses(tmp_path, capsys):
    session = tmp_path / "demo.mcap"
    poses = tmp_path / "poses.tum"
    tracks_csv = tmp_path / "tracks.csv"
    argv = ["localize", str(DEMO), "--out", str(poses), "--tracks", str(tracks_csv)]
    assert main([*argv, "--session", str(session), "--quiet"]) == 0
    assert session.is_file()
    # A second run never overwrites the recording.
    capsys.readouterr()
    assert main([*argv, "--session", str(session), "--quiet"]) == 2
    assert "exists" in capsys.readouterr().err

    columns = np.genfromtxt(tracks_csv, delimiter=",", names=True, dtype=None, encoding="utf-8")
    assert len(columns) == FRAMES
    valid_poses = int(np.sum(columns["valid"]))

    # Targets are T1.., each recorded with the landmark it localises.
    target_of = {lm: target for target, lm in open_session(session).landmark_ids.items()}
    assert sorted(target_of) == list(LANDMARKS)

    assert main(["session", "info", str(session)]) == 0
    info = _info_fields(capsys.readouterr().out)
    assert info["frames"] == f"{FRAMES} tracked (frames 0-{FRAMES - 1}) at 10 fps"
    assert info["duration"].startswith(f"{FRAMES / 10:.2f} s of video")
    assert info["targets"] == str(len(LANDMARKS))
    assert info["scene"] == str(DEMO / "scene.json")
    for landmark in LANDMARKS:
        aberrant = int(np.sum(columns[f"{landmark}_aberrant"]))
        assert info[f"target {target_of[landmark]}"] == (
            f"{FRAMES} boxes (frames 0-{FRAMES - 1}), {aberrant} aberrant, landmark {landmark}"
        )
    assert info["poses"] == f"{valid_poses} valid of {FRAMES}"
    assert info["events"] == f"{len(LANDMARKS)} box_drawn"

    # Every topic the layout promises (docs/sessions.md), with one message per frame where
    # there is one per frame: response maps from frame 1, local variation from frame 2 (eq. 2
    # needs two earlier responses), the spatial weights on the frames that trained (not
    # aberrant), pose topics on valid frames only, one landmark scene.
    counts = _topic_counts(session)
    expected = Counter({"/events": len(LANDMARKS), "/landmarks": 1})
    expected.update({topic: valid_poses for topic in ("/camera/pose", "/tf")})
    expected["/camera/pose_quality"] = FRAMES
    expected["/camera/image"] = FRAMES  # the frames are embedded by default
    for landmark, target in target_of.items():
        trained = FRAMES - int(np.sum(columns[f"{landmark}_aberrant"]))
        expected[f"/targets/{target}/spatial_window"] = trained
        expected[f"/targets/{target}/box"] = FRAMES
        expected[f"/targets/{target}/signals"] = FRAMES
        expected[f"/targets/{target}/response"] = FRAMES - 1
        expected[f"/targets/{target}/local_variation"] = FRAMES - 2
    assert counts == expected
    assert info["complete"] == f"yes ({sum(counts.values())} messages)"

    exported = tmp_path / "export"
    command = ["session", "export", str(session), "--tracks", str(exported / "tracks")]
    command += ["--poses", str(exported / "poses.tum")]
    assert main(command) == 0

    # Same poses as localize wrote directly.
    direct, replayed = read_tum(poses), read_tum(exported / "poses.tum")
    assert len(replayed[0]) == valid_poses
    for a, b in zip(direct, replayed, strict=True):
        np.testing.assert_allclose(a, b, atol=1e-6)
    # Same per-frame boxes as the localize CSV, per landmark.
    for landmark, target in target_of.items():
        boxes = read_boxes(exported / "tracks" / f"{target}_{landmark}.txt")
        expected_boxes = np.stack([columns[f"{landmark}_{k}"] for k in "xywh"], axis=1)
        assert boxes.shape == (FRAMES, 4)
        np.testing.assert_allclose(boxes, expected_boxes, atol=0.01)
