"""CSV tables: one writer for every table we export (comma-separated, Unix line ends)."""

from __future__ import annotations

import csv
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any


def write_csv(
    path: str | Path,
    header: Sequence[str],
    rows: Iterable[Sequence[Any]],
    *,
    overwrite: bool = True,
) -> Path:
    """Write `header` and `rows` to `path` (values as `str()` gives them); with
    `overwrite=False` an existing file raises FileExistsError."""
    path = Path(path)
    with path.open("w" if overwrite else "x", newline="", encoding="utf-8") as handle:
        writer = csv.writer(handle, lineterminator="\n")
        writer.writerow(header)
        writer.writerows(rows)
    return path
