"""Fidelity to the authors' release (AutoTrack_optimized.m), tested where it is not chaotic.

The tracker is chaotic under float rounding: positions are whole pixels (MATLAB `round` of the
sub-pixel peak) and the scale is a discrete choice, so once one rounding decision goes the other
way on some CPU (numba / FFTW SIMD paths differ between machines) two runs wander apart and a
single sequence's P@20 or AUC can move by several hundredths. A per-sequence score threshold
is therefore not a test. What is tested instead:

- fast: the first frames, before any rounding decision can part. There our boxes equal the
  release's boxes (run under Octave, and the authors' own MATLAB outputs) to a fraction of a
  pixel, on several sequences; and our peak scores over the same frames equal the ones recorded
  from a run whose boxes match the release's, to 1e-3 relative. Together these fail on a
  regression in any step's maths (features, window, label, ADMM, detection, Newton peak, ASR,
  ATR, scale filter, the training-feature shift).
- slow: agreement on means over the dev set (as `benchmarks/fidelity.py` reports them), which
  rounding moves by < 0.01: a coarse guard against gross regressions.

How the frame counts were chosen (measured on a 2-core AMD EPYC; see docs/benchmarks.md): the
boxes of our run equal the release's for the first 66 (building5), 30 (Crossing), 23
(MountainBike6), 27 (boat5), 11 (Animal3) frames. Runs whose features carry 1e-6 or 1e-4
relative noise on every frame (a stand-in for another CPU's rounding) keep our unperturbed boxes
for at least 52, 35, 24, 27, 17 frames. The counts below are about two thirds of the smaller of
the two (Yacht2 and wakeboard3 are compared with the authors' outputs only: 77 and 64 equal
frames, at least 31 and 32 under noise). A machine must round far more differently than that
noise to fail, while each change tried on purpose (ADMM iterations 3, label sigma x1.05, the
Hann window, scale step 1.025, gamma's growth 5, ASR off, no Newton steps, no
training-feature shift) moves a box or a peak score within these frames. The theta update is
the exception: the release's form lowers theta by ~1e-8 and the paper's by ~1e-7, too little to
move anything here; tests/test_tracker.py tells the three variants apart directly.
"""

from __future__ import annotations

import numpy as np
import pytest

from autotrack import AutoTrack, preset
from autotrack.evaluation.datasets import load_otb_sequence
from autotrack.io.frames import read_image
from autotrack.io.otb_boxes import read_boxes
from tests.conftest import (
    COLOUR_TABLE,
    OCTAVE_REFERENCE,
    OFFICIAL_REFERENCE,
    SHARED_DATA,
    needs_colour_table,
    needs_sequences,
    shared_sequence_dir,
)

BOX_TOLERANCE_PX = 0.25
"""Boxes are whole (or, with odd sizes, half) pixels: any parted decision moves one by >= 0.5."""
PEAK_RTOL = 1e-3
"""Peak scores over the prefix: 1e-6 feature noise moves them by < 4e-6; every deliberate break
tried moved at least one by > 1e-2."""

PREFIX = {
    # (dataset, sequence): (frames compared with the Octave run, frames compared with the
    # authors' own outputs; 0 where there are none)
    ("UAV123_10fps", "building5"): (35, 35),
    ("OTB", "Crossing"): (20, 0),
    ("DTB70", "MountainBike6"): (15, 15),
    ("UAV123_10fps", "boat5"): (18, 18),
    # The authors' MATLAB run and the Octave run themselves part after frame 4 here.
    ("DTB70", "Animal3"): (7, 4),
    # Added after the Octave run: the authors' outputs only (equal for 77 and 64 frames).
    ("DTB70", "Yacht2"): (0, 20),
    ("UAV123_10fps", "wakeboard3"): (0, 20),
}

