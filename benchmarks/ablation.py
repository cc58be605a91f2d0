"""The `autotrack+` ablation (like the paper's Table 2) and its parameter sensitivity, on the dev set;
NanoTrack and the hybrid tracker with each of its fusion switches (`--hybrid`).

Runs every variant below on every sequence of ../shared/data/sequences (resumable: boxes already in
--out are reused; delete a variant's folder after changing the tracker), scores them with the
one-pass metrics, and prints three tables: the mean P@20 / AUC of each change alone and of all
together against the faithful preset, OpenCV CSRT and the authors' own outputs; the per-sequence
P@20 / AUC; and how the `autotrack+` mean moves when each new parameter is halved and doubled.

    python benchmarks/ablation.py --jobs 2 [--update-doc] [--no-sensitivity]
    python benchmarks/ablation.py --hybrid [--no-sensitivity] [--speed] [--update-doc] --out DIR

With `--hybrid` only the faithful preset, `autotrack+`, CSRT, NanoTrack and the hybrid variants run,
and the table compares them: mean P@20 / AUC, per-sequence AUC, the sequences where a variant is
worse than NanoTrack by more than 0.05 AUC, frames/s on one thread; `--speed` adds frames/s of
NanoTrack, `autotrack+` and the hybrid on one thread on frames resized to 1280x720;
`--update-doc` rewrites the table in docs/hybrid.md and its means in docs/benchmarks.md.
"""

from __future__ import annotations

import argparse
import json
import os
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import replace
from multiprocessing import get_context
from pathlib import Path

import numpy as np
from hybrid_ablation import (
    FAITHFUL,
    HYBRID,
    HYBRID_VARIANTS,
    NANOTRACK,
    PLUS,
    build_hybrid_table,
    halved_doubled_cells,
    hybrid_summary,
    hybrid_variants,
    mean_scores,
    new_box_tracker,
    replace_marked,
    speed_1280x720,
)

from autotrack.evaluation.benchmark import run_task
from autotrack.evaluation.datasets import load_sequences
from autotrack.evaluation.metrics import score_sequence
from autotrack.evaluation.peers import AutoTrackPeer
from autotrack.evaluation.runs import SINGLE_THREAD_ENVIRONMENT, track_timed
from autotrack.io.otb_boxes import read_boxes, write_boxes
from autotrack.params import PRESETS

REPO = Path(__file__).resolve().parents[1]
SHARED = REPO / ".." / "shared" / "data"
OFFICIAL = SHARED / "reference" / "autotrack_official"
DOC = REPO / "docs" / "benchmarks.md"
HYBRID_DOC = REPO / "docs" / "hybrid.md"


ABLATION: dict[str, dict] = {
    FAITHFUL: {},
    "+ robust variation": {"robust_variation": True},
    "+ robust variation + acting ASR": {"robust_variation": True, "acting_asr": True},
    "+ confidence gate": {"confidence_gate": PRESETS[PLUS].confidence_gate},
    "+ gate + re-detection": {
        "confidence_gate": PRESETS[PLUS].confidence_gate,
        "redetect_span": PRESETS[PLUS].redetect_span,
    },
    "+ thin-target scale model": {"scale_model_min_side": PRESETS[PLUS].scale_model_min_side},
    "+ aspect filter": {"num_aspects": 17},
    "+ velocity prediction": {"velocity_weight": 1.0},
    "+ long-term memory": {"memory_rate": PRESETS[PLUS].memory_rate},
    "+ in-plane rotation": {"rotation_step": PRESETS[PLUS].rotation_step},
}
"""Each change of `autotrack+` on its own on top of the faithful preset (the acting ASR needs the
bounded variation, re-detection needs the gate), as Table 2 adds ASR and ATR to STRCF."""

SENSITIVE = (
    "confidence_gate",
    "redetect_span",
    "confidence_memory",
    "delta",
    "variation_floor",
    "scale_model_min_side",
    "memory_rate",
    "distractor_ratio",
    "rotation_step",
    "rotation_margin",
    "redetect_patience",
    "memory_margin",
    "lookalike_reach",
)
"""The parameters `autotrack+` uses or adds (delta is the release's, but it acts only here)."""

CANDIDATES: dict[str, dict] = {
    f"{PLUS} + aspect filter": ABLATION["+ aspect filter"],
    f"{PLUS} + velocity prediction": ABLATION["+ velocity prediction"],
    f"{PLUS} + motion prior": {"motion_prior": 0.5},
    f"{PLUS} + relative ASR": {"asr_relative": True},
}
"""Switches measured on top of `autotrack+` but left out of the preset (docs/benchmarks.md);
their parameters' sensitivity is taken around these variants."""


def kind_of(label: str) -> str:
    """Which tracker a label runs: 'csrt', 'nanotrack', 'hybrid' or 'autotrack'."""
    if label in ("csrt", NANOTRACK):
        return label
    return HYBRID if label.startswith(HYBRID) else "autotrack"


