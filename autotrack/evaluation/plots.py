"""Paper-style OPE plots (precision and success) from summaries, written as PNG files.

Legends read "name [score]", ranked best first: precision at 20 px for precision plots, AUC for
success plots, as in the OTB/UAV123 toolkits. Figures are drawn with matplotlib's Agg canvas
directly (no pyplot state).
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from pathlib import Path

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from autotrack.evaluation.datasets import ATTRIBUTE_FULL_NAMES
from autotrack.evaluation.metrics import PRECISION_THRESHOLDS, SUCCESS_THRESHOLDS, SummaryScore
from autotrack.io.atomic import write_figure

_LINE_STYLES = ("-", "--", "-.", ":")


def _ranked(curves: Mapping[str, SummaryScore], key: str) -> list[tuple[str, SummaryScore]]:
    def score(item: tuple[str, SummaryScore]) -> float:
        value = getattr(item[1], key)
        return -value if np.isfinite(value) else np.inf

    return sorted(curves.items(), key=score)


def _plot(
    curves: Mapping[str, SummaryScore],
    path: Path,
    title: str,
    kind: str,
) -> Path:
    figure = Figure(figsize=(6.0, 4.5), dpi=120)
    FigureCanvasAgg(figure)
    axes = figure.add_subplot()
    if kind == "precision":
        thresholds, key, attribute = PRECISION_THRESHOLDS, "precision", "precision_curve"
        axes.set_xlabel("Location error threshold (pixels)")
        axes.set_ylabel("Precision")
        legend_location = "lower right"
    else:
        thresholds, key, attribute = SUCCESS_THRESHOLDS, "auc", "success_curve"
        axes.set_xlabel("Overlap threshold")
        axes.set_ylabel("Success rate")
        legend_location = "lower left"
    for rank, (name, summary) in enumerate(_ranked(curves, key)):
        axes.plot(
            thresholds,
            getattr(summary, attribute),
            linestyle=_LINE_STYLES[(rank // 10) % len(_LINE_STYLES)],
            linewidth=2.0 if rank == 0 else 1.5,
            label=f"{name} [{getattr(summary, key):.3f}]",
        )
    axes.set_xlim(float(thresholds[0]), float(thresholds[-1]))
    axes.set_ylim(0.0, 1.0)
    axes.grid(True, alpha=0.3)
    axes.set_title(title)
    axes.legend(loc=legend_location, fontsize="small")
    figure.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    return write_figure(path, figure)


def plot_precision(curves: Mapping[str, SummaryScore], path: str | Path, title: str) -> Path:
    """Precision plot (centre error 0..50 px) of several trackers; legend ranked by P@20."""
    return _plot(curves, Path(path), title, "precision")


def plot_success(curves: Mapping[str, SummaryScore], path: str | Path, title: str) -> Path:
    """Success plot (overlap 0..1) of several trackers; legend ranked by AUC."""
    return _plot(curves, Path(path), title, "success")


def _file_label(text: str) -> str:
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", text).strip("_") or "unnamed"


def write_plots(
    overall: Mapping[str, SummaryScore],
    out_dir: str | Path,
    *,
    title: str = "",
    by_dataset: Mapping[str, Mapping[str, SummaryScore]] | None = None,
    by_attribute: Mapping[str, Mapping[str, SummaryScore]] | None = None,
) -> list[Path]:
    """Precision and success plots overall, per dataset (when there are several) and per attribute.

    `overall` maps tracker -> summary; `by_dataset` and `by_attribute` map a dataset or attribute
    name to tracker -> summary. Returns the PNG files written in `out_dir`.
    """
    out_dir = Path(out_dir)
    suffix = f" - {title}" if title else ""
    count = next(iter(overall.values())).sequences if overall else 0
    written = [
        plot_precision(
            overall, out_dir / "precision.png", f"Precision plots of OPE{suffix} ({count})"
        ),
        plot_success(overall, out_dir / "success.png", f"Success plots of OPE{suffix} ({count})"),
    ]
    groups: list[tuple[str, str, Mapping[str, SummaryScore]]] = []
    if by_dataset and len(by_dataset) > 1:
        groups += [("dataset", name, curves) for name, curves in by_dataset.items()]
    if by_attribute:
        groups += [("attribute", name, curves) for name, curves in by_attribute.items()]
    for group, name, curves in groups:
        if not curves:
            continue
        label = ATTRIBUTE_FULL_NAMES.get(name, name) if group == "attribute" else name
        count = next(iter(curves.values())).sequences
        stem = f"{group}_{_file_label(name)}"
        written.append(
            plot_precision(
                curves,
                out_dir / f"precision_{stem}.png",
                f"Precision plots of OPE - {label} ({count})",
            )
        )
        written.append(
            plot_success(
                curves, out_dir / f"success_{stem}.png", f"Success plots of OPE - {label} ({count})"
            )
        )
    return written
