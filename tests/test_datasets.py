"""Benchmark loaders for every layout, layout detection, box files and attributes."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from autotrack.errors import InputError
from autotrack.evaluation.datasets import Sequence, detect_layout, load_sequences, load_uav123
from autotrack.evaluation.metrics import score_sequence
from autotrack.io.otb_boxes import read_boxes, write_boxes
from tests.conftest import (
    OCTAVE_REFERENCE,
    OFFICIAL_REFERENCE,
    SEQUENCES,
    needs_sequences,
    shared_sequence_dir,
)


def _write_images(folder: Path, count: int, prefix: str = "", digits: int = 6) -> list[Path]:
    """Tiny PNG frames whose pixel value is the frame number (1-based)."""
    folder.mkdir(parents=True, exist_ok=True)
    paths = []
    for number in range(1, count + 1):
        path = folder / f"{prefix}{number:0{digits}d}.png"
        cv2.imwrite(str(path), np.full((6, 8), number, np.uint8))
        paths.append(path)
    return paths


def _write_rows(path: Path, rows: list[str]) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text("\n".join(rows) + "\n")


def _frame_numbers(sequence: Sequence) -> list[int]:
    return [int(cv2.imread(str(p), cv2.IMREAD_GRAYSCALE)[0, 0]) for p in sequence.frame_paths]


def _boxes(count: int, start: int = 1) -> list[str]:
    return [f"{start + i},{start + i},4,3" for i in range(count)]


def test_box_files_are_read_zero_based_and_written_one_based(tmp_path):
    path = tmp_path / "gt.txt"
    path.write_text("10\t20\t30\t40\n\n5.5 6 7 8\nNaN,NaN,NaN,NaN\n1,2,NaN,4\n")
    boxes = read_boxes(path)
    np.testing.assert_array_equal(boxes[:2], [[9, 19, 30, 40], [4.5, 5, 7, 8]])
    assert np.isnan(boxes[2:]).all()
    write_boxes(tmp_path / "out.txt", boxes)
    assert (tmp_path / "out.txt").read_text().splitlines() == [
        "10,20,30,40",
        "5.5,6,7,8",
        "NaN,NaN,NaN,NaN",
        "NaN,NaN,NaN,NaN",
    ]


def test_malformed_box_file_names_the_line(tmp_path):
    path = tmp_path / "gt.txt"
    path.write_text("1,2,3,4\n1,2,3\n")
    with pytest.raises(InputError, match="line 2: expected 4 values"):
        read_boxes(path)
    path.write_text("1,2,3,4\n1,2,x,4\n")
    with pytest.raises(InputError, match="line 2: not a number"):
        read_boxes(path)


def test_otb_dataset_with_nan_rows_attributes_and_two_targets(tmp_path):
    root = tmp_path / "DTB70"
    _write_images(root / "Car1" / "img", 4, digits=5)
    _write_rows(root / "Car1" / "groundtruth_rect.txt", ["3,4,5,6", "NaN,NaN,NaN,NaN", *_boxes(2)])
    # DTB70 flag order: SV ARV OCC DEF FCM IPR OPR OV BC SOA MB.
    _write_rows(root / "att" / "Car1.txt", ["1,0,1,0,0,0,0,0,0,0,1"])
    _write_images(root / "Jogging" / "img", 2, digits=4)
    _write_rows(root / "Jogging" / "groundtruth_rect.1.txt", _boxes(2))
    _write_rows(root / "Jogging" / "groundtruth_rect.2.txt", _boxes(2, start=7))
    (root / "not_a_sequence").mkdir()

    assert detect_layout(root) == "otb"
    sequences = {s.name: s for s in load_sequences(root)}
    assert sorted(sequences) == ["Car1", "Jogging-1", "Jogging-2"]
    car = sequences["Car1"]
    assert car.dataset == "DTB70" and len(car) == 4
    assert car.attributes == {"SV", "OCC", "MB"}
    np.testing.assert_array_equal(car.ground_truth[0], [2, 3, 5, 6])
    assert np.isnan(car.ground_truth[1]).all()
    assert car.init_box == (2.0, 3.0, 5.0, 6.0)
    np.testing.assert_array_equal(sequences["Jogging-2"].ground_truth[0], [6, 6, 4, 3])
    assert detect_layout(root / "Car1") == "otb-sequence"


def test_named_attributes_and_attribute_names_file(tmp_path):
    root = tmp_path / "MyData"
    for name in ("a", "b"):
        _write_images(root / name / "img", 2)
        _write_rows(root / name / "groundtruth_rect.txt", _boxes(2))
    _write_rows(root / "a" / "attributes.txt", ["SV, night"])
    _write_rows(root / "att" / "b.txt", ["0 1 1"])
    with pytest.raises(InputError, match="3 attribute flags but no known column order"):
        load_sequences(root)
    _write_rows(root / "att" / "attribute_names.txt", ["SV", "IV", "OCC"])
    sequences = {s.name: s for s in load_sequences(root)}
    assert sequences["a"].attributes == {"SV", "night"}
    assert sequences["b"].attributes == {"IV", "OCC"}


def test_frame_and_ground_truth_count_mismatch_is_reported(tmp_path):
    _write_images(tmp_path / "seq" / "img", 3)
    _write_rows(tmp_path / "seq" / "groundtruth_rect.txt", _boxes(2))
    with pytest.raises(InputError, match="3 frames but 2 ground-truth rows"):
        load_sequences(tmp_path / "seq")


def _uav123_tree(root: Path) -> None:
    video_root, anno = root / "data_seq" / "UAV123_10fps", root / "anno" / "UAV123_10fps"
    _write_images(video_root / "bike1", 5)
    _write_rows(anno / "bike1.txt", ["1,1,4,3", "NaN,NaN,NaN,NaN", *_boxes(3)])
    # UAV123 flag order: SV ARC LR FM FOC POC OV BC IV VC CM SOB.
    _write_rows(anno / "att" / "bike1.txt", ["1,0,0,0,1,0,0,0,0,0,0,1"])
    # car1: sub-sequences sharing their boundary frame, as in configSeqs (1-4, 4-7).
    _write_images(video_root / "car1", 7)
    _write_rows(anno / "car1_1.txt", _boxes(4))
    _write_rows(anno / "car1_2.txt", _boxes(4))
    # boat2: sub-sequences back to back (1-3, 4-6).
    _write_images(video_root / "boat2", 6)
    _write_rows(anno / "boat2_1.txt", _boxes(3))
    _write_rows(anno / "boat2_2.txt", _boxes(3))


def test_uav123_subsequences_partition_their_video(tmp_path):
    _uav123_tree(tmp_path)
    assert detect_layout(tmp_path) == "uav123"
    sequences = {s.name: s for s in load_sequences(tmp_path)}
    assert sorted(sequences) == ["bike1", "boat2_1", "boat2_2", "car1_1", "car1_2"]
    bike = sequences["bike1"]
    assert bike.dataset == "UAV123_10fps"
    assert bike.attributes == {"SV", "FOC", "SOB"}
    assert np.isnan(bike.ground_truth[1]).all()
    assert _frame_numbers(sequences["car1_1"]) == [1, 2, 3, 4]
    assert _frame_numbers(sequences["car1_2"]) == [4, 5, 6, 7]
    assert _frame_numbers(sequences["boat2_1"]) == [1, 2, 3]
    assert _frame_numbers(sequences["boat2_2"]) == [4, 5, 6]


def test_uav123_subsequences_with_gaps_need_the_ranges_file(tmp_path):
    _uav123_tree(tmp_path)
    video_root, anno = tmp_path / "data_seq" / "UAV123_10fps", tmp_path / "anno" / "UAV123_10fps"
    _write_images(video_root / "bird1", 12)
    _write_rows(anno / "bird1_1.txt", _boxes(3))
    _write_rows(anno / "bird1_2.txt", _boxes(4))
    with pytest.raises(InputError, match="sequence_ranges.txt"):
        load_uav123(tmp_path)
    _write_rows(
        tmp_path / "sequence_ranges.txt",
        ["# name video start end (configSeqs)", "bird1_1 bird1 1 3", "bird1_2 bird1 8 11"],
    )
    sequences = {s.name: s for s in load_uav123(tmp_path)}
    assert _frame_numbers(sequences["bird1_1"]) == [1, 2, 3]
    assert _frame_numbers(sequences["bird1_2"]) == [8, 9, 10, 11]
    assert _frame_numbers(sequences["car1_2"]) == [4, 5, 6, 7]


def test_uav123_ranges_json_and_range_errors(tmp_path):
    _uav123_tree(tmp_path)
    (tmp_path / "sequence_ranges.json").write_text(
        '{"car1_1": {"video": "car1", "start": 1, "end": 4},'
        ' "car1_2": {"video": "car1", "start": 5, "end": 8}}'
    )
    with pytest.raises(InputError, match="frames 5-8 are outside video car1"):
        load_uav123(tmp_path)


def test_uavdt_sot_layout(tmp_path):
    root = tmp_path / "UAVDT"
    _write_images(root / "sequences" / "S0101", 3, prefix="img")
    _write_rows(root / "anno" / "S0101_gt.txt", _boxes(3))
    _write_images(root / "sequences" / "S0102", 2, prefix="img")
    _write_rows(root / "anno" / "S0102_gt.txt", ["NaN,NaN,NaN,NaN", "2,2,3,3"])
    # UAVDT flag order: BC CR OR SO IV OB SV LO.
    _write_rows(root / "anno" / "att" / "S0101_att.txt", ["0,0,0,1,1,0,0,0"])
    assert detect_layout(root) == "uavdt"
    sequences = {s.name: s for s in load_sequences(root)}
    assert sorted(sequences) == ["S0101", "S0102"]
    assert sequences["S0101"].attributes == {"SO", "IV"}
    assert sequences["S0101"].dataset == "UAVDT"
    assert np.isnan(sequences["S0102"].ground_truth[0]).all()
    with pytest.raises(InputError, match="first ground-truth box"):
        _ = sequences["S0102"].init_box


def test_visdrone_sot_layout(tmp_path):
    root = tmp_path / "VisDrone2018-SOT-test-dev"
    _write_images(root / "sequences" / "uav0000024_00000_s", 3, prefix="img", digits=7)
    _write_rows(root / "annotations" / "uav0000024_00000_s.txt", _boxes(3))
    # VisDrone flag order: ARC BC CM FM FOC IV LR OV POC SOB SV VC.
    _write_rows(root / "attributes" / "uav0000024_00000_s_attr.txt", ["1,0,0,0,0,0,0,0,0,0,1,0"])
    assert detect_layout(root) == "visdrone"
    (sequence,) = load_sequences(root)
    assert sequence.name == "uav0000024_00000_s" and len(sequence) == 3
    assert sequence.attributes == {"ARC", "SV"}


def test_collection_of_datasets_prefixes_only_colliding_names(tmp_path):
    for dataset, name in (("DTB70", "Car1"), ("OTB", "Car1"), ("OTB", "Dog")):
        _write_images(tmp_path / dataset / name / "img", 2)
        _write_rows(tmp_path / dataset / name / "groundtruth_rect.txt", _boxes(2))
    visdrone = tmp_path / "nested" / "VisDrone"
    _write_images(visdrone / "sequences" / "v1", 2)
    _write_rows(visdrone / "annotations" / "v1.txt", _boxes(2))
    assert detect_layout(tmp_path) == "collection"
    names = [s.name for s in load_sequences(tmp_path)]
    assert names == ["DTB70_Car1", "OTB_Car1", "Dog", "v1"]


def test_unknown_layout_is_a_clear_error(tmp_path):
    (tmp_path / "photos").mkdir()
    (tmp_path / "photos" / "a.jpg").write_bytes(b"")
    with pytest.raises(InputError, match="unknown benchmark layout"):
        detect_layout(tmp_path)
    with pytest.raises(InputError, match="no such benchmark folder"):
        load_sequences(tmp_path / "missing")


def _shared_sequence_folders() -> list[Path]:
    """Sequence folders of the shared data found straight from the file system."""
    return sorted(
        folder.parent for folder in SEQUENCES.glob("*/*/groundtruth_rect.txt") if folder.is_file()
    )


@needs_sequences
def test_shared_data_root_of_otb_style_datasets():
    assert detect_layout(SEQUENCES) == "collection"
    sequences = load_sequences(SEQUENCES)
    # Expected from the data itself: every <dataset>/<sequence>/ folder with a ground truth.
    folders = _shared_sequence_folders()
    assert len(sequences) == len(folders)
    by_name = {s.name: s for s in sequences}
    assert len(by_name) == len(sequences)  # names are unique, so none was prefixed
    assert {(s.dataset, s.name) for s in sequences} == {(f.parent.name, f.name) for f in folders}
    for folder in folders:
        sequence = by_name[folder.name]
        frames = [p for p in (folder / "img").iterdir() if p.suffix.lower() in {".jpg", ".png"}]
        rows = [line for line in (folder / "groundtruth_rect.txt").read_text().splitlines() if line]
        assert len(sequence) == len(frames) == len(rows) == len(sequence.ground_truth), folder
    # The original twelve dev sequences (the ones with a release reference) are all there.
    original = {path.stem for path in OCTAVE_REFERENCE.glob("*/*.txt")}
    assert original <= set(by_name)
    boat = by_name["boat5"]
    assert boat.dataset == "UAV123_10fps" and len(boat) == 169
    np.testing.assert_array_equal(boat.ground_truth[0], [540, 295, 188, 130])  # file: 541,296
    assert boat.frames().read(0).shape == (720, 1280, 3)


def test_nan_ground_truth_rows_of_group2_2_load_and_are_skipped_in_scoring():
    folder = shared_sequence_dir("UAV123_10fps", "group2_2")
    (sequence,) = load_sequences(folder)
    gt = sequence.ground_truth
    assert len(sequence) == len(gt) == 180
    invisible = np.isnan(gt).all(axis=1)
    # Rows 171-175 of the file (1-based) are NaN, every other row is a box.
    assert np.flatnonzero(invisible).tolist() == [170, 171, 172, 173, 174]
    assert np.isfinite(gt[~invisible]).all()
    # Scoring skips them: a prediction that is wrong only there still scores 1.0 / full overlap.
    wrong_there = gt.copy()
    wrong_there[invisible] = [0.0, 0.0, 5.0, 5.0]
    score = score_sequence("group2_2", wrong_there, gt)
    assert score.scored_frames == 175
    assert score.precision == 1.0 and score.success_curve[-2] == 1.0
    # The authors' own boxes score P@20 0.960 over the 175 annotated frames (shared README).
    official = OFFICIAL_REFERENCE / "UAV123_10fps" / "group2_2.txt"
    if official.is_file():
        authors = score_sequence("group2_2", read_boxes(official), gt)
        assert authors.precision == pytest.approx(0.960, abs=5e-4)
        assert authors.precision == pytest.approx(168 / 175)
