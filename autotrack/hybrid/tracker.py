"""The hybrid tracker: AutoTrack+ (a correlation filter) and NanoTrack (a Siamese network) on the
same frames, fused frame by frame by what each says about itself.

The two fail differently. The filter learns the target online and holds a small or look-alike
target the Siamese network jumps off; it says when it cannot be trusted: its aberrance stop
(eta >= phi, paper eq. 4) or its confidence gate closes, and it then does not learn the frame
(`TrackResult.theta` is NaN). The Siamese network never learns, so it does not drift; it fits the
box to the target's shape (the filter keeps its first aspect); and its score is a foreground
probability. Targets move continuously; a jump to a look-alike, or a filter re-learnt on the
background, does not. The rule (`fuse`):

1. Both agree on the centre (each centre within `agree_radius` of the other's box half-sides):
   the mean of the two boxes, each weighted by the inverse of its area. Two trackers that see
   one object with errors of their own (the filter's fixed aspect, the network's coarse 16-pixel
   cells) average to a better box than either. A tracker's error grows with the size of the box
   it reports (its search region, its cells and its scale steps all scale with it), so the
   inverse-variance weights are 1/area: the box that spread over the target and its
   surroundings (a Siamese box grown over a herd, a filter box that kept a boat's first aspect
   after it turned) counts less. Each weight is then multiplied by the Siamese foreground
   probability at the box's centre, the network's likelihood that the centre is on the target:
   a centre the network's map calls background (the filter's box slipping off a fast gull)
   counts less. Only the network's map is read so (rule 2 says why). Nobody is re-initialised:
   each stays an independent estimate.
2. They disagree, and the Siamese network's own score map says the filter's centre is on the
   target too (its foreground probability there is at least `siamese_corroborates`): the two
   models agree on the filter's place and only one backs the Siamese box, so the filter's box
   is trusted if it moved continuously (cross-verification, `cross_check`), and the Siamese
   track is moved there as in rule 3. This is the case of a Siamese box sliding along the
   target or over its surroundings (a motorbike flipping, a box growing over a herd) while the
   filter stays on it, held or not. Only this direction is read: the network's map is a
   classifier's verdict on every place of its search crop, while the filter's response away
   from its peak follows its learnt Gaussian label and measures the distance to its own peak,
   not whether another place is the target. And only corroboration counts, not refutation: a
   probability below 0.5 at the filter's centre is also what a target that changed its look
   gives, where the network is the one that is lost.
3. They disagree otherwise. Each is *credible* when its own evidence is good and it moved
   continuously (its centre within `agree_radius` of its own last box: no jump): the filter
   when it learnt this frame (not held), the Siamese network when its foreground probability is
   at least `siamese_confident` and its score map is not aberrant (eta < phi). When exactly one
   is credible it is trusted and the other may restart from its box: the Siamese track is moved
   there keeping its first-frame template (`NanoTrack.place`); re-initialising the filter
   (`reinit_filter`) is off by default, because a filter held on a target that turns or blurs
   is often still right and a new filter forgets what the old one learnt (on the dev set it
   cost more than it saved, docs/hybrid.md).
4. Both or neither credible: the box that jumped less from the last hybrid box, and nobody is
   restarted (no evidence says who is lost).

Each branch can be switched off (`HybridParams`) for the ablation.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from autotrack.nanotrack import NanoTrack, NanoTrackParams
from autotrack.nanotrack.tracker import foreground_at
from autotrack.params import TrackerParams, preset
from autotrack.result import TrackResult

Box = tuple[float, float, float, float]

BOTH, FILTER, SIAMESE = "both", "filter", "siamese"
"""Which tracker the hybrid box came from: agreement, the correlation filter, the Siamese one."""


@dataclass(frozen=True)
class HybridParams:
    """The two trackers and the fusion's parameters (module docstring)."""

    filter_params: TrackerParams = field(default_factory=lambda: preset("autotrack+"))
    """The correlation filter's parameters (the `autotrack+` preset)."""
    siamese_params: NanoTrackParams = field(default_factory=NanoTrackParams)
    """NanoTrack's parameters and model files."""
    agree_radius: float = 1.0
    """The trackers agree when each box centre lies within `agree_radius` times the other box's
    half width and half height of its centre: 1 is "inside the other's box", the loosest test
    under which both still point at one object of the target's size."""
    siamese_confident: float = 0.5
    """The Siamese foreground probability (the score map at the chosen cell, a two-class
    softmax) above which its box is trusted over a held filter: 0.5 is where the network says
    target rather than background."""
    average_boxes: bool = True
    """Rule 1 averages the two boxes (else it takes the filter's centre and the Siamese shape)."""
    size_weighted: bool = True
    """Rule 1 weights each box by the inverse of its area (else the plain mean): inverse-variance
    weights when each tracker's error is proportional to the side of the box it reports."""
    likelihood_weighted: bool = True
    """Rule 1 multiplies each box's weight by the Siamese foreground probability at its centre,
    the network's likelihood that the centre is on the target (else the size weights alone)."""
    reinit_filter: bool = False
    """Rule 3 re-initialises the filter on a credible Siamese box (else the filter keeps
    tracking on its own)."""
    place_siamese: bool = True
    """Rules 2 and 3 move the Siamese track to the trusted filter box (else it keeps searching on
    its own)."""
    continuity: bool = True
    """Credibility includes moving continuously (else own evidence only, and rule 4 trusts the
    filter)."""
    cross_check: bool = True
    """Rule 2: the filter's box is trusted when the Siamese map corroborates it (else rules 3-4
    decide from each tracker's own evidence alone)."""
    siamese_corroborates: float = 0.5
    """The Siamese foreground probability at the filter's centre from which the network's model
    backs the filter's box (rule 2): 0.5 is where the softmax says target rather than
    background, the same reading as `siamese_confident` of the network's own box."""


