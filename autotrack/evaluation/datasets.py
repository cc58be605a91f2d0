"""Benchmark loaders: one per folder layout, all yielding the same `Sequence`.

Layouts (`detect_layout` tells them apart by their folders):

- ``otb-sequence``: one sequence folder, ``<seq>/img/`` + ``groundtruth_rect.txt`` (OTB, DTB70,
  the layout of ``../shared/data/sequences/<dataset>/<seq>``). OTB's two-target sequences
  (``groundtruth_rect.1.txt``, ``.2.txt``) become ``<seq>-1`` and ``<seq>-2``.
- ``otb``: a dataset folder of such sequence folders (OTB, DTB70). Optional attributes in
  ``<dataset>/att/<seq>.txt`` or ``<seq>/attributes.txt``.
- ``uav123``: ``data_seq/<variant>/<video>/`` + ``anno/<variant>/<seq>.txt`` with attributes in
  ``anno/<variant>/att/<seq>.txt`` (UAV123, UAV123_10fps, UAV20L). Sub-sequences such as
  ``bird1_2`` are frame ranges of one video, see `load_uav123`.
- ``uavdt``: ``sequences/<seq>/`` + ``anno/<seq>_gt.txt``, attributes in
  ``anno/att/<seq>_att.txt`` or ``anno/<seq>_att.txt`` (UAVDT-SOT).
- ``visdrone``: ``sequences/<seq>/`` + ``annotations/<seq>.txt``, attributes in
  ``attributes/<seq>_attr.txt`` (VisDrone-SOT).
- ``collection``: a folder of dataset folders of any of the layouts above.

Ground-truth files hold one ``x,y,w,h`` row per frame (comma, tab or space separated) in the
toolkits' 1-based pixel convention; `Sequence.ground_truth` is 0-based (x and y minus 1).
``NaN`` rows (target invisible) are kept and excluded from scoring.

Attribute files hold either attribute names (``SV, OCC``) or one row of 0/1 flags. Flags are
named by ``attribute_names.txt`` in the same folder when present, else by the column order of
the benchmark's toolkit (`ATTRIBUTE_ORDER`).
"""

from __future__ import annotations

import json
import re
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from autotrack.errors import InputError
from autotrack.io.frames import ImageSequence, list_image_files
from autotrack.io.otb_boxes import read_boxes

GROUND_TRUTH_FILE = "groundtruth_rect.txt"
SEQUENCE_RANGES_FILES = ("sequence_ranges.json", "sequence_ranges.txt")
ATTRIBUTE_NAMES_FILE = "attribute_names.txt"
MAX_COLLECTION_DEPTH = 3
"""How many levels of dataset folders `load_sequences` descends looking for a layout."""

ATTRIBUTE_ORDER: dict[str, tuple[str, ...]] = {
    # UAV123 toolkit perfPlot order (anno/<variant>/att/<seq>.txt).
    "uav123": ("SV", "ARC", "LR", "FM", "FOC", "POC", "OV", "BC", "IV", "VC", "CM", "SOB"),
    # DTB70 paper (Li & Yeung, AAAI 2017), Table 1 order.
    "dtb70": ("SV", "ARV", "OCC", "DEF", "FCM", "IPR", "OPR", "OV", "BC", "SOA", "MB"),
    # UAVDT paper (Du et al., ECCV 2018), SOT attribute order.
    "uavdt": ("BC", "CR", "OR", "SO", "IV", "OB", "SV", "LO"),
    # VisDrone-SOT toolkit (attributes/<seq>_attr.txt).
    "visdrone": ("ARC", "BC", "CM", "FM", "FOC", "IV", "LR", "OV", "POC", "SOB", "SV", "VC"),
}
"""Column order of 0/1 attribute flag files per benchmark."""

ATTRIBUTE_FULL_NAMES: dict[str, str] = {
    "ARC": "Aspect Ratio Change",
    "ARV": "Aspect Ratio Variation",
    "BC": "Background Clutter",
    "CM": "Camera Motion",
    "CR": "Camera Rotation",
    "DEF": "Deformation",
    "FCM": "Fast Camera Motion",
    "FM": "Fast Motion",
    "FOC": "Full Occlusion",
    "IPR": "In-Plane Rotation",
    "IV": "Illumination Variation",
    "LO": "Large Occlusion",
    "LR": "Low Resolution",
    "MB": "Motion Blur",
    "OB": "Object Blur",
    "OCC": "Occlusion",
    "OPR": "Out-of-Plane Rotation",
    "OR": "Object Rotation",
    "OV": "Out-of-View",
    "POC": "Partial Occlusion",
    "SO": "Small Object",
    "SOA": "Similar Objects Around",
    "SOB": "Similar Object",
    "SV": "Scale Variation",
    "VC": "Viewpoint Change",
}
"""Readable names of the attribute abbreviations, for plot titles."""

