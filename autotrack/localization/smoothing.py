"""Temporal consistency of the camera trajectory: a constant-velocity Kalman filter on the pose,
with an optional fixed-lag Rauch-Tung-Striebel smoother on top.

Each of the seven pose coordinates (position x, y, z and the unit quaternion, kept in one
hemisphere so it varies continuously) is an independent constant-velocity state [value, rate]
driven by white acceleration noise (Bar-Shalom's discretised continuous white-noise model).
Position measurements carry the pose's own predicted uncertainty (`PoseEstimate.position_std_m`,
scaled), so ill-conditioned poses count less. The quaternion is renormalised on output.

Latency: with `lag_frames` = 0 the output of frame k is the filtered pose from frames <= k (no
delay, but it lags fast manoeuvres a little); with `lag_frames` = L it is the RTS-smoothed pose
of frame k using frames <= k + L, available L frames (L / fps seconds) later. Frames without a
trusted pose are bridged by prediction but stay flagged invalid: the smoother never invents a
pose where the solver had none, and a gap longer than `max_gap_frames` restarts it.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from autotrack.errors import InputError


@dataclass(frozen=True)
class SmootherParams:
    """Noise model and latency of the pose smoother. Rates are per second of sequence time."""

    fps: float = 10.0
    """Frame rate of the sequence (frames per second)."""
    lag_frames: int = 3
    """Fixed lag L of the RTS smoother (frames); the output of frame k needs frames up to k + L.
    0 = causal Kalman filter, no latency."""
    position_acceleration: float = 2.0
    """Spectral density of the white acceleration noise on each position axis, (m/s^2)^2 / Hz:
    how fast the velocity may change (a UAV's wobble needs a few m/s^2)."""
    rotation_acceleration: float = 0.5
    """The same on each quaternion component (1/s^2)^2 / Hz."""
    position_noise_scale: float = 0.6
    """Position measurement sigma = this x the pose's predicted `position_std_m` (which assumes
    1 px image noise) per axis; refined points are better than 1 px."""
    min_position_noise_m: float = 0.002
    """Floor of the position measurement sigma (metres, per axis)."""
    quaternion_noise: float = 0.001
    """Measurement sigma of each quaternion component (~0.1 deg)."""
    max_gap_frames: int = 5
    """A run of more invalid frames than this restarts the filter from the next trusted pose."""

    def __post_init__(self) -> None:
        if not self.fps > 0:
            raise InputError(f"fps must be positive, got {self.fps}")
        if self.lag_frames < 0:
            raise InputError(f"lag_frames must be >= 0, got {self.lag_frames}")

    @property
    def latency_s(self) -> float:
        """Delay between a frame and its smoothed pose (seconds)."""
        return self.lag_frames / self.fps


@dataclass(frozen=True)
class PoseSample:
    """One frame's pose as the smoother sees it (the raw estimate or a smoothed one)."""

    frame_index: int
    """0-based frame index."""
    valid: bool
    """False when the frame has no trusted pose (NaN position and quaternion)."""
    position: np.ndarray
    """Camera centre (3,), metres."""
    quaternion_xyzw: np.ndarray
    """Camera-to-world rotation as a unit quaternion (4,), TUM order."""
    position_std_m: float = math.nan
    """Predicted 1-sigma position uncertainty of the raw pose (metres, all axes together)."""

    @property
    def rotation(self) -> np.ndarray:
        """Camera-to-world rotation matrix (NaN when invalid)."""
        if not self.valid:
            return np.full((3, 3), np.nan)
        from scipy.spatial.transform import Rotation  # scipy.spatial loads on first use (~0.4 s)

        return Rotation.from_quat(self.quaternion_xyzw).as_matrix()


def constant_velocity_model(dt: float, spectral_density: float) -> tuple[np.ndarray, np.ndarray]:
    """Transition F and process covariance Q of a 1-D constant-velocity state over `dt` seconds
    driven by continuous white acceleration noise of `spectral_density`."""
    transition = np.array([[1.0, dt], [0.0, 1.0]])
    noise = spectral_density * np.array([[dt**3 / 3.0, dt**2 / 2.0], [dt**2 / 2.0, dt]])
    return transition, noise


@dataclass
class _Step:
    sample: PoseSample
    mean_pred: np.ndarray  # (7, 2) predicted state before the measurement
    cov_pred: np.ndarray  # (7, 2, 2)
    mean: np.ndarray  # (7, 2) filtered state
    cov: np.ndarray  # (7, 2, 2)


@dataclass
class PoseSmoother:
    """Online fixed-lag smoother: `push` each frame's raw pose in order; smoothed samples come out
    `lag_frames` later (`flush` at the end returns the rest)."""

    params: SmootherParams = field(default_factory=SmootherParams)
    _window: deque[_Step] = field(default_factory=deque, init=False, repr=False)
    _last: _Step | None = field(default=None, init=False, repr=False)
    _gap: int = field(default=0, init=False, repr=False)
    _last_quaternion: np.ndarray | None = field(default=None, init=False, repr=False)

    def push(self, sample: PoseSample) -> list[PoseSample]:
        """Add the next frame; returns the smoothed samples that became final (0 or more)."""
        out: list[PoseSample] = []
        if not sample.valid:
            self._gap += 1
            if self._gap > self.params.max_gap_frames and self._last is not None:
                out += self.flush()
        elif self._gap > self.params.max_gap_frames:
            out += self.flush()
        if sample.valid:
            self._gap = 0
        step = self._filter(sample)
        if step is None:  # no running filter: nothing to smooth
            out.append(sample)
            return out
        self._last = step
        self._window.append(step)
        if len(self._window) > self.params.lag_frames:
            out.append(self._smoothed_oldest())
            self._window.popleft()
        return out

    def flush(self) -> list[PoseSample]:
        """Smooth and return everything still buffered; the filter restarts afterwards."""
        out = []
        while self._window:
            out.append(self._smoothed_oldest())
            self._window.popleft()
        self._last = None
        self._last_quaternion = None
        return out

    # -- internals ----------------------------------------------------------------------------

    def _measurement(self, sample: PoseSample) -> tuple[np.ndarray, np.ndarray]:
        params = self.params
        quaternion = np.asarray(sample.quaternion_xyzw, dtype=np.float64)
        if self._last_quaternion is not None and quaternion @ self._last_quaternion < 0:
            quaternion = -quaternion  # same rotation, continuous sign
        self._last_quaternion = quaternion
        std = sample.position_std_m
        per_axis = params.position_noise_scale * std / math.sqrt(3.0) if math.isfinite(std) else 0
        sigma_p = max(per_axis, params.min_position_noise_m)
        values = np.concatenate([np.asarray(sample.position, dtype=np.float64), quaternion])
        variances = np.array([sigma_p**2] * 3 + [params.quaternion_noise**2] * 4)
        return values, variances

    def _filter(self, sample: PoseSample) -> _Step | None:
        params = self.params
        if self._last is None:
            if not sample.valid:
                return None
            values, variances = self._measurement(sample)
            mean = np.stack([values, np.zeros(7)], axis=1)
            # Unknown initial rates: a wide prior (1 m/s, 1/s).
            cov = np.zeros((7, 2, 2))
            cov[:, 0, 0] = variances
            cov[:, 1, 1] = 1.0
            return _Step(sample, mean, cov, mean, cov)
        previous = self._last
        dt = (sample.frame_index - previous.sample.frame_index) / params.fps
        f_pos, q_pos = constant_velocity_model(dt, params.position_acceleration)
        _, q_rot = constant_velocity_model(dt, params.rotation_acceleration)
        process = np.stack([q_pos] * 3 + [q_rot] * 4)
        mean_pred = previous.mean @ f_pos.T
        cov_pred = f_pos @ previous.cov @ f_pos.T + process
        if not sample.valid:
            return _Step(sample, mean_pred, cov_pred, mean_pred, cov_pred)
        values, variances = self._measurement(sample)
        innovation = values - mean_pred[:, 0]
        total = cov_pred[:, 0, 0] + variances
        gain = cov_pred[:, :, 0] / total[:, None]  # (7, 2)
        mean = mean_pred + gain * innovation[:, None]
        cov = cov_pred - gain[:, :, None] * cov_pred[:, 0, None, :]
        return _Step(sample, mean_pred, cov_pred, mean, cov)

    def _smoothed_oldest(self) -> PoseSample:
        """RTS backward pass of the means over the window down to its oldest step (the output
        is a pose, so the smoothed covariance, which the means do not need, is not formed)."""
        steps = list(self._window)
        mean = steps[-1].mean
        for k in range(len(steps) - 2, -1, -1):
            current, following = steps[k], steps[k + 1]
            dt = (following.sample.frame_index - current.sample.frame_index) / self.params.fps
            transition, _ = constant_velocity_model(dt, 0.0)
            # C = P_k F^T (P_{k+1|k})^-1, per coordinate
            gain = current.cov @ transition.T @ np.linalg.inv(following.cov_pred)
            mean = current.mean + np.einsum("nij,nj->ni", gain, mean - following.mean_pred)
        oldest = steps[0].sample
        if not oldest.valid:
            return oldest
        quaternion = mean[3:, 0] / np.linalg.norm(mean[3:, 0])
        return replace(oldest, position=mean[:3, 0].copy(), quaternion_xyzw=quaternion)


def smooth_poses(samples: Iterable[PoseSample], params: SmootherParams) -> Iterator[PoseSample]:
    """The smoothed trajectory of a whole sequence, one sample per input sample, in order."""
    smoother = PoseSmoother(params)
    for sample in samples:
        yield from smoother.push(sample)
    yield from smoother.flush()


def samples_from_poses(poses: Sequence) -> list[PoseSample]:
    """PoseSamples of `PoseEstimate`s (anything with frame_index, valid, position,
    quaternion_xyzw() and position_std_m)."""
    return [
        PoseSample(
            frame_index=p.frame_index,
            valid=bool(p.valid),
            position=np.asarray(p.position, dtype=np.float64),
            quaternion_xyzw=np.asarray(p.quaternion_xyzw(), dtype=np.float64),
            position_std_m=float(p.position_std_m),
        )
        for p in poses
    ]


def smoothed_positions(
    poses: Mapping[int, object], params: SmootherParams
) -> list[tuple[int, np.ndarray]]:
    """(frame index, smoothed camera position) of the valid frames of `poses` (frame index ->
    PoseEstimate), in frame order: the smoothed counterpart of a raw trajectory."""
    samples = samples_from_poses([poses[index] for index in sorted(poses)])
    return [(s.frame_index, s.position) for s in smooth_poses(samples, params) if s.valid]
