"""MOT Challenge and CVAT for video exports parse back; TUM poses read in evo; `session export`
writes them and prints evo's command."""

from __future__ import annotations

import shlex
import subprocess
import sys
import xml.etree.ElementTree as ElementTree
from pathlib import Path

import numpy as np
import pytest

from autotrack.cli import main
from autotrack.errors import InputError
from autotrack.io.cvat import read_cvat_video, write_cvat_video
from autotrack.io.mot import read_mot, write_mot
from autotrack.sessions import open_session
from tests.test_sessions import FPS, _record

FRAMES = 12


def _tracks() -> dict[str, np.ndarray]:
    """Two targets: 'car' seen throughout; 'bird' from frame 2, gone at 6-7, back until 9."""
    frames = np.arange(FRAMES, dtype=np.float64)[:, None]
    car = np.hstack([10 + 3.25 * frames, 20 + frames, np.full_like(frames, 40.5), 30 + frames])
    bird = np.hstack([100 - 2 * frames, 50 + 0.5 * frames, np.full((FRAMES, 2), 12.0)])
    bird[:2] = np.nan
    bird[6:8] = np.nan
    bird[10:] = np.nan
    return {"car": car, "bird": bird}


def test_mot_file_has_the_benchmark_layout_and_reads_back(tmp_path: Path) -> None:
    tracks = _tracks()
    scores = {"car": np.linspace(0.9, 0.5, FRAMES), "bird": np.full(FRAMES, np.nan)}
    ids = write_mot(tmp_path / "mot.txt", tracks, scores)
    assert ids == {"car": 1, "bird": 2}
    lines = (tmp_path / "mot.txt").read_text().splitlines()
    assert lines[0] == "1,1,11.00,21.00,40.50,30.00,0.9000,-1,-1,-1"
    assert lines[1] == "2,1,14.25,22.00,40.50,31.00,0.8636,-1,-1,-1"
    assert lines[2] == "3,1,17.50,23.00,40.50,32.00,0.8273,-1,-1,-1"
    assert lines[3] == "3,2,97.00,52.00,12.00,12.00,1.0000,-1,-1,-1"
    assert len(lines) == FRAMES + 6  # car every frame, bird on frames 2-5 and 8-9
    read = read_mot(tmp_path / "mot.txt", FRAMES)
    assert list(read) == [1, 2]
    np.testing.assert_allclose(read[1], tracks["car"], atol=0.005)
    np.testing.assert_allclose(read[2], tracks["bird"], atol=0.005)
    assert np.isnan(read[2][[0, 1, 6, 7, 10, 11]]).all()


def test_bad_mot_files_are_refused_with_the_line(tmp_path: Path) -> None:
    (tmp_path / "bad.txt").write_text("1,1,2,3,4,5,1,-1,-1,-1\n2,1,x,3,4,5\n")
    with pytest.raises(InputError, match="line 2: expected frame,id,left,top"):
        read_mot(tmp_path / "bad.txt")
    (tmp_path / "zero.txt").write_text("0,1,2,3,4,5,1,-1,-1,-1\n")
    with pytest.raises(InputError, match="frames count from 1"):
        read_mot(tmp_path / "zero.txt")


def test_cvat_video_xml_reads_back_with_keyframes_and_outside_marks(tmp_path: Path) -> None:
    tracks = _tracks()
    path = write_cvat_video(
        tmp_path / "tracks.xml",
        tracks,
        keyframes={"car": {0, 5}, "bird": {3}},
        frame_size=(320, 240),
        task_name="demo",
    )
    meta, read = read_cvat_video(path)
    assert meta["size"] == str(FRAMES) and meta["mode"] == "interpolation"
    assert meta["name"] == "demo" and meta["stop_frame"] == str(FRAMES - 1)
    assert [(t.track_id, t.label) for t in read] == [(0, "car"), (1, "bird")]
    car, bird = read
    np.testing.assert_allclose(car.boxes, tracks["car"], atol=0.005)
    np.testing.assert_allclose(bird.boxes, tracks["bird"], atol=0.005)
    assert car.keyframes == {0, 5} and car.outside == frozenset()
    # The first box of each visible stretch is a keyframe; where bird vanishes, outside="1".
    assert bird.keyframes == {2, 3, 8} and bird.outside == {6, 10}
    every = write_cvat_video(tmp_path / "all.xml", tracks, all_keyframes=True)
    _, (car_all, bird_all) = read_cvat_video(every)
    assert car_all.keyframes == set(range(FRAMES))
    assert bird_all.keyframes == {2, 3, 4, 5, 8, 9}


