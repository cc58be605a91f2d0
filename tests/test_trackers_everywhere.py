"""NanoTrack and the hybrid wherever a tracker is chosen: the Pipeline (its targets track
with them, in threads where child processes were asked for), `autotrack track|localize
--preset`, `autotrack sweep`, the session (the tracker's name, the hybrid's `trusted` per frame,
read back, resumed and printed), and the one-line refusal of model files that cannot be loaded.
Short runs on real frames (DTB70 Gull1) and the embedded demo."""

from __future__ import annotations

from pathlib import Path

import cv2
import jsonschema
import numpy as np
import pytest

from autotrack.cli import main
from autotrack.errors import InputError
from autotrack.hybrid.factory import TRUSTED, make_tracker, tracker_params
from autotrack.io.frames import open_frames
from autotrack.io.otb_boxes import read_boxes
from autotrack.pipeline import Pipeline
from autotrack.sessions import open_session

REPO = Path(__file__).resolve().parents[1]
DEMO = REPO / "static" / "demo"
GULL1 = REPO.parent / "shared" / "data" / "sequences" / "DTB70" / "Gull1"
HYBRID_START = 40
"""Gull1 from this frame: within 16 frames the hybrid trusts both, NanoTrack and the filter."""


def window(sequence: Path, folder: Path, start: int, count: int) -> Path:
    """Frames start..start+count-1 of a benchmark sequence with their ground truth (links)."""
    if not sequence.is_dir():
        pytest.skip(f"{sequence} is missing (the shared benchmark data)")
    (folder / "img").mkdir(parents=True)
    for image in sorted((sequence / "img").iterdir())[start : start + count]:
        (folder / "img" / image.name).symlink_to(image)
    rows = (sequence / "groundtruth_rect.txt").read_text().splitlines()[start : start + count]
    (folder / "groundtruth_rect.txt").write_text("\n".join(rows) + "\n")
    return folder


def direct_run(name: str, sequence: Path) -> list:
    """The results of tracker `name` run by hand over a sequence from its first true box."""
    tracker = make_tracker(name)
    box = read_boxes(sequence / "groundtruth_rect.txt")[0]
    results = []
    for index, path in enumerate(sorted((sequence / "img").iterdir())):
        frame = cv2.cvtColor(cv2.imread(str(path)), cv2.COLOR_BGR2RGB)
        results.append(tracker.init(frame, box) if index == 0 else tracker.update(frame))
    return results


@pytest.fixture(scope="module")
def gull(tmp_path_factory) -> Path:
    return window(GULL1, tmp_path_factory.mktemp("gull") / "Gull1", 0, 12)


@pytest.fixture(scope="module")
def gull_hybrid(tmp_path_factory) -> Path:
    return window(GULL1, tmp_path_factory.mktemp("gull40") / "Gull1", HYBRID_START, 16)


@pytest.fixture(scope="module")
def hybrid_results(gull_hybrid) -> list:
    return direct_run("hybrid", gull_hybrid)


def test_a_pipeline_target_tracks_with_nanotrack_in_threads(gull) -> None:
    expected = direct_run("nanotrack", gull)
    frames = open_frames(gull)
    # Two processes asked for: NanoTrack's targets run in this process's threads instead.
    with (
        frames,
        Pipeline(
            frames, tracker_params("nanotrack"), tracker="nanotrack", tracker_processes=2
        ) as run,
    ):
        assert run.tracker_name == "nanotrack"
        first = run.add_target(0, tuple(read_boxes(gull / "groundtruth_rect.txt")[0]))
        second = run.add_target(0, (400.0, 300.0, 60.0, 50.0))
        outcomes = list(run.run())
    boxes = np.array([outcome.tracks[first].box for outcome in outcomes])
    np.testing.assert_array_equal(boxes, [result.box for result in expected])
    last = outcomes[-1].tracks[first]
    assert last.response_map.shape == (16, 16) and np.isfinite(last.global_variation)
    assert second in outcomes[-1].tracks


