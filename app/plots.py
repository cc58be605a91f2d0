"""Live uPlot charts of the tracker's signals over frames, one series per target.

Frames without a value hold NaN, which uPlot cannot range over (a NaN anywhere on a scale
leaves the chart empty) but skips when drawing a line or a point. So every chart gets an
explicit y range from the finite values, widened with headroom and only ever grown, so it
changes rarely. Aberrant frames are a points-only red series on the peak-score and
global-variation charts.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import viser
import viser.uplot

from app.views import SignalHistory

ABERRANT_COLOUR = "#e03131"


def x_scale(frame_count: int) -> viser.uplot.Scale:
    """Frame indices (not timestamps) over the whole sequence, so the charts fill up as the
    run advances and a step back does not rescale them."""
    return {"time": False, "range": (0.0, float(max(1, frame_count - 1)))}


def y_range(
    arrays: Sequence[np.ndarray], current: tuple[float, float] | None
) -> tuple[float, float]:
    """`current` if it holds every finite value, else a range holding both with 10% headroom,
    rounded outward to a tenth of the span's order of magnitude ((-0.1, 1.1) before any
    value)."""
    finite = [values[np.isfinite(values)] for values in arrays]
    values = np.concatenate(finite) if finite else np.zeros(0)
    if values.size == 0:
        return (-0.1, 1.1) if current is None else current
    low, high = float(values.min()), float(values.max())
    if current is not None:
        if current[0] <= low and high <= current[1]:
            return current
        low, high = min(low, current[0]), max(high, current[1])
    span = max(high - low, 1e-6, 1e-3 * max(abs(low), abs(high)))
    low, high = low - 0.1 * span, high + 0.1 * span
    step = 10.0 ** np.floor(np.log10(span)) / 10.0
    return (float(np.floor(low / step) * step), float(np.ceil(high / step) * step))


def _css(colour: tuple[int, int, int]) -> str:
    return "#{:02x}{:02x}{:02x}".format(*colour)


def _line(label: str, colour: str, dash: tuple[float, ...] | None = None) -> viser.uplot.Series:
    series = viser.uplot.Series(label=label, stroke=colour, width=1.5)
    if dash is not None:
        series["dash"] = dash
    return series


def _markers(label: str) -> viser.uplot.Series:
    return viser.uplot.Series(
        label=label,
        stroke=ABERRANT_COLOUR,
        width=0,
        points=viser.uplot.Series_Points(show=True, size=7, fill=ABERRANT_COLOUR),
    )


def _aberrant_values(history: SignalHistory, signal: str, count: int) -> np.ndarray:
    """The largest `signal` value among targets aberrant on each frame, NaN elsewhere."""
    marked = np.full(count, np.nan)
    for target_id in history.target_ids:
        values = history.signals[target_id]
        flagged = values["aberrant"][:count] == 1.0
        candidate = np.where(flagged, values[signal][:count], np.nan)
        marked = np.fmax(marked, candidate)
    return marked


class SignalPlots:
    """The four charts of a tab: peak score, global variation vs phi, theta_ref/theta, fps."""

    def __init__(self, gui: viser.GuiApi) -> None:
        self.gui = gui
        self._layout: tuple[tuple[str, ...], int] | None = None
        """Target ids and frame count the charts were built for."""
        self._handles: list[viser.GuiUplotHandle] = []
        self._ranges: list[tuple[float, float] | None] = []
        self._folder = gui.add_folder("Plots", expand_by_default=True)

    def _build(self, history: SignalHistory) -> None:
        for handle in self._handles:
            handle.remove()
        colours = [_css(colour) for colour in history.colours]
        ids = history.target_ids
        x_axis = x_scale(history.frame_count)
        empty = np.zeros(1)
        x_series = viser.uplot.Series(label="frame")
        with self._folder:
            peak = self.gui.add_uplot(
                data=(empty, *[empty] * len(ids), empty),
                series=(
                    x_series,
                    *[_line(tid, colour) for tid, colour in zip(ids, colours, strict=True)],
                    _markers("aberrant"),
                ),
                title="Peak score",
                scales={"x": x_axis},
                aspect=2.0,
            )
            variation = self.gui.add_uplot(
                data=(empty, *[empty] * len(ids), empty, empty),
                series=(
                    x_series,
                    *[_line(f"{tid} η", colour) for tid, colour in zip(ids, colours, strict=True)],
                    _line("φ", "#868e96", dash=(6.0, 4.0)),
                    _markers("aberrant"),
                ),
                title="Global variation η vs threshold φ",
                scales={"x": x_axis},
                aspect=2.0,
            )
            theta_series: list[viser.uplot.Series] = []
            for tid, colour in zip(ids, colours, strict=True):
                theta_series.append(_line(f"{tid} θref", colour, dash=(4.0, 3.0)))
                theta_series.append(_line(f"{tid} θ", colour))
            theta = self.gui.add_uplot(
                data=(empty, *[empty] * (2 * len(ids))),
                series=(x_series, *theta_series),
                title="θ_ref (dashed) and θ",
                scales={"x": x_axis},
                aspect=2.0,
            )
            fps = self.gui.add_uplot(
                data=(empty, empty),
                series=(x_series, _line("fps", "#1971c2")),
                title="Tracking speed (frames/s)",
                scales={"x": x_axis},
                aspect=2.5,
            )
        self._handles = [peak, variation, theta, fps]
        self._ranges = [None] * len(self._handles)
        self._layout = (ids, history.frame_count)

    def update(self, history: SignalHistory) -> None:
        """Send the latest values (rebuilding the charts when the target list changed)."""
        if not history.target_ids:
            for handle in self._handles:
                handle.remove()
            self._handles = []
            self._layout = None
            return
        if (history.target_ids, history.frame_count) != self._layout:
            self._build(history)
        count = max(history.last_frame + 1, 1)
        frames = np.arange(count, dtype=np.float64)
        ids = history.target_ids

        def signal(name: str) -> list[np.ndarray]:
            return [history.signals[tid][name][:count] for tid in ids]

        theta_values: list[np.ndarray] = []
        for tid in ids:
            theta_values.append(history.signals[tid]["theta_ref"][:count])
            theta_values.append(history.signals[tid]["theta"][:count])
        with np.errstate(divide="ignore", invalid="ignore"):
            rate = 1.0 / history.frame_seconds[:count]
        charts = (
            (*signal("peak_score"), _aberrant_values(history, "peak_score", count)),
            (
                *signal("global_variation"),
                np.full(count, history.phi),
                _aberrant_values(history, "global_variation", count),
            ),
            tuple(theta_values),
            (np.where(np.isfinite(rate), rate, np.nan),),
        )
        for index, (handle, series) in enumerate(zip(self._handles, charts, strict=True)):
            span = y_range(series, self._ranges[index])
            if span != self._ranges[index]:
                handle.scales = {
                    "x": x_scale(history.frame_count),
                    "y": {"auto": False, "range": span},
                }
                self._ranges[index] = span
            handle.data = (frames, *series)

    def data_of(self, title_index: int) -> Sequence[np.ndarray] | None:
        """The data last sent to chart `title_index` (0 peak, 1 variation, 2 theta, 3 fps)."""
        if not self._handles:
            return None
        return self._handles[title_index].data