def test_cvat_video_xml_has_the_documented_structure(tmp_path: Path) -> None:
    """The elements and attributes of CVAT's XML format documentation (version 1.1, video)."""
    path = write_cvat_video(
        tmp_path / "tracks.xml", _tracks(), frame_size=(320, 240), label="object"
    )
    assert path.read_text(encoding="utf-8").startswith("<?xml version='1.0' encoding='utf-8'?>")
    root = ElementTree.parse(path).getroot()
    assert [child.tag for child in root] == ["version", "meta", "track", "track"]
    assert root.findtext("version") == "1.1"
    task = root.find("meta/task")
    tags = [child.tag for child in task]
    documented = ["id", "name", "size", "mode", "overlap", "bugtracker", "flipped", "created"]
    assert [tag for tag in tags if tag in documented] == documented
    assert tags.index("labels") < tags.index("original_size")
    assert task.findtext("original_size/width") == "320"
    assert task.findtext("original_size/height") == "240"
    assert [label.findtext("name") for label in task.findall("labels/label")] == ["object"]
    assert root.find("meta/dumped") is not None
    for track in root.findall("track"):
        assert set(track.attrib) == {"id", "label", "source"} and track.get("label") == "object"
        for box in track.findall("box"):
            assert set(box.attrib) == {
                "frame",
                "keyframe",
                "outside",
                "occluded",
                "xtl",
                "ytl",
                "xbr",
                "ybr",
                "z_order",
            }
            assert float(box.get("xbr")) > float(box.get("xtl"))


# A box track as CVAT itself writes one (the documentation's video example, with boxes).
CVAT_EXAMPLE = """<?xml version="1.0" encoding="utf-8"?>
<annotations>
  <version>1.1</version>
  <meta>
    <task>
      <id>5</id>
      <name>interpolation</name>
      <size>8</size>
      <mode>interpolation</mode>
      <overlap>5</overlap>
      <bugtracker></bugtracker>
      <flipped>False</flipped>
      <labels><label><name>car</name><attributes></attributes></label></labels>
      <original_size><width>640</width><height>480</height></original_size>
    </task>
    <dumped>2018-09-25 16:05:07.134046+03:00</dumped>
  </meta>
  <track id="0" label="car" source="manual">
    <box frame="0" xtl="324.79" ytl="213.16" xbr="371.11" ybr="237.37" outside="0" occluded="0" keyframe="1" z_order="0">
    </box>
    <box frame="1" xtl="325.79" ytl="213.16" xbr="372.11" ybr="237.37" outside="0" occluded="0" keyframe="0" z_order="0">
    </box>
    <box frame="2" xtl="325.79" ytl="213.16" xbr="372.11" ybr="237.37" outside="1" occluded="0" keyframe="1" z_order="0">
    </box>
    <box frame="6" xtl="305.32" ytl="206.32" xbr="355.32" ybr="254.74" outside="0" occluded="0" keyframe="1" z_order="0">
    </box>
  </track>
</annotations>
"""


def test_reader_reads_a_track_as_cvat_writes_it(tmp_path: Path) -> None:
    (tmp_path / "cvat.xml").write_text(CVAT_EXAMPLE, encoding="utf-8")
    meta, (track,) = read_cvat_video(tmp_path / "cvat.xml")
    assert meta["size"] == "8" and track.label == "car"
    np.testing.assert_allclose(track.boxes[0], [324.79, 213.16, 46.32, 24.21], atol=1e-9)
    assert np.isfinite(track.boxes[[0, 1, 6]]).all()
    assert np.isnan(track.boxes[[2, 3, 4, 5, 7]]).all()
    assert track.keyframes == {0, 6} and track.outside == {2}
    (tmp_path / "images.xml").write_text("<annotations><version>1.0</version></annotations>")
    with pytest.raises(InputError, match="not CVAT for video 1.1"):
        read_cvat_video(tmp_path / "images.xml")


