"""Tracker parameters: the published AutoTrack defaults and the paper's ablation presets."""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path
from typing import Literal

ColourFeature = Literal["lab11", "table", "none"]
ThetaUpdate = Literal["release", "paper", "reference"]
BackendName = Literal["fast", "reference"]


@dataclass(frozen=True)
class TrackerParams:
    """AutoTrack parameters. Defaults are the authors' released settings (run_AutoTrack.m)."""

    backend: BackendName = "fast"
    """Where the per-frame maths runs: "fast" (compiled kernels, `tracker.backend`) or
    "reference" (the plain numpy definition, `tracker.dcf`, `tracker.features`; ~10x slower)."""

    # Features
    cell_size: int = 4
    """Feature cell size (pixels per cell side)."""
    use_grey: bool = True
    """Grey channel: (grey / 255 - 0.5) averaged over each cell. 1 channel."""
    use_fhog: bool = True
    """Felzenszwalb HOG, 9 orientations, 31 channels."""
    colour_feature: ColourFeature = "lab11"
    """Colour feature for colour frames: our CIELAB soft colour-term assignment ('lab11', the
    default), the published Color Names table loaded from `colour_table_path` ('table'), or none."""
    colour_table_path: str | None = None
    """Path of a 32768 x 10 Color Names table (.npy or .mat), used when colour_feature='table'."""

    # Search region
    search_area_scale: float = 5.0
    """Side of the square search region = sqrt(w * h * search_area_scale)."""
    min_image_sample_size: float = 150.0**2
    """Smallest search-region area (pixels^2) after the fixed resampling of frame 1."""
    max_image_sample_size: float = 200.0**2
    """Largest search-region area (pixels^2) after the fixed resampling of frame 1."""
    output_sigma_factor: float = 0.06
    """Gaussian label sigma = sqrt(prod(floor(base_target_sz / cell))) * this, in cells."""

    # Detection
    newton_iterations: int = 5
    """Newton iterations refining the sub-pixel peak of the response (Fourier series)."""

    # ADMM (paper eqs. 8-14)
    admm_iterations: int = 4
    """ADMM iterations per frame."""
    admm_lambda: float = 1.0
    """Weight of the spatial regularisation term (lambda in the h-step)."""
    gamma_init: float = 1.0
    """Initial ADMM penalty gamma."""
    gamma_step: float = 10.0
    """Penalty growth per iteration (beta)."""
    gamma_max: float = 10000.0
    """Largest ADMM penalty."""

    # Spatial regularisation (ASR, eqs. 2-3)
    reg_window_max: float = 1e5
    """Base window value outside the target region."""
    reg_window_min: float = 1e-3
    """Base window value inside the target region."""
    adaptive_spatial: bool = True
    """ASR: replace the target-region window by delta * log(local variation + 1) (eq. 3)."""
    delta: float = 0.2
    """Weight of the local response variation in the spatial window (eq. 3)."""

    # Temporal regularisation (ATR, eqs. 4 and 13)
    adaptive_temporal: bool = True
    """ATR: theta from the global response variation, and the aberrance stop."""
    zeta: float = 13.0
    """Temporal reference numerator zeta (eq. 4); also theta in frame 2."""
    nu: float = 0.2
    """nu on the 1e-4-scaled global variation (release form; = 2e-5 on the unscaled norm)."""
    phi: float = 0.3
    """Aberrance threshold on the 1e-4-scaled global variation (= 3000 unscaled)."""
    fixed_theta: float = 15.0
    """Temporal penalty when ATR is off (STRCF's value)."""
    theta_update: ThetaUpdate = "release"
    """In-ADMM theta re-estimation (eq. 13): 'release' (the release's own form: one element of
    the filter difference, MATLAB linear index = channel count; ~1e-6 against zeta), 'paper' (all
    channels, Frobenius norm), 'reference' (theta = theta_ref). Clamped at 0."""

    # Scale filter (DSST)
    num_scales: int = 33
    """Number of scales of the 1-D scale filter."""
    scale_step: float = 1.03
    """Ratio between neighbouring scales."""
    scale_sigma_factor: float = 0.5
    """Scale label sigma = sqrt(num_scales) * this."""
    scale_lambda: float = 1e-4
    """Regulariser of the scale filter."""
    scale_learning_rate: float = 0.025
    """Running-average rate of the scale filter."""
    scale_model_max_area: float = 32.0 * 16.0
    """Largest area (pixels^2) of a resampled scale sample."""

    # Beyond the release (the `autotrack+` preset, autotrack/tracker/plus/robust.py and redetect.py); every
    # switch is off in the faithful presets, which then run the release's code path unchanged.
    robust_variation: bool = False
    """Local variation with its denominator floored at `variation_floor` x the previous peak
    (robust.robust_local_variation) instead of the bare previous response."""
    variation_floor: float = 0.1
    """Floor of the local variation's denominator, as a fraction of the previous peak. The
    label is a Gaussian a few cells wide, so a learnt response below ~10 % of its peak is
    sidelobe noise, not target evidence."""
    acting_asr: bool = False
    """ASR scaled so delta * log(Pi + 1) is the relative attenuation of the last h-step
    (robust.acting_spatial_window); the release's u is ~1e-6 of the h-step denominator."""
    asr_relative: bool = False
    """With the acting ASR, attenuate only cells whose variation exceeds the target region's
    median (robust.acting_spatial_window): a partial change is repressed, a change of the whole
    target (a turn, a scale or light change), which the filter must learn, is not."""
    confidence_gate: float = 0.0
    """Learn the filter and the scale model only when the detection's peak is at least this
    fraction of its running average and its APCE at least the square of it
    (robust.ResponseConfidence); 0 = always (release). 0.7: LMCF's published peak threshold
    (its APCE threshold, 0.45, is ~0.7^2)."""
    confidence_memory: float = 0.1
    """Per-frame rate of the running average of the peak: about ten frames (1 s at the UAV
    benchmarks' 10 fps) of memory, so slow appearance change is followed, an occlusion is not."""
    redetect_span: float = 0.0
    """When the confidence is below the gate, search a square `redetect_span` times the search
    region's side (redetect.wide_search_offset) and move there if it is confident and beats the
    local peak; 0 = never. 3: one full search region beyond the current one in every direction."""
    redetect_patience: int = 1
    """Re-detection may move the tracker only once this many consecutive frames (this one
    included) were below the confidence gate: the target is lost by its own evidence, not
    dimmed for a frame. 1 = on the first such frame. 3 in `autotrack+`: a frame or two below
    the gate is a pole, a tree crown or another vehicle passing over the target, and a wide
    search then finds a look-alike as readily as the target."""
    scale_model_min_side: float = 0.0
    """Smallest side (pixels) of a resampled scale sample; 0 = the release's (area <= 512 only).
    16 px = four fHOG cells, so a thin target keeps interior cells across its short side."""
    velocity_weight: float = 0.0
    """Search centred at the last position plus this fraction of the last confident frame's
    motion (a constant-velocity prediction); 0 = the release (the last position). 1: constant
    velocity. Measured, not in `autotrack+` (docs/tracker.md)."""
    memory_rate: float = 0.0
    """Long-term appearance memory (memory.LongTermMemory, after LCT): the running average of the
    learnt filters, at this rate per learnt, unambiguous frame; when the response has a second
    distinct peak the peak with the most joint evidence of both filters is taken. 0 = off. 0.01:
    LCT's long-term learning rate, a memory of ~100 learnt frames (10 s at 10 fps); in
    `autotrack+`."""
    memory_margin: float = 0.25
    """The memory may move the track to a peak farther from the expected displacement than the
    response's maximum only where the memory responds more than 1 + this times what it does
    at the maximum (memory.disambiguate): it must tell the two apart. 0.25: look-alikes the
    memory cannot tell apart (walkers dressed alike) differ by up to ~10 % in its response
    from frame to frame on the generated walker group; a distractor of another pattern that
    dragged the track off (the passing look-alike of tests/sequences.py) by ~50 %."""
    lookalike_reach: float = 0.0
    """The scale may not grow while a look-alike (another distinct peak of the response, at
    least `distractor_ratio` of the highest) lies within this many grown box sizes of the
    target on both axes (memory.lookalike_within): a larger scale sample then takes in the
    neighbour, whose appearance is the target's, and the scale filter prefers it by a fraction
    of a percent a step, which ran a walker's box away to twice its size in a crowd
    (docs/tracker.md). 0 = the release's scale model. 0.5 in `autotrack+`: the look-alike's
    centre inside the grown box (1.0, the look-alike's box overlapping it, holds the scale of a
    large target whose own parts give second peaks: MotorRolling 0.52 -> 0.33 AUC)."""
    distractor_ratio: float = 0.5
    """A second local maximum of the response at least this fraction of the first counts as a
    distractor (memory.distinct_peaks). 0.5: half the target's own peak, the level above which
    a response is read as multi-modal (a single target's sidelobes stay well below it)."""
    motion_prior: float = 0.0
    """With the long-term memory (without it the prior has nothing to weigh), weigh each
    distinct peak also by a constant-velocity prior:
    a Gaussian around the last confident frame's motion with this standard deviation, as a
    fraction of the target's short side (motion.MotionPrior); 0 = off. 0.5: the separation at
    which two peaks count as two objects, so a peak one such step further off the target's path
    needs 1.65x (e^0.5) the appearance evidence of the other."""
    rotation_step: float = 0.0
    """In-plane rotation (rotation.py): each frame the target is searched at its current angle
    and this many degrees either way, in patches sampled in the target's turned frame, and a
    turned angle is taken when its peak is higher by `rotation_margin` and its response as sharp
    (rotation.turn_wins); 0 = the release's axis-aligned patches. 10: half an
    fHOG orientation bin (20 degrees), the smallest turn that moves a gradient's energy into the
    neighbouring bin. In `autotrack+` since round 6 (docs/tracker.md)."""
    rotation_margin: float = 0.05
    """A turned sample is taken only when its peak exceeds the current angle's by this fraction
    (a prior that the target keeps its angle). 0.05: twice the median frame-to-frame change of
    the peak of `autotrack+` on the dev set (2.5 %), so a still target's noise rarely turns it."""
    num_aspects: int = 0
    """Width / height ratios sampled by the aspect filter (aspect.AspectFilter: DSST's scale
    filter along the other axis of the (width, height) scale space), `scale_step` apart; 0 = the
    release's fixed aspect. 17 = +-8 steps of 3 %: +-27 % per frame, the reach per frame of the
    33-scale filter's +-16 steps halved, since a turning target changes shape more slowly than
    the camera's zoom changes its size. Measured, not in `autotrack+` (docs/tracker.md)."""

    def __post_init__(self) -> None:
        from autotrack.errors import InputError

        problems = []
        if self.backend not in ("fast", "reference"):
            problems.append(f"backend must be 'fast' or 'reference', got {self.backend!r}")
        if self.cell_size < 1:
            problems.append("cell_size must be at least 1")
        if not self.search_area_scale > 0:
            problems.append("search_area_scale must be positive")
        if not 0 < self.min_image_sample_size <= self.max_image_sample_size:
            problems.append("need 0 < min_image_sample_size <= max_image_sample_size")
        if self.admm_iterations < 1 or self.newton_iterations < 0:
            problems.append("admm_iterations must be >= 1 and newton_iterations >= 0")
        if self.num_scales < 1 or not self.scale_step > 1:
            problems.append("num_scales must be >= 1 and scale_step > 1")
        if not 0 < self.variation_floor <= 1 or not 0 < self.confidence_memory <= 1:
            problems.append("variation_floor and confidence_memory must be in (0, 1]")
        if self.memory_margin < 0 or self.lookalike_reach < 0:
            problems.append("memory_margin and lookalike_reach must be >= 0")
        if not 0 <= self.memory_rate <= 1 or not 0 < self.distractor_ratio <= 1:
            problems.append("memory_rate must be in [0, 1] and distractor_ratio in (0, 1]")
        if self.num_aspects < 0 or self.velocity_weight < 0:
            problems.append("num_aspects and velocity_weight must be >= 0")
        if self.motion_prior < 0:
            problems.append("motion_prior must be >= 0")
        if not 0 <= self.rotation_step < 90 or self.rotation_margin < 0:
            problems.append("rotation_step must be in [0, 90) degrees, rotation_margin >= 0")
        if self.confidence_gate < 0 or self.redetect_span < 0 or self.scale_model_min_side < 0:
            problems.append("confidence_gate, redetect_span, scale_model_min_side must be >= 0")
        if self.redetect_patience < 1:
            problems.append("redetect_patience must be at least 1")
        if self.redetect_span and not (self.redetect_span > 1 and self.confidence_gate > 0):
            problems.append("redetect_span needs a confidence_gate and must be > 1")
        if self.colour_feature not in ("lab11", "table", "none"):
            problems.append(
                f"colour_feature must be 'lab11', 'table' or 'none', not {self.colour_feature!r}"
            )
        if self.theta_update not in ("release", "paper", "reference"):
            problems.append(
                f"theta_update must be 'release', 'paper' or 'reference', not {self.theta_update!r}"
            )
        if not (self.use_grey or self.use_fhog or self.colour_feature != "none"):
            problems.append("enable at least one feature")
        if problems:
            raise InputError("invalid tracker parameters: " + "; ".join(problems))

    @property
    def name(self) -> str:
        """Short label of the regularisation variant (for tables)."""
        if self.beyond_release:
            return "autotrack+"
        if self.adaptive_spatial and self.adaptive_temporal:
            return "autotrack"
        if self.adaptive_spatial:
            return "strcf+asr"
        if self.adaptive_temporal:
            return "strcf+atr"
        return "strcf"

    @property
    def beyond_release(self) -> bool:
        """True when any change beyond the authors' release is switched on."""
        return bool(
            self.robust_variation
            or self.acting_asr
            or self.confidence_gate
            or self.redetect_span
            or self.scale_model_min_side
            or self.num_aspects
            or self.velocity_weight
            or self.memory_rate
            or self.motion_prior
            or self.rotation_step
            or self.lookalike_reach
        )

    def with_colour_table(self, path: str | Path | None) -> TrackerParams:
        """The same parameters with the published Color Names table loaded from `path`."""
        if path is None:
            return self
        return replace(self, colour_feature="table", colour_table_path=str(path))