def test_track_preset_nanotrack_writes_its_boxes_and_names_it_in_the_session(
    gull, tmp_path, capsys
) -> None:
    out, session = tmp_path / "boxes.txt", tmp_path / "run.mcap"
    argv = ["track", str(gull), "--preset", "nanotrack", "--out", str(out), "--quiet"]
    assert main([*argv, "--session", str(session)]) == 0
    assert "precision@20px" in capsys.readouterr().out
    expected = np.array([result.box for result in direct_run("nanotrack", gull)])
    np.testing.assert_allclose(read_boxes(out), expected, atol=1e-4)  # 4 decimals
    recorded = open_session(session)
    assert recorded.tracker_name == "nanotrack"
    assert not any(recorded.trusted["T1"])  # only the hybrid says whom it trusted


def test_track_preset_hybrid_records_whom_it_trusted_per_frame(
    gull_hybrid, hybrid_results, tmp_path, capsys
) -> None:
    trusted = [result.trusted for result in hybrid_results]
    assert {"both", "siamese"} <= set(trusted)  # the window exercises more than agreement
    out, session = tmp_path / "boxes.txt", tmp_path / "hybrid.mcap"
    argv = ["track", str(gull_hybrid), "--preset", "hybrid", "--out", str(out), "--quiet"]
    assert main([*argv, "--session", str(session)]) == 0
    expected = np.array([result.box for result in hybrid_results])
    np.testing.assert_allclose(read_boxes(out), expected, atol=1e-4)  # 4 decimals
    recorded = open_session(session)
    assert recorded.tracker_name == "hybrid"
    assert recorded.trusted["T1"].tolist() == trusted
    # Read back as the hybrid's results, and a resumed run tracks with the hybrid again.
    results = recorded.recorded_targets()["T1"].results
    assert [results[k].trusted for k in sorted(results)] == trusted
    frames = open_frames(gull_hybrid)
    with frames, Pipeline.resume(recorded, frames) as resumed:
        assert resumed.tracker_name == "hybrid"
        history = resumed.targets["T1"].results
        assert [history[k].trusted for k in range(len(trusted))] == trusted
    capsys.readouterr()
    assert main(["session", "info", str(session)]) == 0
    printed = capsys.readouterr().out
    assert "tracker   hybrid" in printed
    assert f"siamese {trusted.count('siamese')}" in printed
    table = tmp_path / "tracks.csv"
    assert main(["session", "export", str(session), "--csv", str(table)]) == 0
    rows = [line.split(",") for line in table.read_text().splitlines()]
    assert rows[0][-1] == "trusted" and [row[-1] for row in rows[1:]] == trusted


def test_the_trusted_field_follows_the_schema(hybrid_results) -> None:
    from autotrack.sessions.messages import target_messages
    from autotrack.sessions.schemas import schema_document

    schema = schema_document("autotrack.TargetSignals")
    for result in hybrid_results[:5]:
        topic, signals = target_messages(
            0, "T1", result, landmark_id=None, record_maps=False, rgba=(1, 0, 0, 1)
        )[0]
        jsonschema.validate(signals, schema)
        assert signals["trusted"] == result.trusted
    signals["trusted"] = "neither"
    with pytest.raises(jsonschema.ValidationError):
        jsonschema.validate(signals, schema)
    from autotrack.hybrid.tracker import BOTH, FILTER, SIAMESE

    assert TRUSTED == (BOTH, FILTER, SIAMESE)  # the codes the history and the schema use
    assert schema["properties"]["trusted"]["enum"] == [*TRUSTED, None]


