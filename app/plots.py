"""Live uPlot charts of the tracker's signals over frames, one series per target slot.

The charts are made once per tab, with one series per target number (T1 .. T<max targets>, in
the targets' colours), and only their data and scales change afterwards: a chart made again
is drawn before its panel has its width and flashes narrow. A slot without a target holds no
values.

Frames without a value are sent as null, which uPlot draws as a gap (it would draw a NaN
line across); a frame nothing was tracked on (a live source's dropped frame) gets no row at
all, so the lines join the tracked frames on either side. Every chart gets an explicit y range
fitted to the finite values it shows (rounded outward, so it changes only when the data
leaves it); a flat signal gets a range of ±10% around its value. The global variation η is on
a log scale whose range always holds the threshold φ, so one spike cannot hide φ, with one
labelled grid line per decade. Aberrant frames are a points-only red series; a grey vertical
line marks the current frame (two extra x points just after it carry the line, the other
series repeat the current frame's value there).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
import viser
import viser.uplot

from autotrack_studio.canvas import target_colour
from autotrack_studio.views import SignalHistory
from autotrack_studio.viser_private import send_uplot_data

ABERRANT_COLOUR = "#e03131"
CURSOR_COLOUR = "#495057"
CURSOR_OFFSETS = (1e-3, 2e-3)
"""Where, after the current frame's x, the two points of the cursor line sit (frames)."""
X_STEP = 50
"""The x axis ends at the next multiple of this many frames past the data shown."""
CHART_PADDING = (12, 12, 0, 0)
"""Space (top, right, bottom, left; CSS px) around a chart so its top tick label is not cut."""
CHART_TITLES = ("Peak score", "Global variation η (log) vs φ", "θ_ref (dots) and θ", "Speed")
FLAT_MARGIN = 0.1
"""Half-height of a flat signal's range, as a fraction of its value (±1 around zero)."""
ETA_CHART = CHART_TITLES.index("Global variation η (log) vs φ")

Chart = tuple[np.ndarray | list[float | None], ...]

EMPTY_SCALES = {"x": {"time": False, "auto": False, "range": (1.0, float(X_STEP))}}
"""The scales a chart is made with, before it has data: frame numbers on x (uPlot's default x
scale is time, which labels an empty chart with dates of 1970)."""


def frame_numbers(frame_indices: np.ndarray) -> np.ndarray:
    """The x values of 0-based frame indices: the frame numbers a person reads (1-based, as
    the Frame slider, the status line and the Targets table), so a chart's hover names the
    frame the slider shows."""
    return np.asarray(frame_indices, dtype=float) + 1.0