PRESETS: dict[str, TrackerParams] = {
    "autotrack": TrackerParams(),
    "strcf": TrackerParams(adaptive_spatial=False, adaptive_temporal=False),
    "strcf+asr": TrackerParams(adaptive_spatial=True, adaptive_temporal=False),
    "strcf+atr": TrackerParams(adaptive_spatial=False, adaptive_temporal=True),
    "autotrack+": TrackerParams(
        robust_variation=True,
        acting_asr=True,
        confidence_gate=0.7,
        redetect_span=3.0,
        redetect_patience=3,
        scale_model_min_side=16.0,
        memory_rate=0.01,
        rotation_step=10.0,
        lookalike_reach=0.5,
    ),
}
"""The paper's ablation (Table 2): STRCF baseline, +ASR, +ATR, the full AutoTrack (the authors'
release), and `autotrack+`: AutoTrack with the changes beyond the release (docs/tracker.md)."""


def preset(name: str, colour_table: str | Path | None = None) -> TrackerParams:
    """Parameters of a named preset, optionally with the published Color Names table."""
    key = name.strip().lower()
    if key not in PRESETS:
        from autotrack.errors import InputError

        raise InputError(f"unknown preset {name!r}; choose one of {', '.join(PRESETS)}")
    return PRESETS[key].with_colour_table(colour_table)