@pytest.fixture(scope="module")
def session_path(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return _record(tmp_path_factory.mktemp("exports")).path


def test_session_export_writes_mot_and_cvat_with_the_corrected_frames_as_keyframes(
    session_path: Path, tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    session = open_session(session_path)
    mot, cvat = tmp_path / "tracks.mot.txt", tmp_path / "tracks.xml"
    argv = ["session", "export", str(session_path), "--mot", str(mot), "--cvat", str(cvat)]
    assert main(argv) == 2  # the recorded source is not on disk: the frame size is unknown
    assert "give --frame-size WIDTHxHEIGHT" in capsys.readouterr().err
    assert not cvat.exists()
    assert main([*argv, "--frame-size", "320x240x"]) == 2
    assert "--frame-size must be WIDTHxHEIGHT" in capsys.readouterr().err
    argv += ["--frame-size", "320x240", "--force"]
    assert main(argv) == 0
    printed = capsys.readouterr().out
    assert "(MOT ids: t1 (L1)=1, t2 (L2)=2)" in printed  # t3 was deleted by the user
    read = read_mot(mot, len(session.frame_indices))
    np.testing.assert_allclose(read[1], session.tracks["t1"], atol=0.005)
    np.testing.assert_allclose(read[2], session.tracks["t2"], atol=0.005)
    meta, tracks = read_cvat_video(cvat)
    root = ElementTree.parse(cvat).getroot()
    assert root.findtext("meta/task/original_size/width") == "320"
    assert [track.label for track in tracks] == ["t1 (L1)", "t2 (L2)"]  # target (landmark)
    np.testing.assert_allclose(tracks[0].boxes, session.tracks["t1"], atol=0.005)
    assert tracks[0].keyframes == {0, 20}  # drawn at 0, corrected at 20
    assert tracks[1].keyframes == {0}
    assert main(argv[:-1]) == 2  # without --force
    assert "already exists" in capsys.readouterr().err


def _evo_read_tum(path: Path):
    from evo.tools import file_interface

    return file_interface.read_tum_trajectory_file(str(path))


def test_tum_poses_read_in_evo_and_the_printed_evo_command_runs(
    session_path: Path, tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    pytest.importorskip("evo", reason="evo is in the test extra")
    session = open_session(session_path)
    poses, gt = tmp_path / "poses.tum", tmp_path / "gt.tum"
    argv = ["session", "export", str(session_path), "--poses", str(poses), "--evo"]
    assert main([*argv, "--gt", str(gt)]) == 0
    command = capsys.readouterr().out.strip().splitlines()[-1]
    assert command == shlex.join(
        ["evo_ape", "tum", str(gt), str(poses), "--pose_relation", "trans_part", "-v"]
    )
    trajectory = _evo_read_tum(poses)
    valid = session.poses.valid
    np.testing.assert_allclose(trajectory.timestamps, session.poses.frame_indices[valid] / FPS)
    np.testing.assert_allclose(trajectory.positions_xyz, session.poses.positions[valid], atol=1e-6)
    # evo stores quaternions w, x, y, z; ours are x, y, z, w.
    expected = np.roll(session.poses.quaternions_xyzw[valid], 1, axis=1)
    np.testing.assert_allclose(trajectory.orientations_quat_wxyz, expected, atol=1e-6)

    # A ground truth 5 cm off along x: evo's APE of the printed command is 0.05 m.
    from autotrack.io.tum import write_tum

    write_tum(
        gt,
        trajectory.timestamps,
        trajectory.positions_xyz + [0.05, 0.0, 0.0],
        np.roll(trajectory.orientations_quat_wxyz, -1, axis=1),
    )
    evo_ape = Path(sys.executable).parent / "evo_ape"
    arguments = shlex.split(command)
    result = subprocess.run(
        [str(evo_ape), *arguments[1:]], capture_output=True, text=True, timeout=120
    )
    assert result.returncode == 0, result.stderr
    rmse = next(line for line in result.stdout.splitlines() if line.strip().startswith("rmse"))
    assert float(rmse.split()[-1]) == pytest.approx(0.05, abs=1e-6)


def test_evo_without_ground_truth_or_poses_is_one_line(
    session_path: Path, tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    argv = ["session", "export", str(session_path), "--poses", str(tmp_path / "p.tum"), "--evo"]
    assert main(argv) == 2
    error = capsys.readouterr().err.strip()
    assert error.startswith("autotrack: error: --evo needs the ground-truth trajectory: give --gt")
    assert main(["session", "export", str(session_path), "--evo", "--csv", "x.csv"]) == 2
    assert "give --poses FILE" in capsys.readouterr().err