def folder_of(label: str, overrides: dict) -> str:
    """Folder name of a label's results."""
    kind = kind_of(label)
    if kind == HYBRID:
        return HYBRID + "".join(f"__{k}={overrides[k]}" for k in sorted(overrides))
    return kind if kind in ("csrt", NANOTRACK) else slug(overrides)


def plus_overrides() -> dict:
    """`autotrack+` as overrides of the faithful preset."""
    plus, faithful = PRESETS[PLUS], PRESETS[FAITHFUL]
    return {
        name: getattr(plus, name)
        for name in plus.__dataclass_fields__
        if getattr(plus, name) != getattr(faithful, name)
    }


WITHOUT_ASR = f"{PLUS} without acting ASR"
"""Leave-one-out of the change whose effect on the mean is smallest and least certain."""
WITHOUT_MEMORY = f"{PLUS} without long-term memory"
"""Leave-one-out of the long-term memory (adopted in round 4)."""
WITHOUT_VARIATION = f"{PLUS} without robust variation and acting ASR"
"""Leave-one-out of the two changes to the release's regularisation (the acting ASR needs the
bounded variation): the gate, re-detection and the scale model on the release's ASR and ATR."""

WITHOUT_ROTATION = f"{PLUS} without rotation"
"""Leave-one-out of the newest change: `autotrack+` as it was before rotation was adopted."""

LEAVE_OUTS = (WITHOUT_ASR, WITHOUT_MEMORY, WITHOUT_VARIATION, WITHOUT_ROTATION)


def variants(sensitivity: bool) -> dict[str, dict]:
    """Variant label -> parameter overrides of the faithful preset."""
    table = dict(ABLATION)
    table[PLUS] = plus_overrides()
    table[WITHOUT_ASR] = {**plus_overrides(), "acting_asr": False}
    table[WITHOUT_MEMORY] = {**plus_overrides(), "memory_rate": 0.0}
    table[WITHOUT_VARIATION] = {**plus_overrides(), "acting_asr": False, "robust_variation": False}
    table[WITHOUT_ROTATION] = {**plus_overrides(), "rotation_step": 0.0}
    for label, extra in CANDIDATES.items():
        table[label] = {**plus_overrides(), **extra}
    if sensitivity:
        for base, name, value in sensitivity_bases():
            for factor in (0.5, 2.0):
                changed = type(value)(value * factor)  # an int parameter stays an int
                table[f"{PLUS} {name} x{factor:g}"] = {**table[base], name: changed}
    return table


def sensitivity_bases() -> list[tuple[str, str, float]]:
    """(variant perturbed, parameter, its value there) for every sensitivity row."""
    rows = [(PLUS, name, getattr(PRESETS[PLUS], name)) for name in SENSITIVE]
    for label, extra in CANDIDATES.items():
        # A bool switch has no value to halve: its sensitivity is that of the values it uses.
        rows += [
            (label, name, value) for name, value in extra.items() if not isinstance(value, bool)
        ]
    return rows


def slug(overrides: dict) -> str:
    """Folder name of a variant's results: its overrides, sorted."""
    if not overrides:
        return FAITHFUL
    return "__".join(f"{k}={overrides[k]}" for k in sorted(overrides))


def track(overrides: dict, sequence) -> tuple[np.ndarray, np.ndarray]:
    """Boxes (0-based x, y, w, h) and per-frame tracking seconds of one variant on one sequence."""
    params = replace(PRESETS[FAITHFUL], **overrides)
    result = track_timed(slug(overrides), lambda: AutoTrackPeer(params), sequence)
    return result.boxes, result.times


def _task(kind: str, overrides: dict, sequence):
    if kind == "csrt":
        result = run_task("csrt", sequence)
        return result.boxes, result.times
    if kind in (NANOTRACK, HYBRID):
        result = track_timed(kind, lambda: new_box_tracker(kind, overrides), sequence)
        return result.boxes, result.times
    return track(overrides, sequence)


def _paths(out: Path, folder: str, sequence) -> tuple[Path, Path]:
    base = out / folder / f"{sequence.dataset}__{sequence.name}"
    return base.with_suffix(".txt"), base.with_suffix(".time.json")