def x_range(last: int, frame_count: int) -> tuple[float, float]:
    """Frame numbers 1 .. the next multiple of X_STEP past frame `last` (0-based; at most the
    sequence's end), so the charts fill up as the run advances and rescale only every X_STEP
    frames; on the last frame, just past it, so the current-frame line drawn after it stays
    in view."""
    number = last + 1
    end = min(frame_count, (number // X_STEP + 1) * X_STEP)
    return (1.0, float(max(end, 2, number + 2 * CURSOR_OFFSETS[-1])))


def _finite(arrays: Sequence[np.ndarray]) -> np.ndarray:
    values = [a[np.isfinite(a)] for a in arrays]
    return np.concatenate(values) if values else np.zeros(0)


def y_range(arrays: Sequence[np.ndarray]) -> tuple[float, float]:
    """A range holding every finite value with 10% headroom, rounded outward to a tenth of the
    span's order of magnitude ((0, 1) before any value; ±FLAT_MARGIN around a flat signal)."""
    values = _finite(arrays)
    if values.size == 0:
        return (0.0, 1.0)
    low, high = float(values.min()), float(values.max())
    if high - low <= 1e-3 * max(abs(low), abs(high)):  # flat: the ticks need a real span
        centre = 0.5 * (low + high)
        half = FLAT_MARGIN * abs(centre) if centre != 0.0 else 1.0
        low, high = centre - half, centre + half
    span = high - low
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


def decade_label(exponent: int) -> str:
    """How the log axis labels 10**exponent: 0.1, 1, 10 and 100 plainly, others as 1e-3."""
    return f"{10.0**exponent:g}" if -1 <= exponent <= 2 else f"1e{exponent}"


def decade_axis(span: tuple[float, float]) -> viser.uplot.Axis:
    """A y axis with one tick, grid line and label per decade of `span` (whole decades)."""
    first, last = (round(math.log10(bound)) for bound in span)
    exponents = range(first, last + 1)
    return viser.uplot.Axis(
        splits=tuple(10.0**k for k in exponents),
        values=tuple(decade_label(k) for k in exponents),
    )


def with_gaps(values: np.ndarray) -> list[float | None]:
    """`values` with null (None) for the frames without one: uPlot breaks its line there."""
    return [float(v) if math.isfinite(v) else None for v in values.tolist()]


def with_cursor(
    count: int,
    series: Sequence[np.ndarray],
    cursor: int,
    span: tuple[float, float],
    frames: np.ndarray | None = None,
) -> tuple[np.ndarray, ...]:
    """(x, *series, cursor line) over `frames` (0-based indices, default: every frame
    0..count-1; it must hold the cursor's frame) with the cursor's two points inserted just
    after frame `cursor`; the line spans `span`. x holds frame numbers (`frame_numbers`)."""
    cursor = min(max(cursor, 0), count - 1)
    rows = np.arange(count) if frames is None else np.asarray(frames, dtype=np.int64)
    at = int(np.searchsorted(rows, cursor, side="right"))
    x = frame_numbers(np.concatenate([rows[:at], cursor + np.array(CURSOR_OFFSETS), rows[at:]]))
    out = [x]
    for values in series:
        shown = values[rows]
        repeated = np.repeat(values[cursor : cursor + 1], len(CURSOR_OFFSETS))
        out.append(np.concatenate([shown[:at], repeated, shown[at:]]))
    line = np.full(len(x), np.nan)
    line[at : at + len(CURSOR_OFFSETS)] = span
    out.append(line)
    return tuple(out)


def tracked_rows(history: SignalHistory, count: int, cursor: int) -> np.ndarray:
    """The frames 0..count-1 the charts give a row: those some target has a value on or the
    trackers ran on, and the cursor's. A frame nothing was tracked on (a live source's dropped
    frame) gets none, so the lines join the frames either side instead of breaking into
    fragments too short to see; a target without a value on a row still breaks its line."""
    tracked = np.isfinite(history.frame_seconds[:count])
    for target_id in history.target_ids:
        for values in history.signals[target_id].values():
            tracked |= np.isfinite(values[:count])
    tracked[min(max(cursor, 0), count - 1)] = True
    return np.flatnonzero(tracked)


def chart_data(
    count: int,
    series: Sequence[np.ndarray],
    cursor: int,
    span: tuple[float, float],
    frames: np.ndarray | None = None,
) -> Chart:
    """What a chart is sent: `with_cursor`'s arrays, the y series with null gaps."""
    x, *ys = with_cursor(count, series, cursor, span, frames)
    return (x, *(with_gaps(values) for values in ys))


def send_data(handle: viser.GuiUplotHandle, data: Chart) -> None:
    """Assign a chart's data keeping its nulls. Assigning `handle.data` casts every series to
    a float64 array, null becoming NaN again, so the data is sent past that cast
    (app/viser_private.py)."""
    send_uplot_data(handle, data)


def _css(colour: tuple[int, int, int]) -> str:
    return "#{:02x}{:02x}{:02x}".format(*colour)


def line_series(
    label: str, colour: str, dash: tuple[float, ...] | None = None, slot: str | None = None
) -> viser.uplot.Series:
    """A line; `slot`: the target id it plots (its legend entry is hidden while that target
    does not exist, see `legend_style`)."""
    series = viser.uplot.Series(label=label, stroke=colour, width=1.5)
    if dash is not None:
        series["dash"] = dash
    if slot is not None:
        series["class"] = slot_class(slot)
    return series


def slot_class(target_id: str) -> str:
    """The CSS class of a target's series (uPlot puts it on their legend entries)."""
    return f"autotrack-slot-{target_id}"


def legend_style(absent: Sequence[str]) -> str:
    """A style sheet hiding the legend entries of the targets `absent` (empty: none hidden).
    The charts are made once with a series per target number; this keeps their legends to the
    targets that exist without making the charts again."""
    if not absent:
        return ""
    selectors = ", ".join(f".uplot .u-legend .{slot_class(tid)}" for tid in absent)
    return f"<style>{selectors} {{ display: none; }}</style>"


def _points(label: str, colour: str, size: float, slot: str | None = None) -> viser.uplot.Series:
    series = viser.uplot.Series(
        label=label,
        stroke=colour,
        width=0,
        points=viser.uplot.Series_Points(show=True, size=size, fill=colour),
    )
    if slot is not None:
        series["class"] = slot_class(slot)
    return series


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


def slot_ids(history: SignalHistory, slots: int) -> tuple[str, ...]:
    """The target ids the charts have series for: T1 .. T<slots>, or, when a run has other
    ids (a session recorded elsewhere), its own."""
    numbered = tuple(f"T{number}" for number in range(1, slots + 1))
    return numbered if set(history.target_ids) <= set(numbered) else history.target_ids


def chart_series(
    history: SignalHistory, count: int, ids: Sequence[str] | None = None
) -> list[list[np.ndarray]]:
    """The values of each chart (in CHART_TITLES order) over frames 0..count-1, one series per
    id of `ids` (default: the run's targets; NaN for an id without a target)."""
    ids = history.target_ids if ids is None else ids
    missing = np.full(count, np.nan)

    def signal(tid: str, name: str) -> np.ndarray:
        return history.signals[tid][name][:count] if tid in history.signals else missing

    eta = [np.where(v > 0, v, np.nan) for v in (signal(t, "global_variation") for t in ids)]
    theta: list[np.ndarray] = []
    for tid in ids:
        theta += [signal(tid, "theta_ref"), signal(tid, "theta")]
    aberrant_eta = _aberrant_values(history, "global_variation", count)
    return [
        [*(signal(t, "peak_score") for t in ids), _aberrant_values(history, "peak_score", count)],
        [*eta, np.full(count, history.phi), np.where(aberrant_eta > 0, aberrant_eta, np.nan)],
        theta,
        [_rate(history.frame_seconds[:count]), _rate(history.play_seconds[:count])],
    ]


def chart_layouts(
    ids: Sequence[str], colours: Sequence[str]
) -> tuple[list[viser.uplot.Series], ...]:
    """The series of each chart (CHART_TITLES order) for targets `ids` drawn in `colours`."""
    pairs = list(zip(ids, colours, strict=True))
    theta: list[viser.uplot.Series] = []
    for tid, colour in pairs:
        theta += [
            _points(f"{tid} θref", colour, 4, slot=tid),
            line_series(f"{tid} θ", colour, slot=tid),
        ]
    return (
        [
            *(line_series(tid, c, slot=tid) for tid, c in pairs),
            _points("aberrant", ABERRANT_COLOUR, 7),
        ],
        [
            *(line_series(f"{tid} η", c, slot=tid) for tid, c in pairs),
            line_series("φ", "#868e96", dash=(6.0, 4.0)),
            _points("aberrant", ABERRANT_COLOUR, 7),
        ],
        theta,
        [line_series("trackers fps", "#1971c2"), line_series("in-app fps", "#2f9e44")],
    )


class SignalPlots:
    """The four charts of a tab: peak score, global variation vs phi, theta_ref/theta, speed;
    made once (see the module docstring), with series for targets T1 .. T<slots>."""

    def __init__(
        self, gui: viser.GuiApi, container: viser.GuiTabHandle | None = None, slots: int = 4
    ) -> None:
        self.gui = gui
        self.slots = slots
        self._container = container if container is not None else gui.add_folder("Plots")
        with self._container:
            self._hint = gui.add_markdown("Draw a target to plot its signals here.")
            self._legend_style = gui.add_html("")
        self._handles: list[viser.GuiUplotHandle] = []
        self._scales: list[dict | None] = []
        self._axes: list[tuple | None] = []
        self._ids: tuple[str, ...] = ()
        numbered = tuple(f"T{number}" for number in range(1, slots + 1))
        self._build(numbered, [_css(target_colour(index)) for index in range(slots)])

    def _build(self, ids: tuple[str, ...], colours: Sequence[str]) -> None:
        """(Re)make the charts with series for `ids`: at the start, and again only for a run
        whose target ids are not T1 .. T<slots>."""
        for handle in self._handles:
            handle.remove()
        handles = []
        with self._container:
            for index, (title, chart) in enumerate(
                zip(CHART_TITLES, chart_layouts(ids, colours), strict=True)
            ):
                empty = np.zeros(1)
                handles.append(
                    self.gui.add_uplot(
                        data=(empty, *[empty] * (len(chart) + 1)),
                        series=(viser.uplot.Series(label="frame"), *chart, cursor_series()),
                        title=title,
                        aspect=2.0,
                        padding=CHART_PADDING,
                        axes=self._initial_axes(index),
                        scales=EMPTY_SCALES,
                    )
                )
        self._handles = handles
        self._scales = [None] * len(handles)
        self._axes = [self._initial_axes(index) for index in range(len(handles))]
        self._ids = ids

    @staticmethod
    def _initial_axes(index: int) -> tuple | None:
        if index != ETA_CHART:
            return None
        return (viser.uplot.Axis(), decade_axis((0.1, 1.0)))

    def update(self, history: SignalHistory, cursor: int) -> None:
        """Send the latest values and the cursor at frame `cursor` (the charts stay; their
        series are made again only for target ids outside T1 .. T<slots>)."""
        if self._hint.visible != (not history.target_ids):
            self._hint.visible = not history.target_ids
        ids = slot_ids(history, self.slots)
        if ids != self._ids:
            self._build(ids, [_css(colour) for colour in history.colours])
        style = legend_style([tid for tid in ids if tid not in history.target_ids])
        if self._legend_style.content != style:
            self._legend_style.content = style
        last = max(history.last_frame, cursor, 0)
        count = last + 1
        x_scale = {"time": False, "auto": False, "range": x_range(last, history.frame_count)}
        rows = tracked_rows(history, count, cursor)
        for index, (handle, series) in enumerate(
            zip(self._handles, chart_series(history, count, ids), strict=True)
        ):
            axes = None
            if index == ETA_CHART:
                span = log_range(series, history.phi)
                y_scale = {"distr": 3, "log": 10, "auto": False, "range": span}
                axes = (viser.uplot.Axis(), decade_axis(span))
            else:
                span = y_range(series)
                y_scale = {"auto": False, "range": span}
            scales = {"x": x_scale, "y": y_scale}
            if scales != self._scales[index]:
                handle.scales = scales
                self._scales[index] = scales
            if axes != self._axes[index]:
                handle.axes = axes
                self._axes[index] = axes
            send_data(handle, chart_data(count, series, cursor, span, rows))

    def data_of(self, index: int) -> Sequence[np.ndarray] | None:
        """The data last sent to chart `index` (CHART_TITLES order; y series with None gaps)."""
        if not self._handles:
            return None
        return self._handles[index].data

    def y_scale_of(self, index: int) -> dict | None:
        """The y scale last sent to chart `index`."""
        scales = self._scales[index] if index < len(self._scales) else None
        return None if scales is None else scales["y"]

    def axes_of(self, index: int) -> tuple | None:
        """The axes last sent to chart `index` (None: uPlot's own)."""
        return self._axes[index]
