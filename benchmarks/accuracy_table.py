"""Accuracy and speed of every tracker on ../shared/data/sequences, as a Markdown table.

Runs `autotrack bench` (resumable: results already in --out are reused), writes the JSON summary
and the plots, prints the tables, and with --update-doc rewrites the results section of
docs/benchmarks.md. The MATLAB release's own boxes (run under Octave, in
../shared/data/reference/autotrack_release_octave) are scored alongside as a reference row.

    python benchmarks/accuracy_table.py --jobs 2 --update-doc
    python benchmarks/accuracy_table.py --color-names ../shared/data/color_names/cn_norm_32768x10.npy
"""

from __future__ import annotations

import argparse
import json
import os
import platform
from pathlib import Path

from autotrack.evaluation.benchmark import (
    run_benchmark,
    summarize_run,
    summary_json,
    write_run_plots,
)
from autotrack.evaluation.datasets import load_sequences
from autotrack.evaluation.metrics import SequenceScore, score_sequence, summarize
from autotrack.evaluation.peers import TRACKER_NAMES
from autotrack.io.otb_boxes import read_boxes

REPO = Path(__file__).resolve().parents[1]
SHARED = REPO / ".." / "shared" / "data"
REFERENCE = SHARED / "reference" / "autotrack_release_octave"
DOC = REPO / "docs" / "benchmarks.md"
START, END = "<!-- results:start -->", "<!-- results:end -->"
REFERENCE_LABEL = "AutoTrack MATLAB release (Octave, reference)"


def _cpu_name() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def _reference_scores(sequences) -> list[SequenceScore] | None:
    scores = []
    for sequence in sequences:
        path = REFERENCE / sequence.dataset / f"{sequence.name}.txt"
        if not path.is_file():
            return None
        scores.append(score_sequence(sequence.name, read_boxes(path), sequence.ground_truth))
    return scores


def build_tables(sequences, summaries, reference: list[SequenceScore] | None, command: str) -> str:
    lines = [
        f"Measured with `{command}` on {len(sequences)} sequences "
        f"({sum(len(s) for s in sequences)} frames); {_cpu_name()}, {os.cpu_count()} cores, "
        "one thread per tracker process. fps counts tracking time only (no decoding).",
        "",
        "| tracker | colour feature | P@20 | AUC | fps (median) | fps (all frames) |",
        "|---|---|---|---|---|---|",
    ]
    for name, summary in summaries.items():
        lines.append(
            f"| {name} | {summary.colour_feature or '-'} | {summary.overall.precision:.3f} | "
            f"{summary.overall.auc:.3f} | {summary.fps_median:.1f} | {summary.fps_overall:.1f} |"
        )
    if reference is not None:
        overall = summarize(reference)
        lines.append(
            f"| {REFERENCE_LABEL} | Color Names table | {overall.precision:.3f} | "
            f"{overall.auc:.3f} | - | - |"
        )
    names = list(summaries)
    header = " | ".join(names) + (" | MATLAB release" if reference is not None else "")
    lines += [
        "",
        "Per sequence, P@20 / AUC:",
        "",
        f"| sequence | {header} |",
        "|---|" + "---|" * (len(names) + (reference is not None)),
    ]
    for index, sequence in enumerate(sequences):
        cells = [
            f"{summaries[n].sequences[sequence.name].precision:.3f} / "
            f"{summaries[n].sequences[sequence.name].auc:.3f}"
            for n in names
        ]
        if reference is not None:
            cells.append(f"{reference[index].precision:.3f} / {reference[index].auc:.3f}")
        lines.append(f"| {sequence.dataset}/{sequence.name} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def update_doc(tables: str, colour_table: bool) -> None:
    """Rewrite this colour feature's results section of docs/benchmarks.md (or append it)."""
    key = "table" if colour_table else "default"
    start, end = (
        START.replace("results", f"results:{key}"),
        END.replace("results", f"results:{key}"),
    )
    title = "published Color Names table" if colour_table else "default colour feature (lab11)"
    text = DOC.read_text()
    section = f"{start}\n{tables}\n{end}"
    if start in text and end in text:
        head, rest = text.split(start, 1)
        text = head + section + rest.split(end, 1)[1]
    else:
        heading = f"## Results on ../shared/data/sequences: {title}"
        text = text.rstrip("\n") + f"\n\n{heading}\n\n" + section + "\n"
    DOC.write_text(text)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--root", type=Path, default=SHARED / "sequences")
    parser.add_argument("--trackers", default=",".join(TRACKER_NAMES))
    parser.add_argument("--out", type=Path, default=REPO / "results" / "shared")
    parser.add_argument("--json", type=Path, default=None, help="default: OUT/summary.json")
    parser.add_argument("--jobs", type=int, default=2)
    parser.add_argument("--color-names", type=Path, default=None)
    parser.add_argument("--update-doc", action="store_true", help=f"rewrite the table in {DOC}")
    args = parser.parse_args()

    sequences = load_sequences(args.root)
    run = run_benchmark(
        sequences, args.trackers.split(","), args.out, jobs=args.jobs, colour_table=args.color_names
    )
    summaries = summarize_run(run)
    json_path = args.json or args.out / "summary.json"
    json_path.write_text(json.dumps(summary_json(summaries, args.root), indent=2) + "\n")
    write_run_plots(summaries, args.out / "plots", title="shared sequences")
    command = (
        f"autotrack bench ../shared/data/sequences --trackers {args.trackers} --jobs {args.jobs}"
        + (f" --color-names {args.color_names}" if args.color_names else "")
        + " --json r.json --plots"
    )
    tables = build_tables(sequences, summaries, _reference_scores(sequences), command)
    print(tables)
    if args.update_doc:
        update_doc(tables, args.color_names is not None)
        print(f"updated {DOC}")


if __name__ == "__main__":
    main()