@pytest.fixture(scope="module")
def demo_window(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("demo") / "demo"
    (folder / "img").mkdir(parents=True)
    for image in sorted((DEMO / "img").iterdir())[:8]:
        (folder / "img" / image.name).symlink_to(image)
    for name in ("scene.json", "boxes.json"):
        (folder / name).write_bytes((DEMO / name).read_bytes())
    return folder


@pytest.mark.parametrize("tracker", ["nanotrack", "hybrid"])
def test_localize_preset_tracks_the_landmarks_with_it(demo_window, tracker, tmp_path, capsys):
    session = tmp_path / f"{tracker}.mcap"
    argv = ["localize", str(demo_window), "--preset", tracker, "--session", str(session)]
    assert main([*argv, "--out", str(tmp_path / "poses.tum"), "--quiet"]) == 0
    assert "valid poses: 8" in capsys.readouterr().out
    recorded = open_session(session)
    assert recorded.tracker_name == tracker and len(recorded.targets) == 4
    assert any(recorded.trusted["T1"]) == (tracker == "hybrid")


def test_sweep_refuses_nanotrack_and_sweeps_the_hybrids_filter(gull, tmp_path, capsys) -> None:
    from autotrack.evaluation.datasets import load_sequences
    from autotrack.evaluation.sweep import grid_combinations, parse_grid, run_sweep

    root = tmp_path / "bench"
    root.mkdir()
    (root / "Gull1").symlink_to(gull)
    argv = ["sweep", str(root), "--grid", "phi=0.2,0.3", "--out", str(tmp_path / "out")]
    assert main([*argv, "--preset", "nanotrack", "--no-progress"]) == 2
    error = capsys.readouterr().err
    assert "nanotrack uses no TrackerParams" in error and len(error.splitlines()) == 1
    assert not (tmp_path / "out").exists()

    sequence = load_sequences(root)[0]
    hybrid = grid_combinations(tracker_params("hybrid"), parse_grid(["phi=0.3"]), "hybrid")
    swept = run_sweep([sequence], hybrid, tmp_path / "hybrid", progress=False)
    boxes = swept.benchmark.results[(hybrid[0].label, "Gull1")].boxes
    np.testing.assert_allclose(boxes, [r.box for r in direct_run("hybrid", gull)], atol=1e-9)
    # The same grid of autotrack+ (the hybrid's filter) is other results: refused in its folder.
    plain = grid_combinations(tracker_params("hybrid"), parse_grid(["phi=0.3"]))
    with pytest.raises(InputError, match="holds results of other parameters"):
        run_sweep([sequence], plain, tmp_path / "hybrid", progress=False)


@pytest.mark.parametrize("tracker", ["nanotrack", "hybrid"])
def test_unloadable_models_end_the_commands_in_one_line(
    gull, demo_window, missing_models, tracker, tmp_path, capsys
) -> None:
    out = tmp_path / "boxes.txt"
    argv = ["track", str(gull), "--preset", tracker, "--out", str(out), "--quiet"]
    assert main(argv) == 2
    error = capsys.readouterr().err
    assert error == f"autotrack: error: NanoTrack model not found: {missing_models}\n"
    assert not out.exists()
    assert main(["localize", str(demo_window), "--preset", tracker, "--quiet"]) == 2
    assert "NanoTrack model not found" in capsys.readouterr().err
    with pytest.raises(InputError, match="NanoTrack model not found"):
        make_tracker(tracker)


def test_unloadable_models_end_autotrack_app_before_it_serves(
    gull, missing_models, monkeypatch, capsys
) -> None:
    pytest.importorskip("viser")
    import autotrack_studio.cli

    def serve(*_args) -> int:
        raise AssertionError("the server would start")

    monkeypatch.setattr(autotrack_studio.cli, "free_port", serve)
    assert main(["app", str(gull), "--preset", "hybrid"]) == 2
    error = capsys.readouterr().err
    assert error == f"autotrack: error: NanoTrack model not found: {missing_models}\n"


def test_track_realtime_with_nanotrack_tracks_the_frames_it_takes(gull, tmp_path, capsys) -> None:
    frames = open_frames(gull)
    video = tmp_path / "gull.avi"
    writer = cv2.VideoWriter(str(video), cv2.VideoWriter_fourcc(*"MJPG"), 5.0, frames.frame_size)
    for index in range(len(frames)):
        writer.write(frames.read_bgr(index))
    writer.release()
    frames.close()
    x, y, w, h = read_boxes(gull / "groundtruth_rect.txt")[0]
    out = tmp_path / "boxes.txt"
    argv = ["track", str(video), "--realtime", "--preset", "nanotrack", "--fps", "5"]
    assert main([*argv, "--init", f"{x + 1},{y + 1},{w},{h}", "--out", str(out), "--quiet"]) == 0
    boxes = read_boxes(out)
    taken = np.flatnonzero(np.isfinite(boxes).all(axis=1))
    assert taken[0] == 0 and len(taken) >= 2
    # NanoTrack by hand over the frames the live run took, in order: the same boxes.
    with open_frames(video) as decoded:
        tracker = make_tracker("nanotrack")
        expected = [tracker.init(decoded.read(0), (x, y, w, h)).box]
        expected += [tracker.update(decoded.read(int(k))).box for k in taken[1:]]
    np.testing.assert_allclose(boxes[taken], expected, atol=1e-4)
