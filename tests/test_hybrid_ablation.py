"""The hybrid's ablation table (benchmarks/hybrid_ablation.py) on constructed scores."""

from __future__ import annotations

import sys
from types import SimpleNamespace

import numpy as np

from autotrack.evaluation.metrics import score_sequence
from tests.conftest import REPO

sys.path.insert(0, str(REPO / "benchmarks"))
import hybrid_ablation  # noqa: E402


class _Sequence(SimpleNamespace):
    def __init__(self, name: str) -> None:
        super().__init__(name=name, dataset="D")

    def __len__(self) -> int:
        return 30


def test_the_table_counts_sequences_worse_than_nanotrack_and_prints_sensitivity():
    truth = np.tile([10.0, 10.0, 40.0, 40.0], (30, 1))
    shifted = truth + [30.0, 0.0, 0.0, 0.0]  # a quarter overlap: far below NanoTrack
    sequences = [_Sequence(n) for n in ("good", "bad")]
    boxes = {
        "nanotrack": {"good": truth, "bad": truth},
        "hybrid": {"good": truth, "bad": shifted},
        "hybrid agree_radius x0.5": {"good": truth, "bad": truth},
    }
    scores = {
        label: {name: score_sequence(name, b, truth) for name, b in runs.items()}
        for label, runs in boxes.items()
    }
    fps = dict.fromkeys(boxes, 30.0)
    table = hybrid_ablation.build_hybrid_table(sequences, scores, fps)
    rows = {line.split(" | ")[0].lstrip("| "): line for line in table.splitlines()}
    assert "| 0  |" in rows["nanotrack"]
    assert "| 1 bad |" in rows["hybrid"]
    assert "| D/bad | 0.952 | " in table  # NanoTrack first (a box equal to the truth)
    assert "| `agree_radius` | 1.000 / 0.952 (+0.500 / +" in table
    assert "| `siamese_confident` | not run | not run |" in table


def test_update_doc_replaces_only_the_marked_table(tmp_path):
    doc = tmp_path / "doc.md"
    doc.write_text("before\n<!-- hybrid:start -->\nold\n<!-- hybrid:end -->\nafter\n")
    hybrid_ablation.replace_marked(doc, "| new |")
    assert doc.read_text() == "before\n<!-- hybrid:start -->\n| new |\n<!-- hybrid:end -->\nafter\n"
