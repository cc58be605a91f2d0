"""Long-term appearance memory and distractor disambiguation (`TrackerParams.memory_rate`).

The short-term filter learns the newest appearance every confident frame, so when a look-alike
(another llama, a neighbour in a herd) comes close it can drift onto it at full confidence: the
response has two peaks of nearly equal height and the higher one is not always the target.
LCT (Ma, Yang, Zhang, Yang: *Long-term Correlation Tracking*, CVPR 2015) keeps a second,
conservatively updated filter for the target's long-term appearance. Here that memory is the
running average of the tracker's own learnt filters, taken only on frames the tracker learnt
(confident, not aberrant) at a slow rate: the same features, window and response scale as the
short-term filter, no second training.

When the short-term response has a second distinct peak at least `distractor_ratio` of the
first (a distractor in the search region), each peak is scored by the product of the two
filters' responses there (the joint evidence of the short-term and the long-term appearance)
and the tracker takes the best; without a second peak nothing changes. With `motion_prior` on,
the product also takes a constant-velocity prior on each peak's displacement, so of two
look-alikes the one on the target's path wins unless the other has clearly more evidence.
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from autotrack.tracker import dcf
from autotrack.tracker.plus.motion import MotionPrior


class LongTermMemory:
    """Running average of the learnt filters (half spectra), updated at `rate` per learnt frame."""

    def __init__(self, first_filter_f: np.ndarray, rate: float) -> None:
        self.rate = rate
        self.filter_f = first_filter_f.copy()

    def learn(self, filter_f: np.ndarray) -> None:
        """Fold a newly learnt filter into the memory (call only on frames that were learnt)."""
        self.filter_f *= 1.0 - self.rate
        self.filter_f += self.rate * filter_f

    def response(self, zf: np.ndarray, grid_size: tuple[int, int]) -> np.ndarray:
        """The memory's detection response (eq. 16) on the same features as the tracker's."""
        return dcf.detection_response(self.filter_f, zf, grid_size)


def distinct_peaks(response: np.ndarray, ratio: float, separation: float) -> list[tuple[int, int]]:
    """Integer (row, col) cells of the response's distinct peaks, the global maximum first.

    A distinct peak is a local maximum of its 3 x 3 (circular) neighbourhood, at least `ratio`
    times the global maximum, and at least `separation` cells (circular distance) from every
    higher peak kept: a second mode, not the shoulder of the first.
    """
    top = float(response.max())
    if not (math.isfinite(top) and top > 0):
        return [tuple(int(v) for v in np.unravel_index(np.argmax(response), response.shape))]
    # Only cells above the ratio can be peaks: their 3 x 3 neighbourhoods are gathered alone.
    rows, cols = np.nonzero(response >= ratio * top)
    height, width = response.shape
    values = response[rows, cols]
    local_max = np.ones(len(rows), dtype=bool)
    for dr in (-1, 0, 1):
        for dc in (-1, 0, 1):
            local_max &= values >= response[(rows + dr) % height, (cols + dc) % width]
    rows, cols, values = rows[local_max], cols[local_max], values[local_max]
    order = np.argsort(-values, kind="stable")
    kept: list[tuple[int, int]] = []
    for index in order:
        row, col = int(rows[index]), int(cols[index])
        if all(
            math.hypot(_wrap(row - r, height), _wrap(col - c, width)) >= separation for r, c in kept
        ):
            kept.append((row, col))
    return kept


def _wrap(delta: int, size: int) -> int:
    return (delta + size // 2) % size - size // 2


def choose_peak(
    short_term: np.ndarray,
    long_term: np.ndarray,
    peaks: list[tuple[int, int]],
    motion: MotionPrior | None = None,
) -> int:
    """Index of the peak with the largest product of the evidence (negative counts as 0).

    The evidence is the two responses, each taken at its best cell within one cell of the peak
    (so a one-cell disagreement between the two filters does not decide), times the motion
    prior's likelihood of the peak's displacement when a prior is given.
    """
    height, width = short_term.shape
    scores = []
    for peak in peaks:
        score = max(_near_max(short_term, peak), 0.0) * max(_near_max(long_term, peak), 0.0)
        if motion is not None:
            score *= motion.likelihood(_wrap(peak[0], height), _wrap(peak[1], width))
        scores.append(score)
    return int(np.argmax(scores)) if max(scores) > 0 else 0


def _near_max(response: np.ndarray, cell: tuple[int, int]) -> float:
    height, width = response.shape
    rows = [(cell[0] + d) % height for d in (-1, 0, 1)]
    cols = [(cell[1] + d) % width for d in (-1, 0, 1)]
    return float(response[np.ix_(rows, cols)].max())


def subcell_peak(response: np.ndarray, cell: tuple[int, int]) -> tuple[float, float, float]:
    """(row, col displacement in cells, score) of a peak refined by a parabola along each axis.

    Displacements are wrapped to [-n/2, n/2) as in `dcf.newton_peak`, which refines only the
    global maximum.
    """
    height, width = response.shape
    row, col = cell
    centre = float(response[row, col])
    offsets = []
    for axis_values in (
        (response[(row - 1) % height, col], response[(row + 1) % height, col]),
        (response[row, (col - 1) % width], response[row, (col + 1) % width]),
    ):
        before, after = float(axis_values[0]), float(axis_values[1])
        curvature = before - 2.0 * centre + after
        offset = 0.5 * (before - after) / curvature if curvature < 0 else 0.0
        offsets.append(float(np.clip(offset, -0.5, 0.5)))
    disp_row = (row + (height - 1) // 2) % height - (height - 1) // 2 + offsets[0]
    disp_col = (col + (width - 1) // 2) % width - (width - 1) // 2 + offsets[1]
    return float(disp_row), float(disp_col), centre


def disambiguate(
    response: np.ndarray,
    memory_response: np.ndarray | Callable[[], np.ndarray],
    ratio: float,
    separation: float,
    motion: MotionPrior | None = None,
    margin: float = 0.0,
) -> tuple[tuple[float, float, float] | None, bool]:
    """(the peak to take instead of the global maximum, or None; whether a distractor is present).

    With one distinct peak nothing changes (None, False). With several, the candidates are the
    global maximum, the peaks nearer the expected displacement than it (zero, or the motion
    prior's prediction) and the peaks where the memory responds more than 1 + `margin` times
    what it does at the global maximum; of those the one with the most joint evidence
    (`choose_peak`, with the motion prior if given) is taken; if that is the global maximum,
    (None, True). So the memory takes a track back from a distractor it knows is not the
    target, and never moves it onto a look-alike it cannot tell from the target (a walker in
    a group, a car in a queue).

    `memory_response` may be a function that computes it: it is called only with a second
    peak, so a frame without a look-alike costs no second detection.
    """
    peaks = distinct_peaks(response, ratio, separation)
    if len(peaks) < 2:
        return None, False
    if callable(memory_response):
        memory_response = memory_response()
    expected = motion.predicted if motion is not None else (0.0, 0.0)
    reach = _cell_distance(peaks[0], expected, response.shape)
    held = _near_max(memory_response, peaks[0])
    peaks = [peaks[0]] + [
        peak
        for peak in peaks[1:]
        if _cell_distance(peak, expected, response.shape) < reach
        or _near_max(memory_response, peak) > (1.0 + margin) * held
    ]
    chosen = choose_peak(response, memory_response, peaks, motion)
    if chosen == 0:
        return None, True
    return subcell_peak(response, peaks[chosen]), True


def lookalike_within(
    peaks: list[tuple[int, int]],
    displacement: tuple[float, float],
    shape: tuple[int, int],
    reach_cells: np.ndarray,
) -> bool:
    """Whether a distinct peak other than the target's lies within `reach_cells` (rows, cols)
    of the target's `displacement` on both axes: a look-alike whose box overlaps the target's
    when the reach is one box size. The target's own peak is the one nearest `displacement`.
    """
    offsets = [
        (_wrap(row, shape[0]) - displacement[0], _wrap(col, shape[1]) - displacement[1])
        for row, col in peaks
    ]
    offsets.sort(key=lambda offset: math.hypot(*offset))
    return any(abs(row) < reach_cells[0] and abs(col) < reach_cells[1] for row, col in offsets[1:])


def _cell_distance(cell: tuple[int, int], expected: tuple[float, float], shape) -> float:
    """Distance (cells) of a peak's wrapped displacement from an expected displacement."""
    row, col = _wrap(cell[0], shape[0]), _wrap(cell[1], shape[1])
    return math.hypot(row - expected[0], col - expected[1])