@dataclass(frozen=True)
class Decision:
    """What the fusion rule made of one frame."""

    box: Box
    """The hybrid's box, 0-based (x, y, w, h)."""
    trusted: str
    """BOTH, FILTER or SIAMESE."""
    reinit_filter: bool
    """Start the filter again on `box`."""
    place_siamese: bool
    """Move the Siamese track to `box` (keeping its template)."""


@dataclass(frozen=True)
class HybridResult(TrackResult):
    """A `TrackResult` whose box is the fused one; its signals and maps are the filter's. The
    two trackers' own results and which one was trusted ride along."""

    trusted: str = BOTH
    """BOTH, FILTER or SIAMESE: where this frame's box came from."""
    filter_result: TrackResult | None = None
    """The correlation filter's own result this frame (before any re-initialisation)."""
    siamese_result: TrackResult | None = None
    """NanoTrack's own result this frame."""


def centre(box: Sequence[float]) -> tuple[float, float]:
    """Centre (cx, cy) of an (x, y, w, h) box."""
    return (box[0] + box[2] / 2.0, box[1] + box[3] / 2.0)


def centres_agree(first: Sequence[float], second: Sequence[float], radius: float) -> bool:
    """Each box's centre lies within `radius` half-sides of the other's centre."""
    (x1, y1), (x2, y2) = centre(first), centre(second)
    dx, dy = abs(x1 - x2), abs(y1 - y2)
    return all(
        dx <= radius * box[2] / 2.0 and dy <= radius * box[3] / 2.0 for box in (first, second)
    )


def filter_held(result: TrackResult) -> bool:
    """The filter's own evidence that it lost the target: it did not learn this frame (the
    aberrance stop, eta >= phi, or the confidence gate; theta is NaN when it did not train)."""
    return result.aberrant or not math.isfinite(result.theta)


def siamese_probability(result: TrackResult, peak_cell: tuple[int, int]) -> float:
    """The Siamese foreground probability at the cell its box came from."""
    return float(result.response_map[peak_cell])


