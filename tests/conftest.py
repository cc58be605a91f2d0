"""Shared test configuration: where the real data lives, skip markers for when it is absent.

Real sequences, the release's reference outputs and the published Color Names table are read
in place from `../shared/data` (beside the repository, never copied into it). Tests that need
them use the markers below and skip with one clear line when the data is absent.
"""

from __future__ import annotations

from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
SHARED = REPO.parent / "shared"
SHARED_DATA = SHARED / "data"
SEQUENCES = SHARED_DATA / "sequences"
REFERENCE = SHARED_DATA / "reference"
OCTAVE_REFERENCE = REFERENCE / "autotrack_release_octave"
OFFICIAL_REFERENCE = REFERENCE / "autotrack_official"
COLOUR_TABLE = SHARED_DATA / "color_names" / "cn_norm_32768x10.npy"

needs_sequences = pytest.mark.skipif(
    not SEQUENCES.is_dir(), reason=f"real sequences not found at {SEQUENCES}"
)
needs_colour_table = pytest.mark.skipif(
    not COLOUR_TABLE.is_file(), reason=f"published Color Names table not found at {COLOUR_TABLE}"
)


def shared_sequence_dir(dataset: str, name: str) -> Path:
    """The folder of one shared real sequence; skips the calling test when it is absent."""
    folder = SEQUENCES / dataset / name
    if not folder.is_dir():
        pytest.skip(f"sequence {dataset}/{name} not found under {SEQUENCES}")
    return folder


@pytest.fixture
def missing_models(monkeypatch, tmp_path) -> Path:
    """NanoTrack's default model files point to a file that is not there (a broken install)."""
    from autotrack.nanotrack.tracker import NanoTrackParams

    missing = tmp_path / "gone" / "nanotrack_backbone_sim.onnx"
    defaults = NanoTrackParams.__init__.__defaults__
    monkeypatch.setattr(NanoTrackParams.__init__, "__defaults__", (missing, *defaults[1:]))
    return missing