def run_all(
    sequences, table: dict[str, dict], out: Path, jobs: int, resume_only: bool = False
) -> dict:
    """{label: {sequence name: (boxes, times)}} for every variant and CSRT, resuming from `out`.

    With `resume_only`, nothing is run: variants missing any sequence are left out.
    """
    folders = {label: folder_of(label, overrides) for label, overrides in table.items()}
    folders.setdefault("csrt", "csrt")
    results: dict[str, dict] = {label: {} for label in folders}
    todo = []
    for label, folder in folders.items():
        for sequence in sequences:
            boxes_path, time_path = _paths(out, folder, sequence)
            if boxes_path.is_file() and time_path.is_file():
                boxes = read_boxes(boxes_path)
                times = np.array(json.loads(time_path.read_text()))
                if len(boxes) == len(sequence):
                    results[label][sequence.name] = (boxes, times)
                    continue
            todo.append((label, folder, sequence))
    if resume_only:
        return {k: v for k, v in results.items() if len(v) == len(sequences)}
    # The faithful preset and autotrack+ first, then the ablation rows, CSRT, and the
    # sensitivity runs; within a variant the longest sequences first (balances the pool).
    priority = [FAITHFUL, PLUS, NANOTRACK, *HYBRID_VARIANTS, *ABLATION, *LEAVE_OUTS, *CANDIDATES]
    priority.append("csrt")
    priority += list(folders)
    todo.sort(key=lambda item: (priority.index(item[0]), -len(item[2])))
    os.environ.update(SINGLE_THREAD_ENVIRONMENT)
    # Spawned workers read the one-thread environment when they import numba; forked ones keep
    # the parent's thread count and fail when a kernel is compiled (a cold numba cache).
    with ProcessPoolExecutor(max_workers=max(jobs, 1), mp_context=get_context("spawn")) as pool:
        futures = {
            pool.submit(_task, kind_of(label), table.get(label, {}), sequence): (
                label,
                folder,
                sequence,
            )
            for label, folder, sequence in todo
        }
        for count, future in enumerate(as_completed(futures), 1):
            label, folder, sequence = futures[future]
            boxes, times = future.result()
            boxes_path, time_path = _paths(out, folder, sequence)
            boxes_path.parent.mkdir(parents=True, exist_ok=True)
            write_boxes(boxes_path, boxes)  # 1-based in the file, as toolkits read it
            time_path.write_text(json.dumps([round(float(t), 6) for t in times]))
            results[label][sequence.name] = (boxes, times)
            print(f"[{count}/{len(todo)}] {label} {sequence.name}", flush=True)
    return results


def _scores(sequences, runs: dict) -> dict:
    return {s.name: score_sequence(s.name, runs[s.name][0], s.ground_truth) for s in sequences}


def _official(sequences) -> dict:
    scores = {}
    for sequence in sequences:
        path = OFFICIAL / sequence.dataset / f"{sequence.name}.txt"
        if path.is_file():
            boxes = read_boxes(path)[: len(sequence)]
            scores[sequence.name] = score_sequence(sequence.name, boxes, sequence.ground_truth)
    return scores


def _fps(runs: dict) -> float:
    return float(np.median([len(times) / np.sum(times) for _, times in runs.values()]))


def build_tables(sequences, results: dict, table: dict[str, dict]) -> str:
    names = [s.name for s in sequences]
    scores = {label: _scores(sequences, runs) for label, runs in results.items()}
    official = _official(sequences)
    faithful = scores[FAITHFUL]
    lines = [
        f"{len(sequences)} sequences, {sum(len(s) for s in sequences)} frames, default colour "
        "feature (lab11), one thread per tracker process, two processes. *worse on*: sequences "
        "whose AUC is below the faithful preset's by more than 0.01 (by any amount).",
        "",
        "| variant | P@20 | AUC | ΔP@20 | ΔAUC | worse on | fps (median) |",
        "|---|---|---|---|---|---|---|",
    ]
    base_p, base_auc = mean_scores(faithful, names)
    order = [*ABLATION, PLUS, *LEAVE_OUTS, *CANDIDATES, "csrt"]
    labels = [label for label in order if label in results]
    for label in labels:
        p, a = mean_scores(scores[label], names)
        worse = sum(scores[label][n].auc < faithful[n].auc - 0.01 for n in names)
        strict = sum(scores[label][n].auc < faithful[n].auc for n in names)
        name = "OpenCV CSRT" if label == "csrt" else label
        lines.append(
            f"| {name} | {p:.3f} | {a:.3f} | {p - base_p:+.3f} | {a - base_auc:+.3f} | "
            f"{worse} ({strict}) | {_fps(results[label]):.1f} |"
        )
    with_official = [n for n in names if n in official]
    op, oa = mean_scores(official, with_official)
    fp, fa = mean_scores(faithful, with_official)
    pp, pa = mean_scores(scores[PLUS], with_official)
    lines += [
        "",
        f"On the {len(with_official)} sequences with the authors' own outputs: official "
        f"{op:.3f} / {oa:.3f}, faithful preset {fp:.3f} / {fa:.3f}, {PLUS} {pp:.3f} / {pa:.3f} "
        "(P@20 / AUC).",
        "",
        "Per sequence, P@20 / AUC:",
        "",
    ]
    columns = [label for label in labels if label != "csrt"]
    short = dict(
        zip(
            [*ABLATION, PLUS, *LEAVE_OUTS, *CANDIDATES],
            [
                *("faithful", "+RV", "+RV+ASR", "+gate", "+gate+redet", "+scale", "+aspect"),
                *("+velocity", "+memory", "+rotation", PLUS, "+ no ASR", "+ no memory"),
                *("+ no RV/ASR", "+ no rotation", "+ + aspect", "+ + velocity"),
                *("+ + motion prior", "+ + rel. ASR"),
            ],
            strict=True,
        )
    )
    header = [short.get(c, c) for c in columns]
    lines.append("| sequence | " + " | ".join(header) + " | official | CSRT |")
    lines.append("|---|" + "---|" * (len(columns) + 2))
    for sequence in sequences:
        n = sequence.name
        cells = [f"{scores[c][n].precision:.3f} / {scores[c][n].auc:.3f}" for c in columns]
        cells.append(
            f"{official[n].precision:.3f} / {official[n].auc:.3f}" if n in official else "-"
        )
        cells.append(f"{scores['csrt'][n].precision:.3f} / {scores['csrt'][n].auc:.3f}")
        lines.append(f"| {sequence.dataset}/{n} | " + " | ".join(cells) + " |")
    lines += _sensitivity_lines(results, scores, names)
    return "\n".join(lines)