@dataclass(frozen=True)
class SiameseReading:
    """What the Siamese score map says of one frame's two hypotheses: foreground probabilities."""

    score: float
    """At the cell its box came from: the network's confidence in its own box."""
    at_filter: float
    """At the filter's box centre (`nanotrack.tracker.foreground_at`)."""
    at_siamese: float
    """At its own box centre (`nanotrack.tracker.foreground_at`)."""


def read_siamese(
    siamese_result: TrackResult, peak_cell: tuple[int, int], filter_box: Sequence[float]
) -> SiameseReading:
    """The Siamese map's reading of a frame whose boxes are `siamese_result.box` and
    `filter_box`, its own box having come from `peak_cell`."""
    return SiameseReading(
        siamese_probability(siamese_result, peak_cell),
        foreground_at(siamese_result, centre(filter_box)),
        foreground_at(siamese_result, centre(siamese_result.box)),
    )


def mean_box(first: Sequence[float], second: Sequence[float], weight: float = 0.5) -> Box:
    """The element-wise weighted mean of two (x, y, w, h) boxes, `weight` on the first."""
    return tuple(
        weight * float(u) + (1.0 - weight) * float(v) for u, v in zip(first, second, strict=True)
    )


def inverse_area_weight(first: Sequence[float], second: Sequence[float]) -> float:
    """The first box's share of an inverse-variance mean of two boxes whose errors have standard
    deviations proportional to their sides: 1/area_1 / (1/area_1 + 1/area_2)."""
    first_area, second_area = first[2] * first[3], second[2] * second[3]
    return float(second_area / (first_area + second_area))


def likelihood_weight(weight: float, first_probability: float, second_probability: float) -> float:
    """The first box's share once each box's `weight` (`weight` and 1 - `weight`) is multiplied by
    the probability that its centre is on the target; `weight` itself when both are 0."""
    first, second = weight * first_probability, (1.0 - weight) * second_probability
    return weight if first + second <= 0.0 else float(first / (first + second))


def jump(box: Sequence[float], previous: Sequence[float]) -> float:
    """How far a box's centre moved from the previous box's, in units of the previous size."""
    (x, y), (px, py) = centre(box), centre(previous)
    return math.hypot(x - px, y - py) / math.sqrt(max(previous[2] * previous[3], 1e-9))


def fuse(
    filter_result: TrackResult,
    siamese_result: TrackResult,
    reading: SiameseReading,
    previous: tuple[Box, Box, Box],
    params: HybridParams,
) -> Decision:
    """The fusion rule of one frame (module docstring): the box, whom it trusts, who restarts.

    `reading` is the Siamese map's foreground probabilities (at its chosen cell and at both box
    centres); `previous` the last frame's (hybrid, filter, Siamese) boxes."""
    previous_box, previous_filter, previous_siamese = previous
    filter_box, siamese_box = filter_result.box, siamese_result.box
    radius = params.agree_radius
    if centres_agree(filter_box, siamese_box, radius):  # rule 1
        if params.average_boxes:
            weight = inverse_area_weight(filter_box, siamese_box) if params.size_weighted else 0.5
            if params.likelihood_weighted:
                weight = likelihood_weight(weight, reading.at_filter, reading.at_siamese)
            return Decision(mean_box(filter_box, siamese_box, weight), BOTH, False, False)
        (cx, cy), (_, _, w, h) = centre(filter_box), siamese_box
        return Decision((cx - w / 2.0, cy - h / 2.0, w, h), BOTH, False, False)
    filter_continuous = not params.continuity or centres_agree(filter_box, previous_filter, radius)
    siamese_continuous = not params.continuity or centres_agree(
        siamese_box, previous_siamese, radius
    )
    corroborated = reading.at_filter >= params.siamese_corroborates
    if params.cross_check and corroborated and filter_continuous:  # rule 2
        return Decision(filter_box, FILTER, False, params.place_siamese)
    filter_credible = not filter_held(filter_result) and filter_continuous
    siamese_credible = (
        reading.score >= params.siamese_confident
        and not siamese_result.aberrant
        and siamese_continuous
    )
    if siamese_credible and not filter_credible:  # rule 3
        return Decision(siamese_box, SIAMESE, params.reinit_filter, False)
    if filter_credible and not siamese_credible:
        return Decision(filter_box, FILTER, False, params.place_siamese)
    if params.continuity and jump(siamese_box, previous_box) < jump(filter_box, previous_box):
        return Decision(siamese_box, SIAMESE, False, False)  # rule 4
    return Decision(filter_box, FILTER, False, False)