_SEPARATORS = re.compile(r"[,;\s]+")
_SUBSEQUENCE = re.compile(r"^(?P<video>.+)_(?P<part>\d+)$")


@dataclass(frozen=True, eq=False)
class Sequence:
    """One benchmark sequence: frames on disk and the ground-truth box of every frame."""

    name: str
    """Unique name in a benchmark run (file name of its results)."""
    frame_paths: tuple[Path, ...]
    """Image file of every frame, in frame order."""
    ground_truth: np.ndarray
    """(N, 4) float64 boxes x, y, w, h in 0-based pixels; NaN rows where the target is invisible."""
    attributes: frozenset[str] = frozenset()
    """Attribute abbreviations (e.g. 'SV', 'OCC') when the benchmark provides them."""
    dataset: str = ""
    """Name of the dataset folder the sequence comes from."""

    def __post_init__(self) -> None:
        frame_paths = tuple(Path(p) for p in self.frame_paths)
        boxes = np.array(self.ground_truth, dtype=np.float64)
        if boxes.ndim != 2 or boxes.shape[1] != 4:
            raise InputError(f"{self.name}: ground truth must be N x 4, got shape {boxes.shape}")
        if not frame_paths:
            raise InputError(f"{self.name}: no frames")
        if len(frame_paths) != len(boxes):
            raise InputError(
                f"{self.name}: {len(frame_paths)} frames but {len(boxes)} ground-truth rows"
            )
        boxes.setflags(write=False)
        object.__setattr__(self, "frame_paths", frame_paths)
        object.__setattr__(self, "ground_truth", boxes)
        object.__setattr__(self, "attributes", frozenset(self.attributes))

    def __len__(self) -> int:
        return len(self.frame_paths)

    @property
    def init_box(self) -> tuple[float, float, float, float]:
        """The first frame's ground-truth box (0-based), which initialises the tracker."""
        box = self.ground_truth[0]
        if not (np.all(np.isfinite(box)) and box[2] > 0 and box[3] > 0):
            raise InputError(f"{self.name}: the first ground-truth box {box.tolist()} is not valid")
        x, y, w, h = (float(v) for v in box)
        return (x, y, w, h)

    def frames(self) -> ImageSequence:
        """The frames as a FrameSource (RGB reads, errors naming the frame)."""
        return ImageSequence(self.frame_paths, self.name)


def read_attributes(path: Path, flag_order: tuple[str, ...] | None) -> frozenset[str]:
    """Attributes of one sequence from a file of names or of 0/1 flags (see module docstring)."""
    try:
        text = path.read_text(encoding="utf-8-sig")
    except OSError as error:
        raise InputError(f"cannot read attribute file {path}: {error.strerror}") from error
    tokens = [token for token in _SEPARATORS.split(text.strip()) if token]
    if not tokens or not all(token in ("0", "1") for token in tokens):
        return frozenset(tokens)
    names_file = path.parent / ATTRIBUTE_NAMES_FILE
    if names_file.is_file():
        flag_order = tuple(t for t in _SEPARATORS.split(names_file.read_text().strip()) if t)
    if flag_order is None or len(flag_order) != len(tokens):
        expected = "no known column order" if flag_order is None else f"{len(flag_order)} flags"
        raise InputError(
            f"{path}: {len(tokens)} attribute flags but {expected}; list the attribute names in "
            f"column order in {names_file}"
        )
    return frozenset(name for name, flag in zip(flag_order, tokens, strict=True) if flag == "1")


def _subfolders(folder: Path) -> list[Path]:
    """Visible sub-folders in name order (hidden ones such as .git are never datasets)."""
    return sorted(e for e in folder.iterdir() if e.is_dir() and not e.name.startswith("."))


def _is_otb_sequence(folder: Path) -> bool:
    return (folder / "img").is_dir() and any(folder.glob("groundtruth_rect*.txt"))


def _sequence_frames(folder: Path) -> list[Path]:
    image_folder = folder / "img" if (folder / "img").is_dir() else folder
    return list_image_files(image_folder) if image_folder.is_dir() else []


