"""A target's results by frame, kept as columns (`ResultHistory`).

A long run keeps every frame's box, search region and scalar signals but not a Python object
per frame: they live in one growable float64 array (capacity doubled when full), one row per
frame, beside a sorted column of frame indices. The results of the recent map window are kept
whole (maps included) in a small dict; any other frame's `TrackResult` is rebuilt on demand,
with no maps. It answers what a `dict[int, TrackResult]` did: `history[frame]`, `get`, `in`,
iteration over frames in order, `len`, `items()`; plus truncation after a frame (a target
re-tracked from a correction) and the columns themselves for plots and scores.
"""

from __future__ import annotations

import math
from collections.abc import Iterator, Mapping

import numpy as np

from autotrack.hybrid.factory import TRUSTED, trusted_code, with_trusted
from autotrack.result import TrackResult

INITIAL_CAPACITY = 64
"""Rows allocated before the first doubling."""

_BOX = slice(0, 4)
_SEARCH_BOX = slice(4, 8)
SCALAR_COLUMNS = ("peak_score", "global_variation", "theta_ref", "theta", "scale_factor")
"""The float fields of a TrackResult kept as columns (after the two boxes), in column order."""
_SCALAR = {name: 8 + offset for offset, name in enumerate(SCALAR_COLUMNS)}
_ABERRANT = 8 + len(SCALAR_COLUMNS)
_TRUSTED = _ABERRANT + 1
"""A hybrid result's `trusted` as its code (`autotrack.hybrid.factory.trusted_code`; NaN for
other trackers): a rebuilt result says whom the hybrid trusted."""
_WIDTH = _TRUSTED + 1
_NAN = math.nan
"""One NaN object for every rebuilt NaN field: rebuilt results compare equal (`==` on tuples
of fields tries identity first, and NaN != NaN)."""


