"""Live uPlot charts of the tracker's signals over frames, one series per target.

Frames without a value hold NaN, which uPlot cannot range over (a NaN anywhere on a scale
leaves the chart empty) but skips when drawing a line or a point. So every chart gets an
explicit y range fitted to the finite values it shows (rounded outward, so it changes only
when the data leaves it). The global variation η is on a log scale whose range always holds
the threshold φ, so one spike cannot hide φ. Aberrant frames are a points-only red series; a
grey vertical line marks the current frame (two extra x points just after it carry the line,
the other series repeat the current frame's value there).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import viser
import viser.uplot

from app.views import SignalHistory

ABERRANT_COLOUR = "#e03131"
CURSOR_COLOUR = "#495057"
CURSOR_OFFSETS = (1e-3, 2e-3)
"""Where, after the current frame's x, the two points of the cursor line sit (frames)."""
X_STEP = 50
"""The x axis ends at the next multiple of this many frames past the data shown."""
CHART_PADDING = (12, 12, 0, 0)
"""Space (top, right, bottom, left; CSS px) around a chart so its top tick label is not cut."""
CHART_TITLES = ("Peak score", "Global variation η (log) vs φ", "θ_ref (dots) and θ", "Speed")


def x_range(last: int, frame_count: int) -> tuple[float, float]:
    """Frames 0 .. the next multiple of X_STEP past `last` (at most the sequence's end), so the
    charts fill up as the run advances and rescale only every X_STEP frames."""
    end = min(frame_count - 1, (last // X_STEP + 1) * X_STEP)
    return (0.0, float(max(end, 1)))


def _finite(arrays: Sequence[np.ndarray]) -> np.ndarray:
    values = [a[np.isfinite(a)] for a in arrays]
    return np.concatenate(values) if values else np.zeros(0)


def y_range(arrays: Sequence[np.ndarray]) -> tuple[float, float]:
    """A range holding every finite value with 10% headroom, rounded outward to a tenth of the
    span's order of magnitude ((0, 1) before any value)."""
    values = _finite(arrays)
    if values.size == 0:
        return (0.0, 1.0)
    low, high = float(values.min()), float(values.max())
    span = max(high - low, 1e-6, 1e-3 * max(abs(low), abs(high)))
    low, high = low - 0.1 * span, high + 0.1 * span
    step = 10.0 ** np.floor(np.log10(span)) / 10.0
    return (float(np.floor(low / step) * step), float(np.ceil(high / step) * step))


def log_range(arrays: Sequence[np.ndarray], keep: float) -> tuple[float, float]:
    """Whole decades holding every positive finite value and `keep` (the threshold φ)."""
    values = _finite(arrays)
    values = np.append(values[values > 0], keep)
    low = 10.0 ** math.floor(math.log10(float(values.min())))
    high = 10.0 ** math.ceil(math.log10(float(values.max())))
    return (low, high if high > low else low * 10.0)


def with_cursor(
    count: int, series: Sequence[np.ndarray], cursor: int, span: tuple[float, float]
) -> tuple[np.ndarray, ...]:
    """(x, *series, cursor line) over frames 0..count-1 with the cursor's two points inserted
    just after frame `cursor`; the line spans `span`."""
    frames = np.arange(count, dtype=np.float64)
    at = min(max(cursor, 0), count - 1) + 1
    x = np.concatenate([frames[:at], at - 1 + np.array(CURSOR_OFFSETS), frames[at:]])
    out = [x]
    for values in series:
        repeated = np.repeat(values[at - 1 : at], len(CURSOR_OFFSETS))
        out.append(np.concatenate([values[:at], repeated, values[at:]]))
    line = np.full(len(x), np.nan)
    line[at : at + len(CURSOR_OFFSETS)] = span
    out.append(line)
    return tuple(out)


def _css(colour: tuple[int, int, int]) -> str:
    return "#{:02x}{:02x}{:02x}".format(*colour)


def line_series(
    label: str, colour: str, dash: tuple[float, ...] | None = None
) -> viser.uplot.Series:
    series = viser.uplot.Series(label=label, stroke=colour, width=1.5)
    if dash is not None:
        series["dash"] = dash
    return series


def _points(label: str, colour: str, size: float) -> viser.uplot.Series:
    return viser.uplot.Series(
        label=label,
        stroke=colour,
        width=0,
        points=viser.uplot.Series_Points(show=True, size=size, fill=colour),
    )


def cursor_series() -> viser.uplot.Series:
    return viser.uplot.Series(label="now", stroke=CURSOR_COLOUR, width=1.0)


def _aberrant_values(history: SignalHistory, signal: str, count: int) -> np.ndarray:
    """The largest `signal` value among targets aberrant on each frame, NaN elsewhere."""
    marked = np.full(count, np.nan)
    for target_id in history.target_ids:
        values = history.signals[target_id]
        flagged = values["aberrant"][:count] == 1.0
        candidate = np.where(flagged, values[signal][:count], np.nan)
        marked = np.fmax(marked, candidate)
    return marked


def _rate(seconds: np.ndarray) -> np.ndarray:
    with np.errstate(divide="ignore", invalid="ignore"):
        rate = 1.0 / seconds
    return np.where(np.isfinite(rate), rate, np.nan)


def chart_series(history: SignalHistory, count: int) -> list[list[np.ndarray]]:
    """The values of each chart (in CHART_TITLES order) over frames 0..count-1."""
    ids = history.target_ids

    def signal(name: str) -> list[np.ndarray]:
        return [history.signals[tid][name][:count] for tid in ids]

    eta = [np.where(v > 0, v, np.nan) for v in signal("global_variation")]
    theta: list[np.ndarray] = []
    for tid in ids:
        theta += [history.signals[tid]["theta_ref"][:count], history.signals[tid]["theta"][:count]]
    aberrant_eta = _aberrant_values(history, "global_variation", count)
    return [
        [*signal("peak_score"), _aberrant_values(history, "peak_score", count)],
        [*eta, np.full(count, history.phi), np.where(aberrant_eta > 0, aberrant_eta, np.nan)],
        theta,
        [_rate(history.frame_seconds[:count]), _rate(history.play_seconds[:count])],
    ]


class SignalPlots:
    """The four charts of a tab: peak score, global variation vs phi, theta_ref/theta, speed."""

    def __init__(self, gui: viser.GuiApi, container: viser.GuiTabHandle | None = None) -> None:
        self.gui = gui
        self._layout: tuple[str, ...] | None = None
        """Target ids the charts were built for (not the frame count: a live source's grows
        with every frame, and the x range is sent with each update)."""
        self._handles: list[viser.GuiUplotHandle] = []
        self._scales: list[dict | None] = []
        self._container = container if container is not None else gui.add_folder("Plots")
        with self._container:
            self._hint = gui.add_markdown("The charts appear once a target is drawn.")

    def _build(self, history: SignalHistory) -> None:
        for handle in self._handles:
            handle.remove()
        colours = [_css(colour) for colour in history.colours]
        pairs = list(zip(history.target_ids, colours, strict=True))
        theta: list[viser.uplot.Series] = []
        for tid, colour in pairs:
            theta += [_points(f"{tid} θref", colour, 4), line_series(f"{tid} θ", colour)]
        series = (
            [*(line_series(tid, c) for tid, c in pairs), _points("aberrant", ABERRANT_COLOUR, 7)],
            [
                *(line_series(f"{tid} η", c) for tid, c in pairs),
                line_series("φ", "#868e96", dash=(6.0, 4.0)),
                _points("aberrant", ABERRANT_COLOUR, 7),
            ],
            theta,
            [line_series("trackers fps", "#1971c2"), line_series("in-app fps", "#2f9e44")],
        )
        handles = []
        with self._container:
            for title, chart in zip(CHART_TITLES, series, strict=True):
                empty = np.zeros(1)
                handles.append(
                    self.gui.add_uplot(
                        data=(empty, *[empty] * (len(chart) + 1)),
                        series=(viser.uplot.Series(label="frame"), *chart, cursor_series()),
                        title=title,
                        aspect=2.0,
                        padding=CHART_PADDING,
                    )
                )
        self._handles = handles
        self._scales = [None] * len(handles)
        self._layout = history.target_ids

    def update(self, history: SignalHistory, cursor: int) -> None:
        """Send the latest values and the cursor at frame `cursor` (rebuilding the charts when
        the target list changed)."""
        if self._hint.visible != (not history.target_ids):
            self._hint.visible = not history.target_ids
        if not history.target_ids:
            for handle in self._handles:
                handle.remove()
            self._handles = []
            self._layout = None
            return
        if history.target_ids != self._layout:
            self._build(history)
        last = max(history.last_frame, cursor, 0)
        count = last + 1
        x_scale = {"time": False, "auto": False, "range": x_range(last, history.frame_count)}
        for index, (handle, series) in enumerate(
            zip(self._handles, chart_series(history, count), strict=True)
        ):
            if index == 1:
                span = log_range(series, history.phi)
                y_scale = {"distr": 3, "log": 10, "auto": False, "range": span}
            else:
                span = y_range(series)
                y_scale = {"auto": False, "range": span}
            scales = {"x": x_scale, "y": y_scale}
            if scales != self._scales[index]:
                handle.scales = scales
                self._scales[index] = scales
            handle.data = with_cursor(count, series, cursor, span)

    def data_of(self, index: int) -> Sequence[np.ndarray] | None:
        """The data last sent to chart `index` (CHART_TITLES order)."""
        if not self._handles:
            return None
        return self._handles[index].data

    def y_scale_of(self, index: int) -> dict | None:
        """The y scale last sent to chart `index`."""
        scales = self._scales[index] if index < len(self._scales) else None
        return None if scales is None else scales["y"]
