"""How values are written into session messages: log times, NaN as null, quantised maps.

Shared by the recorder and the reader, so that both sides of each conversion sit together.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from autotrack.errors import SessionError
from autotrack.result import TrackResult
from autotrack.sessions.schemas import TargetStream

FORMAT_VERSION = 1
"""Version of the session layout this package writes and the newest it reads."""
SESSION_METADATA_NAME = "autotrack.session"
"""Name of the MCAP metadata record that marks a file as an AutoTrack session."""
DEFAULT_FPS = 10.0
"""Frame rate used for log times when the source does not give one (frames per second)."""
DEFAULT_FLUSH_INTERVAL_S = 1.0


def frame_time_ns(frame_index: int, fps: float) -> int:
    """Log time of a frame: its time in the video, frame_index / fps, in nanoseconds."""
    if int(frame_index) < 0:
        raise SessionError(f"frame index must be 0 or more, got {frame_index}")
    return round(int(frame_index) * 1e9 / float(fps))


def quantise_map(values: np.ndarray) -> tuple[np.ndarray, float, float]:
    """Min-max quantise a float map to uint8: q = round(255 * (v - lo) / (hi - lo)).

    Returns (q, lo, hi). A constant map gives q = 0 and lo = hi. Non-finite values map to 0.
    """
    values = np.asarray(values, dtype=np.float64)
    finite = np.isfinite(values)
    if not finite.any():
        return np.zeros(values.shape, dtype=np.uint8), math.nan, math.nan
    lo = float(values[finite].min())
    hi = float(values[finite].max())
    span = hi - lo
    if span <= 0.0:
        return np.zeros(values.shape, dtype=np.uint8), lo, hi
    scaled = np.where(finite, (values - lo) / span * 255.0, 0.0)
    return np.clip(np.rint(scaled), 0, 255).astype(np.uint8), lo, hi


def dequantise_map(quantised: np.ndarray, lo: float, hi: float) -> np.ndarray:
    """Inverse of `quantise_map` (to within (hi - lo) / 510): v = lo + q / 255 * (hi - lo)."""
    q = np.asarray(quantised, dtype=np.float32)
    return (np.float32(lo) + q / np.float32(255.0) * np.float32(hi - lo)).astype(np.float32)


MAP_STREAMS = (TargetStream.RESPONSE, TargetStream.LOCAL_VARIATION, TargetStream.SPATIAL_WINDOW)
"""A target's map streams, in the order they are recorded."""
RANGE_FIELDS = {stream: f"{stream.value}_range" for stream in MAP_STREAMS}
"""Map stream -> the signals field holding its quantisation range [lo, hi]."""


def map_of(result: TrackResult, stream: TargetStream) -> np.ndarray | None:
    """The map of `result` a map stream records, as quantised: the spatial weights in log10
    (they span decades, and the app shows them so); None when the result has none."""
    if stream is TargetStream.RESPONSE:
        return result.response_map
    if stream is TargetStream.LOCAL_VARIATION:
        return result.local_variation
    weights = result.spatial_window
    if weights is None:
        return None
    positive = np.asarray(weights, dtype=np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.log10(np.where(positive > 0, positive, np.nan))


def recorded_map(stream: TargetStream, quantised: np.ndarray, lo: float, hi: float) -> np.ndarray:
    """The float32 map a map stream's mono8 image and range stand for (inverse of `map_of`
    and `quantise_map`)."""
    values = dequantise_map(quantised, lo, hi)
    if stream is TargetStream.SPATIAL_WINDOW:
        return np.power(np.float32(10.0), values).astype(np.float32)
    return values


def finite_or_none(value: Any) -> float | None:
    if value is None:
        return None
    number = float(value)
    return number if math.isfinite(number) else None


def none_to_nan(value: Any) -> float:
    return math.nan if value is None else float(value)


def jsonable(value: Any) -> Any:
    """Plain JSON data from numpy scalars/arrays, tuples and NaN (-> null)."""
    if isinstance(value, Mapping):
        return {str(key): jsonable(item) for key, item in value.items()}
    if isinstance(value, np.ndarray):
        return jsonable(value.tolist())
    if isinstance(value, list | tuple | set | frozenset):
        return [jsonable(item) for item in value]
    if isinstance(value, bool | np.bool_):
        return bool(value)
    if isinstance(value, int | np.integer):
        return int(value)
    if isinstance(value, float | np.floating):
        return finite_or_none(value)
    if value is None or isinstance(value, str):
        return value
    if isinstance(value, Path):
        return str(value)
    raise SessionError(f"cannot record a value of type {type(value).__name__} ({value!r}) in JSON")


def encode_json(payload: Mapping[str, Any]) -> bytes:
    return json.dumps(payload, separators=(",", ":"), allow_nan=False).encode("utf-8")


def box_tuple(values: Sequence[float | None]) -> tuple[float, float, float, float]:
    x, y, w, h = (none_to_nan(v) for v in values)
    return (x, y, w, h)


def box_list(box: Sequence[float]) -> list[float]:
    values = [float(v) for v in box]
    if len(values) != 4:
        raise SessionError(f"a box needs 4 numbers (x, y, w, h), got {len(values)}")
    return values
