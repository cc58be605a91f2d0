"""File formats in autotrack.io: boxes.json, CSV tables, TUM, the frame cache; session topics."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest

from autotrack.errors import BoxError, InputError, SceneError
from autotrack.io.boxes_json import read_boxes_json
from autotrack.io.csv_table import write_csv
from autotrack.io.frames import FrameCache, InMemoryFrames
from autotrack.io.tum import read_tum, write_tum
from autotrack.localization.pnp import boxes_by_landmark
from autotrack.localization.scene import load_scene
from autotrack.sessions.schemas import TargetStream, TargetTopic, Topics

DEMO = Path(__file__).resolve().parents[1] / "static" / "demo"


def _write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "boxes.json"
    path.write_text(text, encoding="utf-8")
    return path


def test_boxes_json_reads_both_forms(tmp_path: Path) -> None:
    mapping = read_boxes_json(_write(tmp_path, '{"A": [1, 2, 3, 4], "B": [5.5, 6, 7, 8]}'))
    assert mapping == {"A": (1.0, 2.0, 3.0, 4.0), "B": (5.5, 6.0, 7.0, 8.0)}
    listed = read_boxes_json(_write(tmp_path, "[[1, 2, 3, 4], [5, 6, 7, 8]]"))
    assert listed == [(1.0, 2.0, 3.0, 4.0), (5.0, 6.0, 7.0, 8.0)]


@pytest.mark.parametrize(
    ("text", "error", "message"),
    [
        ("{not json", InputError, "not valid JSON (line 1)"),
        ('"A"', InputError, "expected {landmark id: [x, y, w, h]} or a list of boxes"),
        ('{"A": [1, 2, 3]}', BoxError, "the box of 'A' must be [x, y, w, h]"),
        ('[[1, 2, 3, "4"]]', BoxError, "box 1 must be [x, y, w, h]"),
        ('{"A": [1, 2, 0, 4]}', BoxError, "positive width and height"),
        ('{"A": [1, 2, true, 4]}', BoxError, "four numbers"),
    ],
)
def test_boxes_json_names_what_is_wrong(tmp_path: Path, text, error, message) -> None:
    with pytest.raises(error, match=re.escape(message)):
        read_boxes_json(_write(tmp_path, text))


def test_boxes_json_missing_file_is_an_input_error(tmp_path: Path) -> None:
    with pytest.raises(InputError, match="cannot read boxes file"):
        read_boxes_json(tmp_path / "absent.json")


def test_boxes_by_landmark_checks_a_mapping_and_assigns_a_list() -> None:
    scene = load_scene(DEMO / "scene.json")
    boxes = read_boxes_json(DEMO / "boxes.json")
    assert boxes_by_landmark(boxes, scene) == boxes
    assert boxes_by_landmark([boxes[k] for k in ("B", "D", "C", "A")], scene) == boxes
    with pytest.raises(SceneError, match="unknown landmark 'Z'"):
        boxes_by_landmark({"Z": boxes["A"]}, scene)
    with pytest.raises(InputError, match="cannot tell which box is which landmark"):
        boxes_by_landmark([(10.0, 10.0, 5.0, 5.0), *list(boxes.values())[1:]], scene)


def test_csv_writer_writes_header_and_rows_with_unix_line_ends(tmp_path: Path) -> None:
    path = write_csv(tmp_path / "t.csv", ["frame", "x"], [[0, 1.5], [1, float("nan")]])
    assert path.read_bytes() == b"frame,x\n0,1.5\n1,nan\n"
    with pytest.raises(FileExistsError):
        write_csv(path, ["frame"], [], overwrite=False)


def test_tum_round_trip_skips_invalid_poses(tmp_path: Path) -> None:
    positions = np.array([[0.0, 1.0, 2.0], [np.nan] * 3, [3.0, 4.0, 5.0]])
    quaternions = np.array([[0.0, 0.0, 0.0, 1.0]] * 3)
    assert write_tum(tmp_path / "p.tum", [0.0, 0.1, 0.2], positions, quaternions) == 2
    stamps, read_positions, read_quaternions = read_tum(tmp_path / "p.tum")
    np.testing.assert_allclose(stamps, [0.0, 0.2])
    np.testing.assert_allclose(read_positions, positions[[0, 2]])
    np.testing.assert_allclose(read_quaternions, quaternions[[0, 2]])


def test_frame_cache_keeps_the_last_frames_and_checks_the_range() -> None:
    images = [np.full((4, 6, 3), k, np.uint8) for k in range(5)]
    cache = FrameCache(InMemoryFrames(images, "five"), size=2)
    assert cache.read(3) is images[3]
    assert cache.read(3) is images[3]
    with pytest.raises(InputError, match="frame 5 is outside 0..4"):
        cache.read(5)
    frames = InMemoryFrames(images, "five")
    assert frames.frame_size == (6, 4)
    np.testing.assert_array_equal(frames.read_bgr(2), images[2])  # a grey-level frame


def test_target_topics_round_trip_and_other_topics_are_not_targets() -> None:
    for stream in TargetStream:
        topic = TargetTopic("T7", stream)
        assert TargetTopic.parse(topic.topic.name) == topic
        assert topic.topic.schema == stream.schema
    assert TargetTopic("T1", TargetStream.BOX).topic.name == "/targets/T1/box"
    for fixed in (Topics.POSE, Topics.TF, Topics.EVENTS, Topics.LANDMARKS):
        assert TargetTopic.parse(fixed.name) is None
    assert TargetTopic.parse("/targets/T1/unknown") is None
    assert json.loads(json.dumps(TargetStream.SIGNALS)) == "signals"