class ResultHistory(Mapping[int, TrackResult]):
    """A target's results by 0-based frame index (see the module docstring)."""

    def __init__(self, capacity: int = INITIAL_CAPACITY) -> None:
        self._frames = np.zeros(max(capacity, 1), dtype=np.int64)
        self._values = np.zeros((max(capacity, 1), _WIDTH), dtype=np.float64)
        self._count = 0
        self._recent: dict[int, TrackResult] = {}
        self.maps_from = 0
        """Frames before this one keep no maps (`put`); the recording has them."""

    # -- writing ------------------------------------------------------------------------------

    def put(self, result: TrackResult, map_window: int) -> None:
        """`result` as the result on its frame; the results `map_window` or more frames before
        it lose their maps (0: its own too)."""
        frame_index = result.frame_index
        row = self._row(frame_index)
        if row is None:
            row = self._insert_row(frame_index)
        values = self._values[row]
        values[_BOX] = result.box
        values[_SEARCH_BOX] = result.search_box
        for name, column in _SCALAR.items():
            values[column] = getattr(result, name)
        values[_ABERRANT] = 1.0 if result.aberrant else 0.0
        values[_TRUSTED] = trusted_code(result)
        self._recent[frame_index] = result
        # Restarted before the window: the frames from here on are tracked afresh.
        first = min(self.maps_from, frame_index)
        self.maps_from = max(first, frame_index - map_window + 1)
        if self.maps_from - first <= len(self._recent):
            stale = range(first, self.maps_from)
        else:
            stale = [index for index in self._recent if index < self.maps_from]
        for index in stale:
            self._recent.pop(index, None)

    def truncate_after(self, frame_index: int) -> list[int]:
        """Drop the results after `frame_index`; the frames dropped, in order."""
        keep = int(np.searchsorted(self._frames[: self._count], frame_index, side="right"))
        dropped = self._frames[keep : self._count].tolist()
        self._count = keep
        for index in dropped:
            self._recent.pop(index, None)
        return dropped

    def _insert_row(self, frame_index: int) -> int:
        """A new row for `frame_index`, in frame order (appended unless earlier frames follow)."""
        if self._count == len(self._frames):
            self._frames = doubled(self._frames)
            self._values = doubled(self._values)
        row = int(np.searchsorted(self._frames[: self._count], frame_index))
        if row < self._count:  # before later frames: shift them down one row
            self._frames[row + 1 : self._count + 1] = self._frames[row : self._count]
            self._values[row + 1 : self._count + 1] = self._values[row : self._count]
        self._frames[row] = frame_index
        self._count += 1
        return row

    # -- reading ------------------------------------------------------------------------------

    def _row(self, frame_index: int) -> int | None:
        """The row of `frame_index` (None: no result there)."""
        count = self._count
        if count == 0:
            return None
        row = frame_index - int(self._frames[0])  # frames are usually consecutive
        if not 0 <= row < count or self._frames[row] != frame_index:
            row = int(np.searchsorted(self._frames[:count], frame_index))
            if row >= count or self._frames[row] != frame_index:
                return None
        return row

    def __getitem__(self, frame_index: int) -> TrackResult:
        kept = self._recent.get(frame_index)
        if kept is not None:
            return kept
        row = self._row(frame_index)
        if row is None:
            raise KeyError(frame_index)
        values = self._values[row].tolist()
        result = TrackResult(
            frame_index=int(frame_index),
            box=tuple(values[_BOX]),
            peak_score=_number(values[_SCALAR["peak_score"]]),
            response_map=None,
            local_variation=None,
            global_variation=_number(values[_SCALAR["global_variation"]]),
            theta_ref=_number(values[_SCALAR["theta_ref"]]),
            theta=_number(values[_SCALAR["theta"]]),
            aberrant=values[_ABERRANT] != 0.0,
            scale_factor=_number(values[_SCALAR["scale_factor"]]),
            search_box=tuple(values[_SEARCH_BOX]),
        )
        code = values[_TRUSTED]
        return result if code != code else with_trusted(result, TRUSTED[int(code)])

    def __contains__(self, frame_index: object) -> bool:
        return isinstance(frame_index, int | np.integer) and self._row(int(frame_index)) is not None

    def __iter__(self) -> Iterator[int]:
        return iter(self._frames[: self._count].tolist())

    def __len__(self) -> int:
        return self._count

    def __repr__(self) -> str:
        return f"ResultHistory({self._count} frames, maps from {self.maps_from})"

    @property
    def first_frame(self) -> int:
        """First frame with a result (-1: none)."""
        return int(self._frames[0]) if self._count else -1

    @property
    def last_frame(self) -> int:
        """Last frame with a result (-1: none)."""
        return int(self._frames[self._count - 1]) if self._count else -1

    @property
    def frames(self) -> np.ndarray:
        """The frames with a result, ascending (a read-only view)."""
        return _read_only(self._frames[: self._count])

    @property
    def boxes(self) -> np.ndarray:
        """The boxes (x, y, w, h) of those frames, one row each (a read-only view)."""
        return _read_only(self._values[: self._count, _BOX])

    @property
    def search_boxes(self) -> np.ndarray:
        """The search regions of those frames, one row each (a read-only view)."""
        return _read_only(self._values[: self._count, _SEARCH_BOX])

    @property
    def aberrant(self) -> np.ndarray:
        """Whether each of those frames was aberrant (a new array)."""
        return self._values[: self._count, _ABERRANT] != 0.0

    @property
    def trusted(self) -> np.ndarray:
        """Whom the hybrid trusted on each of those frames, as `trusted_code`s (NaN: another
        tracker; a read-only view)."""
        return _read_only(self._values[: self._count, _TRUSTED])

    def column(self, name: str) -> np.ndarray:
        """A scalar field (one of SCALAR_COLUMNS) over those frames (a read-only view)."""
        return _read_only(self._values[: self._count, _SCALAR[name]])

    @property
    def nbytes(self) -> int:
        """Bytes held by the columns (allocated capacity, the recent results' maps aside)."""
        return self._frames.nbytes + self._values.nbytes


def _number(value: float) -> float:
    return value if value == value else _NAN


def doubled(values: np.ndarray) -> np.ndarray:
    """`values` with twice its rows (the new ones zero): a growable column's next capacity, so
    appending n rows copies O(n) in all."""
    grown = np.zeros((2 * len(values), *values.shape[1:]), dtype=values.dtype)
    grown[: len(values)] = values
    return grown


def _read_only(view: np.ndarray) -> np.ndarray:
    view.flags.writeable = False
    return view
