"""The benchmark runner, the tracker adapters and `autotrack bench` end to end."""

from __future__ import annotations

import json
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import cv2
import numpy as np
import pytest

from autotrack.cli import main
from autotrack.errors import InputError
from autotrack.evaluation import benchmark
from autotrack.evaluation.benchmark import (
    format_table,
    run_benchmark,
    run_task,
    summarize_run,
    summary_json,
)
from autotrack.evaluation.datasets import Sequence, load_sequences
from autotrack.evaluation.metrics import score_sequence
from autotrack.evaluation.peers import TRACKER_NAMES, OpenCVPeer, make_tracker
from autotrack.evaluation.runs import TaskResult, load_result, result_paths, single_thread
from autotrack.io.otb_boxes import read_boxes
from autotrack.machine import describe_machine, machine_line
from tests.conftest import COLOUR_TABLE, SEQUENCES


def _shared_sequence(dataset: str, name: str, frames: int) -> Sequence:
    """The first `frames` frames of a shared real sequence (skips when the data is absent)."""
    folder = SEQUENCES / dataset / name
    roots = load_sequences(folder) if folder.is_dir() else []
    if not roots:
        pytest.skip("shared data not available")
    sequence = roots[0]
    return Sequence(
        sequence.name,
        sequence.frame_paths[:frames],
        sequence.ground_truth[:frames],
        sequence.attributes,
        sequence.dataset,
    )


def _write_moving_square(folder: Path, frames: int, step: tuple[int, int], seed: int) -> None:
    """An OTB-style sequence: a textured square moving over a textured background."""
    rng = np.random.default_rng(seed)
    background = cv2.GaussianBlur(rng.integers(0, 255, (90, 120, 3), dtype=np.uint8), (5, 5), 0)
    target = np.kron(np.indices((4, 4)).sum(axis=0) % 2, np.ones((5, 5)))[..., None] * [
        250,
        40,
        40,
    ]
    (folder / "img").mkdir(parents=True)
    rows = []
    for index in range(frames):
        x, y = 30 + step[0] * index, 25 + step[1] * index
        frame = background.copy()
        frame[y : y + 20, x : x + 20] = target.astype(np.uint8)
        cv2.imwrite(str(folder / "img" / f"{index + 1:04d}.png"), frame)
        rows.append(f"{x + 1},{y + 1},20,20")
    (folder / "groundtruth_rect.txt").write_text("\n".join(rows) + "\n")


@pytest.fixture
def synthetic_root(tmp_path: Path) -> Path:
    root = tmp_path / "Synthetic"
    _write_moving_square(root / "right", 14, (2, 1), seed=1)
    _write_moving_square(root / "down", 10, (1, 2), seed=2)
    (root / "right" / "attributes.txt").write_text("FM, SV\n")
    (root / "down" / "attributes.txt").write_text("FM\n")
    return root


def test_make_tracker_knows_every_name_and_rejects_others():
    assert TRACKER_NAMES == (
        "autotrack",
        "strcf",
        "strcf+asr",
        "strcf+atr",
        "autotrack+",
        "nanotrack",
        "hybrid",
        "csrt",
        "kcf",
        "mosse",
    )
    with pytest.raises(InputError, match="unknown tracker 'staple'"):
        make_tracker("staple")


def test_opencv_peer_tracks_rgb_and_grey_frames(synthetic_root):
    (sequence, _) = load_sequences(synthetic_root)
    frames = sequence.frames()
    for grey in (False, True):
        tracker = make_tracker("kcf")
        first = frames.read(0)
        first = cv2.cvtColor(first, cv2.COLOR_RGB2GRAY) if grey else first
        assert tracker.init(first, sequence.init_box) == sequence.init_box
        for index in range(1, len(sequence)):
            frame = frames.read(index)
            box = tracker.update(cv2.cvtColor(frame, cv2.COLOR_RGB2GRAY) if grey else frame)
        assert np.allclose(box, sequence.ground_truth[-1], atol=2), grey


