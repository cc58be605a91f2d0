"""NanoTrack and the hybrid tracker in the dev-set ablation (`python benchmarks/ablation.py
--hybrid`): the hybrid's variants (each fusion switch, each parameter halved and doubled), how
they are made, their table, and frames/s on one thread on 1280x720 frames."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np

from autotrack.evaluation.runs import single_thread

FAITHFUL = "autotrack"
"""The faithful preset's name (both tables compare with it)."""
PLUS = "autotrack+"
"""The `autotrack+` preset's name, the hybrid's correlation filter."""

NANOTRACK = "nanotrack"
HYBRID = "hybrid"
HYBRID_VARIANTS: dict[str, dict] = {
    HYBRID: {},
    f"{HYBRID} without box averaging": {"average_boxes": False},
    f"{HYBRID} without size weighting": {"size_weighted": False},
    f"{HYBRID} without likelihood weighting": {"likelihood_weighted": False},
    f"{HYBRID} with filter re-initialisation": {"reinit_filter": True},
    f"{HYBRID} without Siamese re-placing": {"place_siamese": False},
    f"{HYBRID} without continuity": {"continuity": False},
    f"{HYBRID} without cross-verification": {"cross_check": False},
}
"""The hybrid tracker and each of its fusion switches off (`autotrack.hybrid.HybridParams`)."""
HYBRID_SENSITIVE = ("agree_radius", "siamese_confident", "siamese_corroborates")
"""The hybrid's numeric parameters, halved and doubled in the sensitivity rows."""


def hybrid_variants(sensitivity: bool) -> dict[str, dict]:
    """Hybrid label -> `HybridParams` overrides: the switches, then the sensitivity rows."""
    from autotrack.hybrid import HybridParams

    table = dict(HYBRID_VARIANTS)
    if sensitivity:
        for name in HYBRID_SENSITIVE:
            value = getattr(HybridParams(), name)
            for factor in (0.5, 2.0):
                table[f"{HYBRID} {name} x{factor:g}"] = {name: value * factor}
    return table


def new_box_tracker(kind: str, overrides: dict):
    """NanoTrack, or the hybrid with `HybridParams` overrides, returning boxes."""
    from autotrack.hybrid import HybridParams, HybridTracker
    from autotrack.hybrid.factory import BoxesOf
    from autotrack.nanotrack import NanoTrack

    if kind == NANOTRACK:
        return BoxesOf(NanoTrack())
    return BoxesOf(HybridTracker(replace(HybridParams(), **overrides)))


def mean_scores(scores: dict, names) -> tuple[float, float]:
    """Mean P@20 and AUC of one tracker's {sequence: SequenceScore}."""
    return (
        float(np.mean([scores[n].precision for n in names])),
        float(np.mean([scores[n].auc for n in names])),
    )


def halved_doubled_cells(
    scores: dict, names, tracker: str, parameter: str, base: tuple[float, float]
) -> list[str]:
    """The sensitivity table's two cells of one parameter of `tracker` ('{tracker} {parameter}
    x0.5' and 'x2' labels): mean P@20 / AUC and their change from `base`, or 'not run'."""
    cells = []
    for factor in (0.5, 2.0):
        label = f"{tracker} {parameter} x{factor:g}"
        if label not in scores:
            cells.append("not run")
            continue
        p, a = mean_scores(scores[label], names)
        cells.append(f"{p:.3f} / {a:.3f} ({p - base[0]:+.3f} / {a - base[1]:+.3f})")
    return cells


def _hybrid_row(label: str, scores: dict, names: list[str], fps: dict) -> str:
    p, a = mean_scores(scores[label], names)
    nano = scores[NANOTRACK]
    worse = [n for n in names if scores[label][n].auc < nano[n].auc - 0.05]
    return f"| {label} | {p:.3f} | {a:.3f} | {len(worse)} {' '.join(worse)} | {fps[label]:.1f} |"


def _labels(scores: dict) -> list[str]:
    return [
        label for label in (FAITHFUL, PLUS, "csrt", NANOTRACK, *HYBRID_VARIANTS) if label in scores
    ]