def _layout_or_none(folder: Path, depth: int) -> str | None:
    if _is_otb_sequence(folder):
        return "otb-sequence"
    if (folder / "data_seq").is_dir() and (folder / "anno").is_dir():
        return "uav123"
    if (folder / "sequences").is_dir() and (folder / "annotations").is_dir():
        return "visdrone"
    if (folder / "sequences").is_dir() and (folder / "anno").is_dir():
        return "uavdt"
    subfolders = _subfolders(folder)
    if any(_is_otb_sequence(sub) for sub in subfolders):
        return "otb"
    if depth < MAX_COLLECTION_DEPTH and any(
        _layout_or_none(sub, depth + 1) is not None for sub in subfolders
    ):
        return "collection"
    return None


def detect_layout(root: str | Path) -> str:
    """The layout of a folder: 'otb-sequence', 'otb', 'uav123', 'uavdt', 'visdrone' or 'collection'.

    Raises InputError naming the layouts it looked for when the folder matches none.
    """
    root = Path(root).expanduser()
    if not root.is_dir():
        raise InputError(f"no such benchmark folder: {root}")
    layout = _layout_or_none(root, 0)
    if layout is None:
        raise InputError(
            f"unknown benchmark layout in {root}: expected a sequence folder (img/ + "
            f"{GROUND_TRUTH_FILE}), a folder of such sequences (OTB, DTB70), UAV123 "
            "(data_seq/ + anno/), UAVDT-SOT (sequences/ + anno/<seq>_gt.txt), VisDrone-SOT "
            "(sequences/ + annotations/), or a folder of these datasets"
        )
    return layout


def _otb_flag_order(dataset: str) -> tuple[str, ...] | None:
    key = dataset.lower()
    if key.startswith("dtb70"):
        return ATTRIBUTE_ORDER["dtb70"]
    if key.startswith(("uav123", "uav20l")):
        return ATTRIBUTE_ORDER["uav123"]
    return None


def load_otb_sequence(folder: str | Path, dataset: str | None = None) -> list[Sequence]:
    """The sequence(s) of one OTB-style folder (two for OTB's two-target folders)."""
    folder = Path(folder).expanduser()
    if not _is_otb_sequence(folder):
        raise InputError(f"{folder} is not a sequence folder (img/ + {GROUND_TRUTH_FILE})")
    dataset = dataset if dataset is not None else folder.parent.name
    frames = list_image_files(folder / "img")
    if not frames:
        raise InputError(f"no image files in {folder / 'img'}")
    attribute_files = [folder / "attributes.txt", folder.parent / "att" / f"{folder.name}.txt"]
    attribute_file = next((path for path in attribute_files if path.is_file()), None)
    attributes = (
        read_attributes(attribute_file, _otb_flag_order(dataset)) if attribute_file else frozenset()
    )
    targets = [(folder.name, folder / GROUND_TRUTH_FILE)]
    if not targets[0][1].is_file():
        numbered = sorted(folder.glob("groundtruth_rect.*.txt"))
        targets = [(f"{folder.name}-{path.name.split('.')[1]}", path) for path in numbered]
    return [
        Sequence(name, tuple(frames), read_boxes(path), attributes, dataset)
        for name, path in targets
    ]


def load_otb_dataset(root: str | Path) -> list[Sequence]:
    """Every sequence folder directly inside an OTB-style dataset folder, sorted by name."""
    root = Path(root).expanduser()
    sequences: list[Sequence] = []
    for folder in _subfolders(root):
        if _is_otb_sequence(folder):
            sequences.extend(load_otb_sequence(folder, root.name))
    if not sequences:
        raise InputError(f"no sequence folders (img/ + {GROUND_TRUTH_FILE}) in {root}")
    return sequences


def read_sequence_ranges(root: Path) -> dict[str, tuple[str, int, int]]:
    """UAV123 sub-sequence ranges from `root/sequence_ranges.{json,txt}`, if present.

    Returns name -> (video folder, first frame, last frame), frames 1-based inclusive as in the
    UAV123 toolkit's configSeqs. The txt form has one `name video start end` line per sequence
    (`#` starts a comment); the json form maps name to {"video", "start", "end"}.
    """
    ranges: dict[str, tuple[str, int, int]] = {}
    for file_name in SEQUENCE_RANGES_FILES:
        path = root / file_name
        if not path.is_file():
            continue
        try:
            if path.suffix == ".json":
                entries = json.loads(path.read_text())
                for name, entry in entries.items():
                    ranges[name] = (str(entry["video"]), int(entry["start"]), int(entry["end"]))
            else:
                for line_number, line in enumerate(path.read_text().splitlines(), start=1):
                    fields = [f for f in _SEPARATORS.split(line.split("#")[0].strip()) if f]
                    if not fields:
                        continue
                    if len(fields) != 4:
                        raise ValueError(f"line {line_number}: expected 'name video start end'")
                    ranges[fields[0]] = (fields[1], int(fields[2]), int(fields[3]))
        except (ValueError, KeyError, TypeError, AttributeError) as error:
            raise InputError(f"{path}: malformed sequence ranges ({error})") from error
    return ranges