def test_opencv_peer_keeps_its_last_box_when_the_tracker_reports_failure():
    class FailingTracker:
        def init(self, frame, rect):
            self.rect = rect

        def update(self, frame):
            return False, (0.0, 0.0, 0.0, 0.0)

    peer = OpenCVPeer("mosse")
    peer._tracker = FailingTracker()
    frame = np.zeros((40, 50, 3), np.uint8)
    assert peer.init(frame, (10.4, 5.6, 8.2, 9.5)) == (10.0, 6.0, 8.0, 10.0)
    assert peer.update(frame) == (10.0, 6.0, 8.0, 10.0)


def test_run_task_on_a_real_sequence_with_opencv_peers():
    sequence = _shared_sequence("OTB", "Crossing", 20)
    for name in ("kcf", "mosse", "csrt"):
        result = run_task(name, sequence)
        assert result.boxes.shape == (20, 4) and result.times.shape == (20,)
        assert np.all(result.times > 0)
        np.testing.assert_array_equal(result.boxes[0], np.round(sequence.ground_truth[0]))
    # CSRT follows the pedestrian over these frames (its P@20 on the full sequence is 1.0).
    assert score_sequence("c", result.boxes, sequence.ground_truth).precision == 1.0


def test_single_thread_limits_opencv_numba_and_blas_and_restores_them():
    numba = pytest.importorskip("numba")
    before = (cv2.getNumThreads(), numba.get_num_threads())
    with single_thread():
        assert cv2.getNumThreads() == 1 and numba.get_num_threads() == 1
        threadpoolctl = pytest.importorskip("threadpoolctl")
        assert all(pool["num_threads"] == 1 for pool in threadpoolctl.threadpool_info())
    assert (cv2.getNumThreads(), numba.get_num_threads()) == before


def test_resume_does_not_rerun_saved_pairs(synthetic_root, tmp_path, monkeypatch):
    sequences = load_sequences(synthetic_root)
    calls: list[tuple[str, str]] = []

    def counting_run_task(tracker, sequence, colour_table=None):
        calls.append((tracker, sequence.name))
        return run_task(tracker, sequence, colour_table)

    monkeypatch.setattr(benchmark, "run_task", counting_run_task)
    out = tmp_path / "results"
    first = run_benchmark(sequences, ["kcf", "mosse"], out, progress=False)
    assert first.computed == 4 and first.resumed == 0 and len(calls) == 4
    boxes_file, timing_file = result_paths(out, "kcf", "right")
    assert len(read_boxes(boxes_file)) == 14
    assert json.loads(timing_file.read_text())["frames"] == 14
    stamp = boxes_file.stat().st_mtime_ns

    second = run_benchmark(sequences, ["kcf", "mosse"], out, progress=False)
    assert second.computed == 0 and second.resumed == 4 and len(calls) == 4
    assert boxes_file.stat().st_mtime_ns == stamp
    np.testing.assert_array_equal(
        second.results[("kcf", "right")].boxes, first.results[("kcf", "right")].boxes
    )

    # A truncated box file (interrupted foreign write) is rerun, the others are not.
    boxes_file.write_text("\n".join(boxes_file.read_text().splitlines()[:5]) + "\n")
    third = run_benchmark(sequences, ["kcf", "mosse"], out, progress=False)
    assert third.computed == 1 and calls[-1] == ("kcf", "right")


def test_saved_result_from_another_colour_feature_is_not_reused(synthetic_root, tmp_path):
    (sequence, _) = load_sequences(synthetic_root)
    run_benchmark([sequence], ["kcf"], tmp_path, progress=False)
    assert isinstance(load_result(tmp_path, "kcf", sequence, None), TaskResult)
    assert load_result(tmp_path, "kcf", sequence, "table:/x/cn.npy") is None


def test_parallel_and_custom_executors_match_inline_results(synthetic_root, tmp_path):
    sequences = load_sequences(synthetic_root)
    inline = run_benchmark(sequences, ["kcf"], tmp_path / "inline", progress=False)
    pooled = run_benchmark(sequences, ["kcf"], tmp_path / "pool", jobs=2, progress=False)
    with ThreadPoolExecutor(max_workers=2) as executor:
        custom = run_benchmark(
            sequences, ["kcf"], tmp_path / "custom", executor=executor, progress=False
        )
    for sequence in sequences:
        key = ("kcf", sequence.name)
        np.testing.assert_array_equal(pooled.results[key].boxes, inline.results[key].boxes)
        np.testing.assert_array_equal(custom.results[key].boxes, inline.results[key].boxes)