# fmt: off
PEAK_SCORES = {
    # Our peak scores, frames 2.. of the prefix (the run whose boxes equal the release's). A
    # deliberate change of the maths that moves them must come with re-measured values here.
    "building5": [
        0.0116395, 0.0129849, 0.0135231, 0.0134861, 0.0148844, 0.0144595, 0.0152264, 0.016039,
        0.0175797, 0.0179539, 0.0182991, 0.0194241, 0.01897, 0.0200732, 0.0210993, 0.0214741,
        0.0219907, 0.0222498, 0.0227763, 0.0230385, 0.0238644, 0.0245619, 0.0247963, 0.0244995,
        0.0254999, 0.0249669, 0.0250532, 0.0258718, 0.0266901, 0.0266205, 0.0268955, 0.027025,
        0.0268118, 0.0274939,
    ],
    "Crossing": [
        0.0124632, 0.0126377, 0.0134762, 0.0139003, 0.0145679, 0.0150941, 0.0156072, 0.0162587,
        0.0156823, 0.015375, 0.016691, 0.0169436, 0.0163428, 0.0160903, 0.016302, 0.0168693,
        0.0177816, 0.017656, 0.0183175,
    ],
    "MountainBike6": [
        0.0152266, 0.0151467, 0.0168887, 0.0183624, 0.0168573, 0.018117, 0.019341, 0.0147406,
        0.0161208, 0.0175389, 0.0187308, 0.0157499, 0.0175658, 0.0187844,
    ],
    "boat5": [
        0.0199422, 0.0225913, 0.0242463, 0.0263916, 0.0276444, 0.0282394, 0.0293618, 0.0301877,
        0.0302637, 0.0314608, 0.0323146, 0.0314999, 0.031727, 0.0316911, 0.0320127, 0.032543,
        0.0329303,
    ],
    "Animal3": [
        0.0252834, 0.0260091, 0.0266106, 0.0300034, 0.0292015, 0.0296846,
    ],
    "Yacht2": [
        0.0240644, 0.0246397, 0.0247003, 0.0251816, 0.0274394, 0.0291165, 0.0297397, 0.0307751,
        0.0309972, 0.0318721, 0.0324826, 0.0327575, 0.0332253, 0.034517, 0.035231, 0.0363451,
        0.0361614, 0.0354905, 0.034997,
    ],
    "wakeboard3": [
        0.0169261, 0.0184843, 0.0169217, 0.018415, 0.0204908, 0.0205676, 0.0221409, 0.0233201,
        0.0240161, 0.0231948, 0.0252307, 0.0231082, 0.0242474, 0.0235751, 0.0240567, 0.0244263,
        0.0252026, 0.0264373, 0.0258276,
    ],
}
# fmt: on


def _track_prefix(dataset: str, name: str, frames: int):
    sequence = load_otb_sequence(shared_sequence_dir(dataset, name))[0]
    tracker = AutoTrack(preset("autotrack", COLOUR_TABLE))
    results = []
    for index, path in enumerate(sequence.frame_paths[:frames]):
        image = read_image(path, index)
        if index == 0:
            results.append(tracker.init(image, sequence.init_box))
        else:
            results.append(tracker.update(image))
    return sequence, results


def _first_parting(ours: np.ndarray, reference: np.ndarray) -> int | None:
    apart = np.flatnonzero(np.abs(ours - reference).max(axis=1) > BOX_TOLERANCE_PX)
    return int(apart[0]) if apart.size else None


@needs_sequences
@needs_colour_table
@pytest.mark.parametrize(("dataset", "name"), list(PREFIX))
def test_first_frames_equal_the_release_boxes_and_recorded_peaks(dataset, name):
    octave_frames, official_frames = PREFIX[(dataset, name)]
    sequence, results = _track_prefix(dataset, name, max(octave_frames, official_frames))
    boxes = np.array([result.box for result in results])

    if octave_frames:
        octave = read_boxes(OCTAVE_REFERENCE / dataset / f"{name}.txt")[:octave_frames]
        parting = _first_parting(boxes[:octave_frames], octave)
        assert parting is None, (
            f"{name}: frame {parting + 1} is {boxes[parting]} (0-based x, y, w, h), the "
            f"release under Octave has {octave[parting]}"
        )
    if official_frames:
        official = read_boxes(OFFICIAL_REFERENCE / dataset / f"{name}.txt")[:official_frames]
        parting = _first_parting(boxes[:official_frames], official)
        assert parting is None, (
            f"{name}: frame {parting + 1} is {boxes[parting]}, the authors' run has "
            f"{official[parting]}"
        )
    # Frame 1 is the ground truth moved by MATLAB's integer centre (up to half a pixel).
    assert np.abs(boxes[0] - sequence.ground_truth[0]).max() <= 0.5

    peaks = np.array([result.peak_score for result in results[1:]])
    np.testing.assert_allclose(peaks, PEAK_SCORES[name], rtol=PEAK_RTOL)


