"""Every output is written whole or not at all: a full disk (ENOSPC, injected into the one
place files are written, `autotrack.io.atomic`) leaves neither a partial file nor a clobbered
one, and the CLI says so in one line, exit 2 (issue 17)."""

from __future__ import annotations

import builtins
import errno
import os
import shutil
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from autotrack.io import atomic
from tests.sequences import moving_target_sequence

REPO = Path(__file__).resolve().parents[1]
DEMO = REPO / "static" / "demo"
SENTINEL = b"precious results\n"


class _FullDisk:
    """A file that takes half of what it is given, then reports a full disk."""

    def __init__(self, handle) -> None:
        self.handle = handle

    def write(self, data: bytes) -> int:
        self.handle.write(data[: len(data) // 2])
        self.handle.flush()
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    def __enter__(self) -> _FullDisk:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.handle.close()


def _fill_disk(monkeypatch: pytest.MonkeyPatch, stem: str | None = None) -> None:
    """Writes meet a full disk: every write, or only that of the output named `stem`."""

    def opened(path, mode):
        handle = builtins.open(path, mode)  # noqa: SIM115 - the writer closes it
        if stem is None or Path(path).name.startswith(f".{stem}."):
            return _FullDisk(handle)
        return handle

    monkeypatch.setattr(atomic, "open", opened, raising=False)


@pytest.fixture
def full_disk(monkeypatch: pytest.MonkeyPatch) -> None:
    _fill_disk(monkeypatch)


def _boxes() -> np.ndarray:
    return moving_target_sequence(num_frames=6).boxes


def _writers() -> dict[str, Callable[[Path], object]]:
    from matplotlib.figure import Figure

    from autotrack.io.csv_table import write_csv
    from autotrack.io.cvat import write_cvat_video
    from autotrack.io.live import LiveSummary, write_frame_log
    from autotrack.io.mot import write_mot
    from autotrack.io.otb_boxes import write_boxes
    from autotrack.io.tum import write_tum
    from autotrack.localization.scene import load_scene, save_scene

    boxes = _boxes()
    count = len(boxes)
    figure = Figure()
    figure.add_subplot().plot(boxes[:, 0])
    frame = moving_target_sequence(num_frames=1).frames[0]
    return {
        "boxes.txt": lambda path: write_boxes(path, boxes),
        "poses.tum": lambda path: write_tum(
            path, np.arange(count) / 30.0, boxes[:, :3], np.tile([0, 0, 0, 1.0], (count, 1))
        ),
        "tracks.csv": lambda path: write_csv(path, ["x", "y"], boxes[:, :2].tolist()),
        "tracks.mot": lambda path: write_mot(path, {"T1": boxes}),
        "tracks.xml": lambda path: write_cvat_video(path, {"T1": boxes}, frame_size=(320, 240)),
        "frames.csv": lambda path: write_frame_log(
            path, LiveSummary(count, tuple(np.arange(count) / 30.0), (), tuple(range(count)), 0.2)
        ),
        "scene.json": lambda path: save_scene(load_scene(DEMO / "scene.json"), path),
        "plot.png": lambda path: atomic.write_figure(path, figure),
        "frame.jpg": lambda path: atomic.write_image(path, frame),
    }


@pytest.mark.parametrize("name", list(_writers()))
@pytest.mark.parametrize("existing", [False, True], ids=["new", "existing"])
def test_a_full_disk_leaves_no_partial_file_and_no_clobbered_one(
    tmp_path: Path, request: pytest.FixtureRequest, name: str, existing: bool
) -> None:
    write = _writers()[name]
    reference = tmp_path / "reference" / name
    reference.parent.mkdir()
    write(reference)  # what a good disk gets
    assert reference.stat().st_size > 0
    out = tmp_path / "out"
    out.mkdir()
    target = out / name
    if existing:
        target.write_bytes(SENTINEL)
    request.getfixturevalue("full_disk")
    with pytest.raises(OSError) as caught:
        write(target)
    assert caught.value.errno == errno.ENOSPC and caught.value.filename == str(target)
    assert sorted(out.iterdir()) == ([target] if existing else [])
    if existing:
        assert target.read_bytes() == SENTINEL


LOCALIZE = ["localize", "demo", "--quiet", "--out", "out/p.tum", "--tracks", "out/t.csv"]
LOCALIZE += ["--smoothed", "out/s.tum"]
BENCH = ["bench", "seqs", "--no-progress", "--out", "out/results", "--json", "out/b.json"]
CLI_CASES = {
    # argv, files there before, the output whose write meets the full disk, files written whole
    "track --out": (
        ["track", "seq", "--init", "1,1,9,9", "--quiet", "--out", "out/b.txt"],
        [],
        "b",
        [],
    ),
    "track --out --force": (
        ["track", "seq", "--init", "1,1,9,9", "--quiet", "--force", "--out", "out/old.txt"],
        ["old.txt"],
        "old",
        [],
    ),
    "localize --out": (LOCALIZE, [], "p", []),
    "localize --tracks": (LOCALIZE, [], "t", ["p.tum"]),
    "localize --smoothed": (LOCALIZE, [], "s", ["p.tum", "t.csv"]),
    "bench --json": (BENCH, [], "b", ["results/*/moving.*"]),
    "synth": (
        ["synth", "out/synth", "--frames", "2", "--sequences", "1", "--quiet"],
        [],
        "00001",  # the first frame: the ground-truth files are written before the frames
        ["synth/*/*.json", "synth/*/*.tum", "synth/*/groundtruth/*.txt"],
    ),
}


@pytest.fixture(scope="module")
def workspace(tmp_path_factory) -> Path:
    import cv2

    root = tmp_path_factory.mktemp("full")
    frames = moving_target_sequence(num_frames=5).frames
    (root / "seq").mkdir()
    for index, frame in enumerate(frames, start=1):
        cv2.imwrite(str(root / "seq" / f"{index:04d}.png"), frame)
    (root / "seqs" / "moving" / "img").mkdir(parents=True)
    for index, frame in enumerate(frames, start=1):
        cv2.imwrite(str(root / "seqs" / "moving" / "img" / f"{index:04d}.jpg"), frame)
    gt = moving_target_sequence(num_frames=5).boxes + [1, 1, 0, 0]
    np.savetxt(root / "seqs" / "moving" / "groundtruth_rect.txt", gt, fmt="%.2f", delimiter=",")
    shutil.copytree(DEMO, root / "demo")
    return root


@pytest.mark.parametrize("case", list(CLI_CASES))
def test_a_full_disk_at_the_end_of_a_run_ends_in_one_line(
    workspace: Path, capsys: pytest.CaptureFixture, monkeypatch, case: str
) -> None:
    from autotrack.cli import main

    argv, existing, failing, whole = CLI_CASES[case]
    _fill_disk(monkeypatch, failing)
    monkeypatch.chdir(workspace)
    out = workspace / "out"
    shutil.rmtree(out, ignore_errors=True)
    out.mkdir()
    for name in existing:
        (out / name).write_bytes(SENTINEL)
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("autotrack: error: "), err
    assert "No space left on device" in err and ".partial" not in err
    left = {p.relative_to(out).as_posix() for p in out.rglob("*") if p.is_file()}
    written = {p.relative_to(out).as_posix() for pattern in whole for p in out.glob(pattern)}
    assert left == set(existing) | written  # outputs written before the full disk, each whole
    assert not any(name.startswith(f"{failing}.") for name in left - set(existing))
    for name in existing:
        assert (out / name).read_bytes() == SENTINEL