def test_summary_json_schema_and_table(synthetic_root, tmp_path):
    sequences = load_sequences(synthetic_root)
    run = run_benchmark(sequences, ["kcf", "mosse"], tmp_path, progress=False)
    summaries = summarize_run(run)
    document = json.loads(json.dumps(summary_json(summaries, synthetic_root)))
    assert set(document["trackers"]) == {"kcf", "mosse"}
    kcf = document["trackers"]["kcf"]
    for key in ("precision", "auc", "fps", "fps_overall", "frames", "sequences"):
        assert key in kcf
    assert kcf["colour_feature"] is None and kcf["frames"] == 24
    assert set(kcf["sequences"]) == {"right", "down"}
    assert set(kcf["sequences"]["right"]) >= {"precision", "auc", "fps", "frames"}
    assert kcf["sequences"]["down"]["frames"] == 10
    assert kcf["precision"] == pytest.approx(summaries["kcf"].overall.precision, abs=1e-4)
    assert kcf["attributes"]["FM"]["sequences"] == 2 and kcf["attributes"]["SV"]["sequences"] == 1
    assert len(kcf["success_curve"]) == 21 and len(kcf["precision_curve"]) == 51
    table = format_table(summaries).splitlines()
    assert table[0].split()[:3] == ["tracker", "P@20", "AUC"]
    assert table[2].startswith("kcf") and table[3].startswith("mosse")


def test_cli_bench_end_to_end(synthetic_root, tmp_path, capsys):
    out, summary = tmp_path / "out", tmp_path / "summary.json"
    argv = ["bench", str(synthetic_root), "--trackers", "kcf,mosse", "--out", str(out)]
    code = main([*argv, "--json", str(summary), "--plots", "--no-progress"])
    assert code == 0
    printed = capsys.readouterr().out
    assert "2 sequences, 24 frames; 4 runs tracked, 0 resumed" in printed
    assert "kcf" in printed and "mosse" in printed
    assert (out / "kcf" / "right.txt").is_file() and (out / "mosse" / "down.txt").is_file()
    document = json.loads(summary.read_text())
    assert document["trackers"]["kcf"]["precision"] == pytest.approx(1.0)
    # where the fps were measured: this machine, in the JSON and under the table
    machine = document["machine"]
    assert machine == json.loads(json.dumps(describe_machine()))
    assert f"fps measured on: {machine_line(machine)}\n" in printed
    plots = sorted(path.name for path in (out / "plots").glob("*.png"))
    assert plots == [
        "precision.png",
        "precision_attribute_FM.png",
        "precision_attribute_SV.png",
        "success.png",
        "success_attribute_FM.png",
        "success_attribute_SV.png",
    ]
    assert main([*argv, "--no-progress"]) == 0
    printed = capsys.readouterr().out
    assert "0 runs tracked, 4 resumed" in printed
    assert "(the 4 resumed runs': where they ran)" in printed


def test_cli_bench_bad_input_is_one_line(synthetic_root, tmp_path, capsys):
    assert main(["bench", str(synthetic_root), "--trackers", "kcf,nope", "--no-progress"]) == 2
    error = capsys.readouterr().err.strip()
    assert error.startswith("autotrack: error: unknown tracker(s) nope") and "\n" not in error
    assert main(["bench", str(tmp_path / "missing"), "--no-progress"]) == 2
    assert "no such benchmark folder" in capsys.readouterr().err


def _require_autotrack() -> None:
    try:
        import autotrack.tracker.tracker  # noqa: F401
    except ImportError as error:
        pytest.skip(f"the AutoTrack tracker is not importable: {error}")