# -- slow: agreement on means over the dev set ------------------------------------------------

MEAN_SCORE_TOLERANCE = 0.02
"""|our mean P@20 / AUC - the release's| over the sequences with a reference, the one sequence
that agrees least left out. Measured 0.004 / < 0.001 on a 2-core AMD EPYC; with 1e-6 feature
noise on every frame 0.004 / 0.002 (the shared README: rounding moves the mean of a dozen by
< 0.01)."""
SEQUENCES_LEFT_OUT = 1
"""A knife-edge sequence turns on one parted rounding decision into a lost target, which alone
moves a mean of twelve by ~0.03: on a 2-core Intel Xeon, DTB70/Animal1 parts from the authors'
run at frame 25 (as on the EPYC, with both backends) and then loses the wildebeest (P@20
0.653 against 1.000), the other eleven agreeing to 0.003. The ablation table shows the same
sequence flipping to ~0.63 under small changes. So the sequence that agrees least is left out;
a gross regression moves many sequences and still fails."""
MEAN_IOU_FLOOR = 0.85
"""Mean over those sequences of the mean per-frame IoU with the release's boxes: 0.946 here,
0.907 with 1e-6 feature noise (MotorRolling, lost by both, drifts elsewhere: 0.35)."""
# These means are a coarse guard against gross regressions only: moderate breaks of one step
# (ADMM iterations 3, label sigma 0.07) moved them no more than rounding noise did. The sharp
# check is the first-frames test above.


def _mean_gap(pairs: list[tuple[tuple[float, float], tuple[float, float]]]) -> np.ndarray:
    """|mean(ours) - mean(reference)| (P@20, AUC), the SEQUENCES_LEFT_OUT pairs whose P@20
    differ most left out."""
    ours = np.array([pair[0] for pair in pairs])
    reference = np.array([pair[1] for pair in pairs])
    kept = np.argsort(np.abs(ours[:, 0] - reference[:, 0]), kind="stable")
    kept = kept[: len(pairs) - SEQUENCES_LEFT_OUT]
    return np.abs(ours[kept].mean(axis=0) - reference[kept].mean(axis=0))


def test_the_mean_gap_leaves_out_only_the_least_agreeing_sequence():
    pairs = [((1.0, 0.6), (1.0, 0.6))] * 10 + [((0.6, 0.4), (1.0, 0.6))]
    np.testing.assert_allclose(_mean_gap(pairs), [0.0, 0.0])
    two_lost = pairs + [((0.5, 0.3), (1.0, 0.6))]
    np.testing.assert_allclose(_mean_gap(two_lost), [0.4 / 11, 0.2 / 11])


@pytest.mark.slow
@needs_sequences
@needs_colour_table
def test_means_over_the_dev_set_agree_with_the_release():
    from benchmarks.fidelity import compare, means, sequence_jobs, track_all

    jobs = sequence_jobs(SHARED_DATA, "autotrack", str(COLOUR_TABLE))
    rows = [compare(SHARED_DATA, *output[:3]) for output in track_all(jobs, processes=2)]
    result = means(rows)
    assert result.octave_count >= 12 and result.all_count >= result.octave_count
    assert result.mean_iou_octave >= MEAN_IOU_FLOOR

    for reference in ("octave", "official"):
        pairs = [(row.ours, getattr(row, reference)) for row in rows]
        pairs = [pair for pair in pairs if pair[1] is not None]
        if pairs:
            gap = _mean_gap(pairs)
            assert gap.max() <= MEAN_SCORE_TOLERANCE, (reference, gap, pairs)