def _partition_ranges(
    video: str, frame_count: int, parts: list[tuple[str, int]]
) -> dict[str, tuple[int, int]]:
    """Frame ranges of sub-sequences that cover a video in order (see `load_uav123`)."""
    lengths = [length for _, length in parts]
    names = ", ".join(name for name, _ in parts)
    if sum(lengths) == frame_count:
        overlap = 0
    elif sum(lengths) - (len(parts) - 1) == frame_count:
        overlap = 1
    else:
        raise InputError(
            f"cannot infer the frame ranges of {names} in video {video} ({frame_count} frames, "
            f"{sum(lengths)} annotated rows): the sub-sequences leave gaps, so give their ranges "
            f"in sequence_ranges.txt at the benchmark root (lines 'name video start end', 1-based "
            f"inclusive, from the toolkit's configSeqs)"
        )
    ranges: dict[str, tuple[int, int]] = {}
    start = 1
    for name, length in parts:
        ranges[name] = (start, start + length - 1)
        start += length - overlap
    return ranges


def load_uav123(root: str | Path) -> list[Sequence]:
    """UAV123-layout sequences (UAV123, UAV123_10fps, UAV20L) under `root`.

    A sequence whose annotation name is a video folder uses all its frames. A sub-sequence
    (`bird1_2.txt` with video `bird1/`) takes its frame range from `root/sequence_ranges.txt`
    or `.json` when listed there (the toolkit's configSeqs start/end frames). Otherwise the
    sub-sequences of a video must cover it in order: either back to back (sum of annotation
    lengths = frames in the video) or, as UAV123's configSeqs does for car1, group1 and others,
    each starting on the previous one's last frame (sum - (parts - 1) = frames). Videos whose
    sub-sequences leave gaps (UAV123's bird1) need the ranges file; an InputError says so.
    """
    root = Path(root).expanduser()
    anno_root, video_root = root / "anno", root / "data_seq"
    variants = sorted(
        entry.name
        for entry in anno_root.iterdir()
        if entry.is_dir() and (video_root / entry.name).is_dir()
    )
    if not variants:
        raise InputError(
            f"{root}: no anno/<name>/ folder with a matching data_seq/<name>/ "
            "(e.g. anno/UAV123_10fps/ and data_seq/UAV123_10fps/)"
        )
    ranges = read_sequence_ranges(root)
    sequences: list[Sequence] = []
    for variant in variants:
        sequences.extend(_load_uav123_variant(anno_root / variant, video_root / variant, ranges))
    return sequences


def _load_uav123_variant(
    anno_dir: Path, video_dir: Path, ranges: dict[str, tuple[str, int, int]]
) -> list[Sequence]:
    dataset = anno_dir.name
    flag_order = ATTRIBUTE_ORDER["uav123"]
    boxes = {path.stem: read_boxes(path) for path in sorted(anno_dir.glob("*.txt"))}
    if not boxes:
        raise InputError(f"no annotation files in {anno_dir}")
    video_frames: dict[str, list[Path]] = {}

    def frames_of(video: str) -> list[Path]:
        if video not in video_frames:
            folder = video_dir / video
            frames = _sequence_frames(folder)
            if not frames:
                raise InputError(f"no frames for video {video}: {folder} is missing or empty")
            video_frames[video] = frames
        return video_frames[video]

    spans: dict[str, tuple[str, int, int]] = {}
    groups: dict[str, list[tuple[int, str]]] = {}
    for name in boxes:
        if name in ranges:
            spans[name] = ranges[name]
        elif (video_dir / name).is_dir():
            spans[name] = (name, 1, len(frames_of(name)))
        elif (match := _SUBSEQUENCE.match(name)) and (video_dir / match["video"]).is_dir():
            groups.setdefault(match["video"], []).append((int(match["part"]), name))
        else:
            raise InputError(f"annotation {anno_dir / name}.txt has no video folder in {video_dir}")
    for video, members in groups.items():
        parts = [(name, len(boxes[name])) for _, name in sorted(members)]
        for name, (start, end) in _partition_ranges(video, len(frames_of(video)), parts).items():
            spans[name] = (video, start, end)

    sequences = []
    for name in sorted(boxes):
        video, start, end = spans[name]
        frames = frames_of(video)
        if not 1 <= start <= end <= len(frames):
            raise InputError(
                f"{name}: frames {start}-{end} are outside video {video} ({len(frames)} frames)"
            )
        attribute_file = anno_dir / "att" / f"{name}.txt"
        attributes = (
            read_attributes(attribute_file, flag_order) if attribute_file.is_file() else frozenset()
        )
        sequences.append(
            Sequence(name, tuple(frames[start - 1 : end]), boxes[name], attributes, dataset)
        )
    return sequences