def inside_frame(box: Sequence[float], size_wh: tuple[int, int], min_side: float = 2.0) -> Box:
    """The part of a box inside a frame of (width, height), at least `min_side` on each side."""
    width, height = size_wh
    x0 = min(max(box[0], 0.0), width - min_side)
    y0 = min(max(box[1], 0.0), height - min_side)
    x1 = max(min(box[0] + box[2], float(width)), x0 + min_side)
    y1 = max(min(box[1] + box[3], float(height)), y0 + min_side)
    return (x0, y0, x1 - x0, y1 - y0)


class HybridTracker:
    """AutoTrack+ and NanoTrack fused by `fuse`: `init(frame, box)`, `update(frame)` return
    `HybridResult`s."""

    def __init__(self, params: HybridParams | None = None) -> None:
        from autotrack import AutoTrack

        self.params = params or HybridParams()
        self._new_filter = lambda: AutoTrack(self.params.filter_params)
        self.filter = self._new_filter()
        self.siamese = NanoTrack(self.params.siamese_params)
        self.frame_number = 0
        self.box: Box = (0.0, 0.0, 0.0, 0.0)
        """The last hybrid box."""
        self.filter_box: Box = self.box
        """The filter's last box (where it was restarted, if it was)."""
        self.siamese_box: Box = self.box
        """The Siamese track's last box (where it was moved, if it was)."""

    def init(self, frame_rgb: np.ndarray, box: Sequence[float]) -> HybridResult:
        """Start both trackers on the first frame's box."""
        filter_result = self.filter.init(frame_rgb, box)
        siamese_result = self.siamese.init(frame_rgb, box)
        self.frame_number = 1
        self.box = self.filter_box = filter_result.box
        self.siamese_box = siamese_result.box
        return HybridResult(
            **_fields(filter_result),
            trusted=BOTH,
            filter_result=filter_result,
            siamese_result=siamese_result,
        )

    def update(self, frame_rgb: np.ndarray) -> HybridResult:
        """Track into the next frame with both trackers and fuse their boxes."""
        filter_result = self.filter.update(frame_rgb)
        siamese_result = self.siamese.update(frame_rgb)
        reading = read_siamese(siamese_result, self.siamese.peak_cell, filter_result.box)
        previous = (self.box, self.filter_box, self.siamese_box)
        decision = fuse(filter_result, siamese_result, reading, previous, self.params)
        if decision.reinit_filter:
            height, width = frame_rgb.shape[:2]
            self.filter = self._new_filter()
            self.filter.init(frame_rgb, inside_frame(decision.box, (width, height)))
        if decision.place_siamese:
            self.siamese.place(decision.box)
        self.frame_number += 1
        self.box = tuple(float(v) for v in decision.box)
        self.filter_box = self.box if decision.reinit_filter else filter_result.box
        self.siamese_box = self.box if decision.place_siamese else siamese_result.box
        box = self.box
        fused = replace(filter_result, box=box, frame_index=self.frame_number - 1)
        return HybridResult(
            **_fields(fused),
            trusted=decision.trusted,
            filter_result=filter_result,
            siamese_result=siamese_result,
        )


def _fields(result: TrackResult) -> dict:
    return {name: getattr(result, name) for name in TrackResult.__dataclass_fields__}
