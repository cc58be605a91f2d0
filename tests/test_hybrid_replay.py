"""The replay of the fusion rule on recorded runs (benchmarks/hybrid_replay.py) gives the hybrid
tracker's own boxes when the fusion does not feed back."""

from __future__ import annotations

import sys

import numpy as np

from autotrack.evaluation.datasets import load_otb_sequence
from autotrack.hybrid import HybridParams, HybridTracker
from tests.conftest import REPO, needs_sequences, shared_sequence_dir

sys.path.insert(0, str(REPO / "benchmarks"))
import hybrid_replay  # noqa: E402

FRAMES = 24


@needs_sequences
def test_the_replay_reproduces_the_hybrid_without_re_placing_on_real_frames():
    sequence = load_otb_sequence(shared_sequence_dir("DTB70", "Gull1"))[0]
    # A tight agreement radius makes the two trackers disagree on some of these frames.
    params = HybridParams(place_siamese=False, agree_radius=0.25)
    tracker = HybridTracker(params)
    boxes, trusted = [], []
    with sequence.frames() as frames:
        for index in range(FRAMES):
            frame = frames.read(index)
            result = tracker.init(frame, sequence.init_box) if index == 0 else tracker.update(frame)
            boxes.append(result.box)
            trusted.append(result.trusted)
    recorded = hybrid_replay.record(sequence, params, frames=FRAMES)
    assert len(recorded["filter_box"]) == FRAMES and np.isnan(recorded["siamese_score"][0])
    # The Siamese map corroborates the filter's centre on some frames and not on others: the
    # replay reads the cross-verification's evidence both ways.
    corroborated = recorded["siamese_at_filter"][1:] >= params.siamese_corroborates
    assert 0 < np.count_nonzero(corroborated) < FRAMES - 1
    replayed, replayed_trusted = hybrid_replay.replay(recorded, params)
    assert len(set(trusted)) > 1  # more than one branch of the rule fired
    assert replayed_trusted == trusted
    np.testing.assert_array_equal(replayed, np.asarray(boxes))