def test_autotrack_presets_run_through_the_benchmark(tmp_path):
    _require_autotrack()
    from autotrack import AutoTrack, preset
    from autotrack.io.frames import read_image

    sequence = _shared_sequence("UAV123_10fps", "building5", 30)
    run = run_benchmark([sequence], ["autotrack", "strcf", "kcf"], tmp_path, progress=False)
    summaries = summarize_run(run)
    frames = [read_image(path, index) for index, path in enumerate(sequence.frame_paths)]
    for name in ("autotrack", "strcf"):
        # The benchmark's boxes are the preset's own, run directly on the same frames ...
        tracker = AutoTrack(preset(name))
        direct = [tracker.init(frames[0], sequence.init_box).box]
        direct += [tracker.update(frame).box for frame in frames[1:]]
        np.testing.assert_allclose(run.results[(name, sequence.name)].boxes, direct, atol=1e-9)
        # ... and its scores are those boxes' scores against the ground truth.
        expected = score_sequence(sequence.name, np.array(direct), sequence.ground_truth)
        scored = summaries[name].sequences[sequence.name]
        assert scored.precision == expected.precision
        assert scored.auc == pytest.approx(expected.auc)
        assert summaries[name].overall.auc == pytest.approx(expected.auc)
    document = summary_json(summaries)
    assert document["trackers"]["autotrack"]["colour_feature"] == "lab11"
    assert document["trackers"]["kcf"]["colour_feature"] is None


def test_colour_table_reaches_the_autotrack_variants_and_the_json(tmp_path):
    _require_autotrack()
    table = COLOUR_TABLE
    if not table.is_file():
        pytest.skip("shared Color Names table not available")
    sequence = _shared_sequence("UAV123_10fps", "building5", 10)
    run = run_benchmark([sequence], ["strcf+asr"], tmp_path, colour_table=table, progress=False)
    document = summary_json(summarize_run(run))
    assert document["trackers"]["strcf+asr"]["colour_feature"] == f"table:{table}"
    # The saved result is tied to that colour feature: without the table it is rerun.
    assert load_result(tmp_path, "strcf+asr", sequence, "lab11") is None
    assert load_result(tmp_path, "strcf+asr", sequence, f"table:{table}") is not None


def test_ab_tracker_overrides_take_each_parameters_type():
    from benchmarks.ab_tracker import parse_overrides

    parsed = parse_overrides("rotation_step=10,robust_variation=1,num_aspects=17")
    assert parsed == {"rotation_step": 10.0, "robust_variation": True, "num_aspects": 17}
    assert isinstance(parsed["rotation_step"], float) and isinstance(parsed["num_aspects"], int)
    assert parse_overrides("") == {}
    with pytest.raises(ValueError, match="no tracker parameter 'rotation'"):
        parse_overrides("rotation=10")


def test_cost_curve_image_sizes_track_the_same_content():
    from benchmarks.cost_curve import _SlidingTexture

    frames = 60
    small, large = _SlidingTexture(640, 360, frames), _SlidingTexture(1920, 1080, frames)
    # The one-target points' box sits at the image's centre, which stays at one texture
    # position as the texture slides; around it (search region and scale samples of a 60 px
    # box, +-150 px) both image sizes hold the same pixels.
    around_small = small.texture[180 - 165 : 180 + 165, 320 - 200 : 320 + 200]
    around_large = large.texture[540 - 165 : 540 + 165, 960 - 200 : 960 + 200]
    assert np.array_equal(around_small, around_large)
    # ... and only there: the rest is each size's own noise.
    assert not np.array_equal(small.texture[:40, :40], large.texture[:40, :40])
    # Frame k is the texture moved by (1, 2) px a frame.
    assert np.array_equal(small.frame(3)[:-3, :-6], small.frame(0)[3:, 6:])


def test_cost_curve_runs_every_point_in_alternating_passes_and_keeps_the_fastest(monkeypatch):
    from benchmarks import cost_curve

    order = []

    def fake_run(**point):
        order.append(tuple(point.values()))
        return {"ms_per_frame": 10.0 - len(order) % 3}

    monkeypatch.setattr(cost_curve, "run_point", fake_run)
    runs = cost_curve.measure_all(frames=7, repeats=3)
    points = cost_curve._points(7)
    # The points the tables share (one 60x60 target, 1280x720, one thread) are measured once.
    assert len(points) == len(set(points)) == 7 + 4 + 8 - 2
    assert order == points + points[::-1] + points
    assert all(len(results) == 3 for results in runs.values())
    assert cost_curve._ms([{"ms_per_frame": t} for t in (9.5, 6.25, 8.0)]) == "6.25 (slowest 9.50)"
