"""Replay the hybrid's fusion rule on recorded runs of its two trackers: a rule change measured on
the dev set in seconds instead of a full hybrid run.

`autotrack+` and NanoTrack run once each, on their own, on every sequence; what `fuse` reads of
them per frame (the filter's box, aberrance flag and theta; the Siamese box, aberrance flag and
foreground probabilities at its chosen cell and at both box centres) is saved under `--out`. The replay then walks `fuse`
over the frames with `HybridTracker`'s bookkeeping of the last (hybrid, filter, Siamese) boxes.

The replay is exact only where the fusion does not feed back into the trackers: with
`place_siamese` and `reinit_filter` off (both move a tracker, so its later frames differ from
its own run). It replays the default rule without re-placing, which the ablation measures as a
real run too (`hybrid without Siamese re-placing`): compare the two to see how much the
re-placing changes. Confirm a rule with a real run (`benchmarks/ablation.py --hybrid`).

    python benchmarks/hybrid_replay.py --out /tmp/hybrid_replay [--set size_weighted=False ...]
"""

from __future__ import annotations

import argparse
import math
from concurrent.futures import ProcessPoolExecutor
from dataclasses import astuple, replace
from multiprocessing import get_context
from pathlib import Path

import numpy as np

from autotrack.evaluation.datasets import load_sequences
from autotrack.evaluation.metrics import score_sequence
from autotrack.evaluation.runs import single_thread
from autotrack.hybrid import HybridParams, fuse
from autotrack.hybrid.tracker import SiameseReading, read_siamese
from autotrack.result import TrackResult

REPO = Path(__file__).resolve().parents[1]
SEQUENCES = REPO / ".." / "shared" / "data" / "sequences"
FIELDS = ("filter_box", "filter_aberrant", "filter_theta", "siamese_box", "siamese_aberrant")
READING = tuple(f"siamese_{name}" for name in SiameseReading.__dataclass_fields__)
"""The Siamese map's reading (`SiameseReading`): siamese_score, siamese_at_filter, ..."""


def record(
    sequence, params: HybridParams | None = None, frames: int | None = None
) -> dict[str, np.ndarray]:
    """Both trackers' own runs on a sequence (its first `frames`, default all), one thread: per
    frame, what `fuse` reads (FIELDS and READING, the reading NaN on the first frame)."""
    from autotrack import AutoTrack
    from autotrack.nanotrack import NanoTrack

    params = params or HybridParams()
    filter_tracker, siamese = AutoTrack(params.filter_params), NanoTrack(params.siamese_params)
    rows: dict[str, list] = {name: [] for name in (*FIELDS, *READING)}
    with sequence.frames() as source, single_thread():
        for index in range(len(sequence) if frames is None else min(frames, len(sequence))):
            frame = source.read(index)
            if index == 0:
                own = filter_tracker.init(frame, sequence.init_box)
                siamese_result = siamese.init(frame, sequence.init_box)
                reading = SiameseReading(math.nan, math.nan, math.nan)
            else:
                own, siamese_result = filter_tracker.update(frame), siamese.update(frame)
                reading = read_siamese(siamese_result, siamese.peak_cell, own.box)
            for name, value in zip(
                FIELDS,
                (own.box, own.aberrant, own.theta, siamese_result.box, siamese_result.aberrant),
                strict=True,
            ):
                rows[name].append(value)
            for name, value in zip(READING, astuple(reading), strict=True):
                rows[name].append(value)
    return {name: np.asarray(values, dtype=np.float64) for name, values in rows.items()}


def _evidence(box, aberrant, theta=math.nan) -> TrackResult:
    """A `TrackResult` carrying what `fuse` reads of one tracker's frame."""
    return TrackResult(
        frame_index=0,
        box=tuple(float(v) for v in box),
        peak_score=math.nan,
        response_map=None,
        local_variation=None,
        global_variation=math.nan,
        theta_ref=math.nan,
        theta=float(theta),
        aberrant=bool(aberrant),
        scale_factor=1.0,
        search_box=(0.0, 0.0, 1.0, 1.0),
    )


def replay(recorded: dict[str, np.ndarray], params: HybridParams) -> tuple[np.ndarray, list[str]]:
    """The hybrid's boxes and trusted tracker per frame, `fuse` walked over a recorded run (exact
    with `place_siamese` and `reinit_filter` off: module docstring)."""
    from autotrack.hybrid.tracker import BOTH

    box = filter_box = tuple(recorded["filter_box"][0])
    siamese_box = tuple(recorded["siamese_box"][0])
    boxes, trusted = [box], [BOTH]
    for index in range(1, len(recorded["filter_box"])):
        own = _evidence(
            recorded["filter_box"][index],
            recorded["filter_aberrant"][index],
            recorded["filter_theta"][index],
        )
        siamese = _evidence(recorded["siamese_box"][index], recorded["siamese_aberrant"][index])
        reading = SiameseReading(*(float(recorded[name][index]) for name in READING))
        decision = fuse(own, siamese, reading, (box, filter_box, siamese_box), params)
        box, filter_box, siamese_box = tuple(float(v) for v in decision.box), own.box, siamese.box
        boxes.append(box)
        trusted.append(decision.trusted)
    return np.asarray(boxes), trusted


def _record_cached(arguments: tuple[Path, object]) -> Path:
    out, sequence = arguments
    path = out / f"{sequence.dataset}__{sequence.name}.npz"
    if not path.is_file():
        np.savez(path, **record(sequence))
    return path


def _value(text: str):
    for kind in (int, float):
        try:
            return kind(text)
        except ValueError:
            pass
    if text in ("True", "False"):
        return text == "True"
    raise SystemExit(f"--set: {text!r} is not a number, True or False")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--root", type=Path, default=SEQUENCES)
    parser.add_argument("--out", type=Path, required=True, help="folder of the recorded runs")
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument(
        "--set", action="append", default=[], metavar="NAME=VALUE", help="a HybridParams field"
    )
    args = parser.parse_args()
    overrides = {}
    for item in args.set:
        name, _, text = item.partition("=")
        if name not in HybridParams.__dataclass_fields__:
            raise SystemExit(f"--set: HybridParams has no field {name!r}")
        overrides[name] = _value(text)
    params = replace(HybridParams(), place_siamese=False, reinit_filter=False, **overrides)
    sequences = load_sequences(args.root)
    args.out.mkdir(parents=True, exist_ok=True)
    with ProcessPoolExecutor(max(args.jobs, 1), mp_context=get_context("spawn")) as pool:
        paths = list(pool.map(_record_cached, [(args.out, s) for s in sequences]))
    scores = []
    for sequence, path in zip(sequences, paths, strict=True):
        boxes, _ = replay(dict(np.load(path)), params)
        scores.append(score_sequence(sequence.name, boxes, sequence.ground_truth))
        print(
            f"{sequence.dataset}/{sequence.name}: {scores[-1].precision:.3f} {scores[-1].auc:.3f}"
        )
    precision = float(np.mean([s.precision for s in scores]))
    auc = float(np.mean([s.auc for s in scores]))
    print(
        f"replayed hybrid ({', '.join(args.set) or 'defaults'}, no re-placing): "
        f"P@20 {precision:.3f} AUC {auc:.3f}"
    )


if __name__ == "__main__":
    main()