def _sensitivity_lines(results: dict, scores: dict, names: list[str]) -> list[str]:
    """The sensitivity table: each parameter halved and doubled around its variant."""
    lines: list[str] = []
    sensitivity = [label for label in results if label.startswith(f"{PLUS} ") and " x" in label]
    if sensitivity:
        lines += [
            "",
            "Sensitivity: mean P@20 / AUC of a variant with one parameter halved or doubled "
            "(an integer rounded down), and the change from the variant.",
            "",
            "| variant | parameter | value | mean there | x0.5 | x2 |",
            "|---|---|---|---|---|---|",
        ]
        for base, name, value in sensitivity_bases():
            if base not in scores:
                continue
            base_p, base_a = mean_scores(scores[base], names)
            cells = halved_doubled_cells(scores, names, PLUS, name, (base_p, base_a))
            lines.append(
                f"| {base} | `{name}` | {value:g} | {base_p:.3f} / {base_a:.3f} | "
                + " | ".join(cells)
                + " |"
            )
    return lines


def update_doc(tables: str) -> None:
    """Replace the ablation section of docs/benchmarks.md (between its markers)."""
    replace_marked(DOC, tables, "ablation")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--root", type=Path, default=SHARED / "sequences")
    parser.add_argument("--out", type=Path, default=REPO / "results" / "ablation")
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--no-sensitivity", action="store_true", help="ablation only")
    parser.add_argument(
        "--resume-only", action="store_true", help="tabulate what is saved, run nothing"
    )
    parser.add_argument("--only", default=None, help="comma-separated labels: run just these")
    parser.add_argument(
        "--update-doc",
        action="store_true",
        help="rewrite the tables in the docs (with --hybrid: docs/hybrid.md and docs/benchmarks.md)",
    )
    parser.add_argument("--hybrid", action="store_true", help="NanoTrack and the hybrid table")
    parser.add_argument("--speed", action="store_true", help="with --hybrid: fps on 1280x720")
    args = parser.parse_args()
    sequences = load_sequences(args.root)
    if args.hybrid:
        hybrid_table = {FAITHFUL: {}, PLUS: plus_overrides(), NANOTRACK: {}}
        hybrid_table.update(hybrid_variants(sensitivity=not args.no_sensitivity))
        if args.only:
            hybrid_table = {k: v for k, v in hybrid_table.items() if k in args.only.split(",")}
        results = run_all(sequences, hybrid_table, args.out, args.jobs, args.resume_only)
        scores = {label: _scores(sequences, runs) for label, runs in results.items()}
        fps = {label: _fps(runs) for label, runs in results.items()}
        table = build_hybrid_table(sequences, scores, fps)
        print(table)
        if args.speed:
            print(speed_1280x720(next(s for s in sequences if s.name == "S1301")))
        if args.update_doc:
            replace_marked(HYBRID_DOC, table)
            replace_marked(DOC, "\n".join(hybrid_summary(sequences, scores, fps)))
            print(f"updated {HYBRID_DOC} and {DOC}")
        return
    table = variants(sensitivity=not args.no_sensitivity)
    if args.only:
        wanted = args.only.split(",")
        run_all(sequences, {k: v for k, v in table.items() if k in wanted}, args.out, args.jobs)
        return
    results = run_all(sequences, table, args.out, args.jobs, args.resume_only)
    tables = build_tables(sequences, results, table)
    print(tables)
    if args.update_doc:
        update_doc(tables)
        print(f"updated {DOC}")


if __name__ == "__main__":
    main()
