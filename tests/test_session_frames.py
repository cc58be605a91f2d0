"""Session recordings embed the frames they tracked (issue 39 item 2): a JPEG or PNG file's
bytes as they are, any other frame encoded once as JPEG, on the camera topic at the time of
the frame's box annotations, valid for Foxglove's reader and schemas; `--no-frames` leaves
them out; `session export --frames` writes them back out."""

from __future__ import annotations

import base64
import json
import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest
from mcap.reader import make_reader

from autotrack.cli import main
from autotrack.io.frames import open_frames
from autotrack.sessions import open_session
from autotrack.sessions.frames import EmbeddedFrames
from tests.conftest import REPO
from tests.test_sessions import _validate_every_message

DEMO = REPO / "static" / "demo"
FRAMES = 5


@pytest.fixture(scope="module")
def short_demo(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The demo's first five frames: three JPEG files as shipped, one as PNG, one as BMP."""
    folder = tmp_path_factory.mktemp("demo") / "short"
    (folder / "img").mkdir(parents=True)
    for name in ("scene.json", "boxes.json"):
        shutil.copy(DEMO / name, folder / name)
    sources = sorted((DEMO / "img").iterdir())[:FRAMES]
    for index, source in enumerate(sources[:3]):
        shutil.copy(source, folder / "img" / f"{index + 1:05d}.jpg")
    cv2.imwrite(str(folder / "img" / "00004.png"), cv2.imread(str(sources[3])))
    cv2.imwrite(str(folder / "img" / "00005.bmp"), cv2.imread(str(sources[4])))
    return folder


def _images(path: Path) -> list[tuple[int, str, dict]]:
    """(log time, topic, payload) of every camera image and box annotation, read with the MCAP
    library itself."""
    with path.open("rb") as handle:
        return [
            (message.log_time, channel.topic, json.loads(message.data))
            for _, channel, message in make_reader(handle, validate_crcs=True).iter_messages()
            if channel.topic == "/camera/image" or channel.topic.endswith("/box")
        ]


def _localize(sequence: Path, session: Path, *extra: str) -> None:
    argv = ["localize", str(sequence), "--session", str(session), "--quiet", *extra]
    assert main(argv) == 0


def test_localize_embeds_each_frame_as_its_file_or_encoded_once(
    short_demo: Path, tmp_path: Path
) -> None:
    session = tmp_path / "s.mcap"
    _localize(short_demo, session)
    counts = _validate_every_message(session)  # Foxglove's published schemas, every message
    assert counts["foxglove.CompressedImage"] == FRAMES
    messages = _images(session)
    images = [(time, payload) for time, topic, payload in messages if topic == "/camera/image"]
    box_times = {time for time, topic, _ in messages if topic.endswith("/box")}
    assert [payload["format"] for _, payload in images] == ["jpeg"] * 3 + ["png", "jpeg"]
    assert {time for time, _ in images} == box_times  # the boxes sit on their frame's image
    assert {payload["frame_id"] for _, payload in images} == {"camera"}
    files = sorted((short_demo / "img").iterdir())
    for (_, payload), path in zip(images[:4], files[:4], strict=True):
        assert base64.b64decode(payload["data"]) == path.read_bytes()  # not re-encoded
    bmp = cv2.imdecode(np.frombuffer(base64.b64decode(images[4][1]["data"]), np.uint8), 1)
    assert np.abs(bmp.astype(int) - cv2.imread(str(files[4])).astype(int)).mean() < 3

    recorded = open_session(session)
    assert recorded.image_count == FRAMES and recorded.metadata["embed_frames"] == "true"
    assert not recorded.recorded_live  # reopened on its sequence, not on these frames
    with open_frames(short_demo) as original:
        embedded = EmbeddedFrames(recorded)
        assert len(embedded) == FRAMES
        for index in range(4):  # the files' own bytes: the same pixels
            np.testing.assert_array_equal(embedded.read(index), original.read(index))


def test_no_frames_leaves_them_out_and_export_writes_them_back(
    short_demo: Path, tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    with_frames, without = tmp_path / "frames.mcap", tmp_path / "none.mcap"
    _localize(short_demo, with_frames)
    _localize(short_demo, without, "--no-frames")
    assert not [m for m in _images(without) if m[1] == "/camera/image"]
    assert open_session(without).metadata["embed_frames"] == "false"
    assert with_frames.stat().st_size > without.stat().st_size

    out = tmp_path / "out"
    assert main(["session", "export", str(with_frames), "--frames", str(out)]) == 0
    written = sorted(out.iterdir())
    assert [p.name for p in written] == [
        "000001.jpg",
        "000002.jpg",
        "000003.jpg",
        "000004.png",
        "000005.jpg",
    ]
    files = sorted((short_demo / "img").iterdir())
    assert [p.read_bytes() for p in written[:4]] == [p.read_bytes() for p in files[:4]]
    with open_frames(out) as exported:  # a sequence the tools open again
        assert len(exported) == FRAMES
    capsys.readouterr()
    assert main(["session", "export", str(with_frames), "--frames", str(out)]) == 2
    assert "exists" in capsys.readouterr().err
    assert main(["session", "export", str(without), "--frames", str(tmp_path / "x")]) == 2
    assert "no frames" in capsys.readouterr().err
    assert not (tmp_path / "x").exists()


def test_track_records_a_session_with_its_frames(short_demo: Path, tmp_path: Path) -> None:
    session = tmp_path / "track.mcap"
    box = json.loads((short_demo / "boxes.json").read_text())["A"]
    init = ",".join(str(v + (1 if k < 2 else 0)) for k, v in enumerate(box))  # 1-based x, y
    argv = ["track", str(short_demo), "--init", init, "--session", str(session), "--quiet"]
    assert main(argv) == 0
    assert _validate_every_message(session)["foxglove.CompressedImage"] == FRAMES
    recorded = open_session(session)
    assert recorded.targets == ("T1",) and recorded.image_count == FRAMES
    assert main([*argv[:-3], "--session", str(tmp_path / "n.mcap"), "--no-frames"]) == 0
    assert open_session(tmp_path / "n.mcap").image_count == 0


def test_a_path_that_is_not_utf8_is_recorded_like_any_other(
    short_demo: Path, tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    """Issue 42 item 9: a Latin-1 folder name reaches the program surrogate-escaped
    (`os.fsdecode`); the session records it exactly and every command prints it."""
    import os

    folder = Path(os.fsdecode(os.fsencode(str(tmp_path)) + b"/caf\xe9"))
    shutil.copytree(short_demo, folder)
    session = folder / os.fsdecode(b"s\xe9.mcap")
    _localize(folder, session, "--out", str(folder / "poses.tum"))
    out = capsys.readouterr().out
    assert "session recorded to" in out and "caf\\udce9" in out  # shown, not a traceback
    recorded = open_session(session)
    assert recorded.source == str(folder)  # exactly the path given
    assert recorded.scene_path == str(folder / "scene.json")
    assert recorded.metadata["source"].endswith("caf\\xe9")  # readable text in the file
    assert recorded.image_count == FRAMES
    assert _validate_every_message(session)["foxglove.CompressedImage"] == FRAMES
    assert main(["session", "info", str(session)]) == 0
    assert "complete  yes" in capsys.readouterr().out
    frames_out = folder / os.fsdecode(b"fr\xe9")
    assert main(["session", "export", str(session), "--frames", str(frames_out)]) == 0
    assert len(list(frames_out.iterdir())) == FRAMES
