"""CSV tables: one writer for every table we export (comma-separated, Unix line ends)."""

from __future__ import annotations

import csv
import io
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

from autotrack.io.atomic import write_text


def write_csv(
    path: str | Path,
    header: Sequence[str],
    rows: Iterable[Sequence[Any]],
    *,
    overwrite: bool = True,
    line_end: str = "\n",
) -> Path:
    """Write `header` and `rows` to `path` (values as `str()` gives them); with
    `overwrite=False` an existing file raises FileExistsError. Written whole or not at all
    (`autotrack.io.atomic`)."""
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator=line_end)
    writer.writerow(header)
    writer.writerows(rows)
    return write_text(path, buffer.getvalue(), overwrite=overwrite)
