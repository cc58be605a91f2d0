"""OTB-style box files: one `x,y,w,h` row per frame in the toolkits' 1-based pixel convention
(comma, tab, semicolon or space separated; `NaN` rows where the target is not visible)."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from autotrack.errors import InputError
from autotrack.io.atomic import write_text

_SEPARATORS = re.compile(r"[,;\s]+")


def read_boxes(path: str | Path) -> np.ndarray:
    """Read an x,y,w,h box file in the toolkits' 1-based convention as 0-based (N, 4) float64.

    Rows may be comma, tab, semicolon or space separated; blank lines are skipped; a row with
    any NaN becomes a NaN row.
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8-sig")
    except OSError as error:
        raise InputError(f"cannot read box file {path}: {error.strerror}") from error
    rows = []
    for line_number, line in enumerate(text.splitlines(), start=1):
        fields = [field for field in _SEPARATORS.split(line.strip()) if field]
        if not fields:
            continue
        if len(fields) != 4:
            raise InputError(
                f"{path}, line {line_number}: expected 4 values x,y,w,h, found {len(fields)}"
            )
        try:
            rows.append([float(field) for field in fields])
        except ValueError as error:
            raise InputError(f"{path}, line {line_number}: not a number in {line!r}") from error
    if not rows:
        raise InputError(f"{path}: no boxes")
    boxes = np.array(rows, dtype=np.float64)
    boxes[np.isnan(boxes).any(axis=1)] = np.nan
    boxes[:, :2] -= 1.0
    return boxes


def write_boxes(path: str | Path, boxes: np.ndarray) -> None:
    """Write (N, 4) 0-based boxes as comma-separated x,y,w,h rows, 1-based (toolkit convention)."""
    out = np.array(boxes, dtype=np.float64).reshape(-1, 4).copy()
    out[:, :2] += 1.0
    lines = [",".join(_format_number(v) for v in row) for row in out]
    write_text(path, "\n".join(lines) + "\n")


def _format_number(value: float) -> str:
    if not np.isfinite(value):
        return "NaN"
    text = f"{value:.4f}".rstrip("0").rstrip(".")
    return "0" if text in ("-0", "") else text