def hybrid_summary(sequences, scores: dict, fps: dict) -> list[str]:
    """The means table (docs/benchmarks.md's NanoTrack and hybrid rows): each tracker's mean
    P@20 / AUC and the sequences where it is worse than NanoTrack by more than 0.05 AUC."""
    names = [s.name for s in sequences]
    labels = _labels(scores)
    return [
        f"{len(sequences)} sequences, {sum(len(s) for s in sequences)} frames, one thread per "
        "tracker process. *worse than NanoTrack*: sequences whose AUC is below NanoTrack's by "
        "more than 0.05.",
        "",
        "| tracker | P@20 | AUC | worse than NanoTrack | fps (median) |",
        "|---|---|---|---|---|",
        *(_hybrid_row(label, scores, names, fps) for label in labels),
    ]


def build_hybrid_table(sequences, scores: dict, fps: dict) -> str:
    """The hybrid's table from {label: {sequence: SequenceScore}} and {label: median frames/s}:
    `hybrid_summary`, each tracker's per-sequence AUC, the sensitivity rows."""
    names = [s.name for s in sequences]
    labels = _labels(scores)
    lines = [
        *hybrid_summary(sequences, scores, fps),
        "",
        "Per sequence, AUC:",
        "",
        "| sequence | " + " | ".join(labels) + " |",
        "|---|" + "---|" * len(labels),
    ]
    for sequence in sequences:
        cells = [f"{scores[label][sequence.name].auc:.3f}" for label in labels]
        lines.append(f"| {sequence.dataset}/{sequence.name} | " + " | ".join(cells) + " |")
    sensitivity = [label for label in scores if label.startswith(f"{HYBRID} ") and " x" in label]
    if sensitivity:
        base_p, base_a = mean_scores(scores[HYBRID], names)
        lines += [
            "",
            "Sensitivity of the hybrid: mean P@20 / AUC with one parameter halved or doubled.",
            "",
            "| parameter | x0.5 | x2 |",
            "|---|---|---|",
        ]
        for name in HYBRID_SENSITIVE:
            cells = halved_doubled_cells(scores, names, HYBRID, name, (base_p, base_a))
            lines.append(f"| `{name}` | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def replace_marked(path: Path, text: str, marker: str = "hybrid") -> None:
    """Replace the text between `<!-- {marker}:start -->` and `<!-- {marker}:end -->` in a doc."""
    start, end = f"<!-- {marker}:start -->", f"<!-- {marker}:end -->"
    document = path.read_text()
    head, rest = document.split(start, 1)
    path.write_text(head + start + "\n" + text + "\n" + end + rest.split(end, 1)[1])


def speed_1280x720(sequence, frames: int = 120, rounds: int = 2) -> str:
    """Frames/s on one thread of NanoTrack, `autotrack+` and the hybrid on a sequence's frames
    resized to 1280x720 (the box scaled alike), the three interleaved `rounds` times; the best
    round's median frame time of each."""
    import time

    import cv2

    from autotrack import AutoTrack, preset
    from autotrack.hybrid import HybridTracker
    from autotrack.nanotrack import NanoTrack

    count = min(frames, len(sequence))
    with sequence.frames() as source:
        first = source.read(0)
        images = [cv2.resize(source.read(i), (1280, 720)) for i in range(count)]
    sx, sy = 1280 / first.shape[1], 720 / first.shape[0]
    x, y, w, h = sequence.init_box
    box = (x * sx, y * sy, w * sx, h * sy)
    makers = {
        NANOTRACK: NanoTrack,
        PLUS: lambda: AutoTrack(preset(PLUS)),
        HYBRID: HybridTracker,
    }
    best = dict.fromkeys(makers, 0.0)
    with single_thread():
        for _ in range(rounds):
            for name, make in makers.items():
                tracker = make()
                tracker.init(images[0], box)
                times = []
                for image in images[1:]:
                    start = time.perf_counter()
                    tracker.update(image)
                    times.append(time.perf_counter() - start)
                best[name] = max(best[name], 1.0 / float(np.median(times)))
    cells = ", ".join(f"{name} {fps:.1f}" for name, fps in best.items())
    return f"1280x720, one thread, {sequence.name} ({count} frames): frames/s {cells}"