def _load_flat_layout(
    root: Path,
    annotation_files: list[Path],
    name_of: Callable[[Path], str],
    attribute_paths: Callable[[str], list[Path]],
    flag_order: tuple[str, ...],
) -> list[Sequence]:
    if not annotation_files:
        raise InputError(f"no annotation files found under {root}")
    sequences = []
    for path in annotation_files:
        name = name_of(path)
        frames = _sequence_frames(root / "sequences" / name)
        if not frames:
            raise InputError(f"{name}: no frames in {root / 'sequences' / name}")
        attribute_file = next((p for p in attribute_paths(name) if p.is_file()), None)
        attributes = read_attributes(attribute_file, flag_order) if attribute_file else frozenset()
        sequences.append(Sequence(name, tuple(frames), read_boxes(path), attributes, root.name))
    return sequences


def load_uavdt(root: str | Path) -> list[Sequence]:
    """UAVDT-SOT sequences: `sequences/<seq>/` frames + `anno/<seq>_gt.txt` boxes."""
    root = Path(root).expanduser()
    anno = root / "anno"
    return _load_flat_layout(
        root,
        sorted(anno.glob("*_gt.txt")),
        lambda path: path.name[: -len("_gt.txt")],
        lambda name: [anno / "att" / f"{name}_att.txt", anno / f"{name}_att.txt"],
        ATTRIBUTE_ORDER["uavdt"],
    )


def load_visdrone(root: str | Path) -> list[Sequence]:
    """VisDrone-SOT sequences: `sequences/<seq>/` frames + `annotations/<seq>.txt` boxes."""
    root = Path(root).expanduser()
    return _load_flat_layout(
        root,
        sorted((root / "annotations").glob("*.txt")),
        lambda path: path.stem,
        lambda name: [root / "attributes" / f"{name}_attr.txt"],
        ATTRIBUTE_ORDER["visdrone"],
    )


def _load_layout(root: Path, layout: str, depth: int) -> list[Sequence]:
    if layout == "otb-sequence":
        return load_otb_sequence(root)
    if layout == "otb":
        return load_otb_dataset(root)
    if layout == "uav123":
        return load_uav123(root)
    if layout == "uavdt":
        return load_uavdt(root)
    if layout == "visdrone":
        return load_visdrone(root)
    sequences: list[Sequence] = []
    for folder in _subfolders(root):
        sub_layout = _layout_or_none(folder, depth + 1)
        if sub_layout is not None:
            sequences.extend(_load_layout(folder, sub_layout, depth + 1))
    return sequences


def _unique_names(sequences: list[Sequence]) -> list[Sequence]:
    counts = Counter(sequence.name for sequence in sequences)
    renamed = [
        Sequence(f"{s.dataset}_{s.name}", s.frame_paths, s.ground_truth, s.attributes, s.dataset)
        if counts[s.name] > 1
        else s
        for s in sequences
    ]
    duplicates = [name for name, n in Counter(s.name for s in renamed).items() if n > 1]
    if duplicates:
        raise InputError(f"sequence names are not unique in this benchmark: {duplicates}")
    return renamed


def load_sequences(root: str | Path) -> list[Sequence]:
    """Every sequence under `root`, whatever its layout (see `detect_layout`).

    Names are unique: a name found in several datasets is prefixed with its dataset folder
    (`DTB70_Gull1`).
    """
    root = Path(root).expanduser()
    layout = detect_layout(root)
    return _unique_names(_load_layout(root, layout, 0))
