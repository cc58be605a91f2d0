"""Beyond the release: the maths of the `autotrack+` preset's robust regularisation and gating.

Pure functions (plus one small running-average class) used by `AutoTrack` when the
corresponding `TrackerParams` switches are on; the faithful presets never call them.

- `robust_local_variation`: the local response variation of eq. 2 with its denominator floored
  at a fraction of the previous peak, so cells where the previous response was ~0 (everywhere
  away from the target) cannot blow up the variation.
- `acting_spatial_window`: ASR (eq. 3) rescaled so that delta * log(Pi + 1) is the relative
  attenuation of the h-step (eq. 12) instead of a term ~1e-6 of its denominator.
- `ResponseConfidence`: the detection peak and its APCE relative to their running averages
  (LMCF, Wang et al. CVPR 2017); below the gate the filter and the scale model are not updated
  and re-detection is tried.
"""

from __future__ import annotations

import math

import numpy as np

from autotrack.tracker import regularization


def robust_local_variation(
    response: np.ndarray,
    displacement: tuple[float, float],
    previous_response: np.ndarray,
    previous_displacement: tuple[float, float],
    floor: float,
) -> np.ndarray:
    """Local variation Pi (eq. 2) with the denominator floored: |R_t - R_t-1| / max(|R_t-1|, f).

    f = floor * max|R_t-1|. The release divides by |R_t-1| itself, which is ~0 away from the
    peak (the label is a Gaussian of a few cells), so Pi there is noise over noise. With the
    floor a cell's variation is its change relative to the previous peak wherever the previous
    response was weaker than `floor` of it, and Pi <= (|R_t| + |R_t-1|) / f stays bounded.
    Maps are aligned on their integer peaks and the result is centred as in eq. 2.
    """
    aligned, previous_aligned = regularization.centred_alignment(
        response, displacement, previous_response, previous_displacement
    )
    magnitude = np.abs(previous_aligned)
    denominator = np.maximum(
        magnitude, floor * float(np.max(magnitude)) + np.finfo(np.float32).tiny
    )
    variation = np.abs(aligned - previous_aligned) / denominator
    return variation.astype(np.float32, copy=False)


def acting_spatial_window(
    base_window: np.ndarray,
    variation_centred: np.ndarray,
    region: tuple[slice, slice],
    delta: float,
    reference_penalty: float,
    lambda_spatial: float,
    relative: bool = False,
) -> np.ndarray:
    """ASR (eq. 3) scaled so it changes what is learnt.

    The h-step (eq. 12) multiplies cell i of the filter by T / (lambda u_i^2 + gamma T). With
    u_i = delta log(Pi_i + 1) (release) that is 1 / (1 + ~1e-6): nothing. Here the target
    region gets u_i = delta log(Pi_i + 1) * sqrt(gamma_ref T / lambda), so in the h-step run at
    penalty gamma_ref cell i is attenuated by 1 / (1 + (delta log(Pi_i + 1))^2): the paper's
    delta becomes the weight of the variation against the data, and cells whose response varied
    wildly (partial occlusion, deformation) are learnt less. The tracker takes gamma_ref =
    gamma_init, the first h-step, where the spatial structure of the filter is set (the later
    ones run at 10x and 100x the penalty and mostly enforce g = h); scaled to the last h-step's
    penalty instead, u ~ 10-300 suppresses the whole target and the tracker drifts off at once.
    Outside the region u keeps the base value (the filter's support); non-finite Pi gets it too.
    """
    cells = base_window.shape[0] * base_window.shape[1]
    scale = math.sqrt(reference_penalty * cells / lambda_spatial)
    window = base_window.copy()
    with np.errstate(invalid="ignore", over="ignore"):
        log_variation = np.log(variation_centred[region].astype(np.float64) + 1.0)
        if relative:  # only what varied more than the target as a whole (a part, not a turn)
            log_variation = np.maximum(log_variation - np.nanmedian(log_variation), 0.0)
        values = delta * log_variation * scale
    floor = float(base_window[region].min())
    outside = float(base_window.max())
    values = np.where(np.isfinite(values), np.maximum(values, floor), outside)
    window[region] = values.astype(window.dtype)
    return window


def apce(response: np.ndarray) -> float:
    """Average peak-to-correlation energy |R_max - R_min|^2 / mean((R - R_min)^2) (LMCF eq. 9).

    High for one sharp peak over a flat floor, low for a flat or multi-peaked response.
    """
    low = float(np.min(response))
    energy = float(np.mean((response - low) ** 2))
    if energy <= 0 or not math.isfinite(energy):
        return 0.0
    return (float(np.max(response)) - low) ** 2 / energy


class ResponseConfidence:
    """Calibrated confidence of a detection: its peak and APCE against their running averages.

    LMCF (Wang et al., CVPR 2017) updates only when the peak is >= 0.7 and the APCE >= 0.45 of
    their historical means. APCE is quadratic in the peak height over a given sidelobe floor, so
    one gate g covers both: the confidence is min(peak / peak_ref, sqrt(APCE / APCE_ref)), in
    units of the usual peak, and a frame is confident when it is >= g (g = 0.7 gives LMCF's two
    thresholds, 0.7 and 0.49). `memory` is the exponential averaging rate (per frame); see
    `observe` for how frames below the gate enter the averages.
    """

    def __init__(self, memory: float) -> None:
        self.memory = memory
        self.peak_reference: float | None = None
        self.apce_reference: float | None = None
        self.frames_seen = 0

    @property
    def calibrated(self) -> bool:
        """Whether the averages span their own memory (1 / memory frames) yet."""
        return self.frames_seen * self.memory >= 1.0

    def confidence(self, peak: float, sharpness: float) -> float:
        """min(peak / peak_ref, sqrt(APCE / APCE_ref)); 0 if not finite, 1 until calibrated.

        Until the averages have seen 1 / memory frames they are a guess (one frame sets them),
        so every frame counts as confident and is learnt, as in the release.
        """
        if not (math.isfinite(peak) and math.isfinite(sharpness)):
            return 0.0
        if not self.calibrated or not self.peak_reference or not self.apce_reference:
            return 1.0
        return min(peak / self.peak_reference, math.sqrt(max(sharpness, 0.0) / self.apce_reference))

    def observe(self, peak: float, sharpness: float, gate: float) -> None:
        """Fold this frame into the averages, each clipped from below at the gate.

        A confident frame enters the plain running averages. A frame below the gate pulls each
        average down by at most memory * (1 - gate) (peak) or memory * (1 - gate^2) (APCE) of
        it per frame, so an appearance that stays changed for ~1 / (memory (1 - gate)) frames
        (10-20 with the defaults) is eventually accepted as the target's, while a passing
        occluder is not learnt.
        """
        if not (math.isfinite(peak) and math.isfinite(sharpness)):
            return
        self.frames_seen += 1
        if not self.peak_reference or not self.apce_reference:
            self.peak_reference, self.apce_reference = peak, sharpness
            return
        if not self.calibrated:  # plain mean of the first frames
            self.peak_reference += (peak - self.peak_reference) / self.frames_seen
            self.apce_reference += (sharpness - self.apce_reference) / self.frames_seen
            return
        rate = self.memory
        peak_target = max(peak, gate * self.peak_reference)
        apce_target = max(sharpness, gate**2 * self.apce_reference)
        self.peak_reference += rate * (peak_target - self.peak_reference)
        self.apce_reference += rate * (apce_target - self.apce_reference)
