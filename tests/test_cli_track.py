"""`autotrack track`: output convention, scores, and one clear line for every bad input."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import cv2
import numpy as np
import pytest

from autotrack.cli import main
from autotrack.io.otb_boxes import read_boxes
from tests.sequences import moving_target_sequence


@pytest.fixture(scope="module")
def sequence_folder(tmp_path_factory) -> Path:
    generated = moving_target_sequence(num_frames=20)
    folder = tmp_path_factory.mktemp("seq") / "mover"
    (folder / "img").mkdir(parents=True)
    for index, frame in enumerate(generated.frames):
        cv2.imwrite(str(folder / "img" / f"{index + 1:04d}.png"), frame[:, :, ::-1])
    one_based = generated.boxes + np.array([1, 1, 0, 0])
    np.savetxt(folder / "groundtruth_rect.txt", one_based, fmt="%.3f", delimiter=",")
    return folder


def test_track_writes_one_based_boxes_and_prints_scores(sequence_folder, tmp_path, capsys):
    out = tmp_path / "boxes.txt"
    assert main(["track", str(sequence_folder), "--out", str(out), "--quiet"]) == 0
    printed = capsys.readouterr().out
    assert "frames: 20 · start-up " in printed and " fps over 17 frames" in printed
    assert "precision@20px: 1.000" in printed and "success AUC:" in printed
    boxes = read_boxes(out)  # read back to 0-based
    truth = read_boxes(sequence_folder / "groundtruth_rect.txt")
    assert boxes.shape == (20, 4)
    # The release's first box sits within half a pixel of the ground truth it was given.
    np.testing.assert_allclose(boxes[0], truth[0], atol=1.0)


def test_the_printed_rate_leaves_the_start_up_frames_out(sequence_folder, monkeypatch, capsys):
    from autotrack.cli.timing import STARTUP_FRAMES
    from autotrack.pipeline import Pipeline

    tracked = Pipeline.run

    def compiling_first(self):  # a first run: the first frames wait for the compiler
        for outcome in tracked(self):
            if outcome.frame_index < STARTUP_FRAMES:
                self.frame_seconds[outcome.frame_index] = 1000.0
            yield outcome

    monkeypatch.setattr(Pipeline, "run", compiling_first)
    assert main(["track", str(sequence_folder), "--quiet"]) == 0
    rate = re.search(r"tracker time only\) ([0-9.]+) fps over 17 frames", capsys.readouterr().out)
    assert rate is not None and float(rate.group(1)) > 1.0  # 17 frames / 3000 s would be 0.006


def _centres(boxes: np.ndarray) -> np.ndarray:
    return boxes[:, :2] + boxes[:, 2:] / 2


def test_track_with_explicit_init_starts_from_that_box(sequence_folder, tmp_path, capsys):
    """--init (1-based, like the output) is the first output row, and tracking starts there."""
    truth = read_boxes(sequence_folder / "groundtruth_rect.txt")  # 0-based
    np.testing.assert_array_equal(truth[0], [76, 100, 40, 40])
    on_target, on_background = tmp_path / "target.txt", tmp_path / "background.txt"
    folder = str(sequence_folder / "img")  # a plain image folder: no ground truth beside it
    assert (
        main(["track", folder, "--init", "77,101,40,40", "--out", str(on_target), "--quiet"]) == 0
    )
    assert "precision" not in capsys.readouterr().out
    argv = ["track", folder, "--init", "241,41,40,40", "--out", str(on_background), "--quiet"]
    assert main(argv) == 0
    assert on_target.read_text().splitlines()[0] == "77,101,40,40"
    assert on_background.read_text().splitlines()[0] == "241,41,40,40"

    # From the target's box the tracker follows it over its 128 px journey ...
    followed = read_boxes(on_target)
    errors = np.linalg.norm(_centres(followed) - _centres(truth), axis=1)
    assert np.linalg.norm(_centres(truth)[-1] - _centres(truth)[0]) > 120
    assert errors.max() < 10.0
    # ... while a box on the static background (0-based centre 260, 60) stays where it was.
    stayed = read_boxes(on_background)
    assert np.linalg.norm(_centres(stayed) - [260.0, 60.0], axis=1).max() < 10.0


def _error_line(capsys) -> str:
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "Traceback" not in err[0]
    return err[0]


def test_missing_and_empty_folders(tmp_path, capsys):
    assert main(["track", str(tmp_path / "nope")]) == 2
    assert "no such file" in _error_line(capsys)
    (tmp_path / "empty").mkdir()
    assert main(["track", str(tmp_path / "empty"), "--init", "1,1,5,5"]) == 2
    assert "no image files" in _error_line(capsys)


def test_corrupt_frame_in_the_middle_names_the_frame(sequence_folder, tmp_path, capsys):
    broken = tmp_path / "broken"
    (broken / "img").mkdir(parents=True)
    for index, path in enumerate(sorted((sequence_folder / "img").iterdir())[:8]):
        data = path.read_bytes() if index != 5 else b"not a png at all"
        (broken / "img" / path.name).write_bytes(data)
    lines = (sequence_folder / "groundtruth_rect.txt").read_text().splitlines()[:8]
    (broken / "groundtruth_rect.txt").write_text("\n".join(lines) + "\n")
    assert main(["track", str(broken), "--quiet"]) == 2
    line = _error_line(capsys)
    assert "frame 5" in line and "0006.png" in line


@pytest.mark.parametrize(
    ("init", "message"),
    [
        ("1,2,3", "four numbers"),
        ("a,b,c,d", "four numbers"),
        ("10,10,0,10", "--init 10,10,0,10 (1-based x,y,w,h) has zero size"),
        ("5000,10,20,20", "--init 5000,10,20,20 (1-based x,y,w,h) lies outside"),
        ("nan,10,20,20", "--init nan,10,20,20 (1-based x,y,w,h) must be four finite numbers"),
    ],
)
def test_bad_init_boxes(sequence_folder, capsys, init, message):
    """Each message quotes the box as the user typed it (1-based), not the tracker's 0-based
    values."""
    assert main(["track", str(sequence_folder), "--init", init, "--quiet"]) == 2
    assert message in _error_line(capsys)


def test_init_box_at_the_image_edge_is_checked_in_the_typed_convention(sequence_folder, capsys):
    """The centre of 1-based x = 1, w = 1 is 0-based 0.5: inside; of x = 0, w = 1 is -0.5."""
    assert main(["track", str(sequence_folder), "--init", "1,1,1,1", "--quiet"]) == 0
    capsys.readouterr()
    assert main(["track", str(sequence_folder), "--init", "0,1,1,1", "--quiet"]) == 2
    assert "--init 0,1,1,1 (1-based x,y,w,h) lies outside" in _error_line(capsys)


def test_unreadable_video_and_missing_colour_table(tmp_path, sequence_folder, capsys):
    video = tmp_path / "clip.mp4"
    video.write_bytes(b"\x00" * 64)
    assert main(["track", str(video), "--init", "1,1,5,5"]) == 2
    assert "video" in _error_line(capsys)
    missing = tmp_path / "cn.npy"
    assert main(["track", str(sequence_folder), "--color-names", str(missing)]) == 2
    assert "not found" in _error_line(capsys)


def test_console_script_exits_non_zero_without_traceback(tmp_path):
    completed = subprocess.run(
        [sys.executable, "-m", "autotrack.cli", "track", str(tmp_path / "missing")],
        capture_output=True,
        text=True,
        check=False,
    )
    assert completed.returncode == 2
    assert "Traceback" not in completed.stderr and "no such file" in completed.stderr
