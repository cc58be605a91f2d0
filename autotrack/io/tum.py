"""TUM trajectories (`timestamp tx ty tz qx qy qz qw`, camera-to-world, metres), as read by evo."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from autotrack.errors import InputError
from autotrack.io.atomic import write_text


def write_tum(
    path: str | Path,
    timestamps: Sequence[float] | np.ndarray,
    positions: np.ndarray,
    quaternions_xyzw: np.ndarray,
) -> int:
    """Write a TUM trajectory (`timestamp tx ty tz qx qy qz qw`, camera-to-world, metres).

    Rows with a non-finite value (invalid poses) are skipped; returns the number written.
    """
    timestamps = np.asarray(timestamps, dtype=np.float64).reshape(-1)
    positions = np.asarray(positions, dtype=np.float64).reshape(-1, 3)
    quaternions = np.asarray(quaternions_xyzw, dtype=np.float64).reshape(-1, 4)
    if not len(timestamps) == len(positions) == len(quaternions):
        raise InputError("timestamps, positions and quaternions must have the same length")
    lines = ["# timestamp tx ty tz qx qy qz qw (camera-to-world, metres)"]
    written = 0
    for stamp, position, quaternion in zip(timestamps, positions, quaternions, strict=True):
        row = np.concatenate([[stamp], position, quaternion])
        if not np.all(np.isfinite(row)):
            continue
        lines.append(" ".join(f"{v:.6f}" if k == 0 else f"{v:.9g}" for k, v in enumerate(row)))
        written += 1
    write_text(path, "\n".join(lines) + "\n")
    return written


def read_tum(path: str | Path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Read a TUM trajectory: timestamps (n,), positions (n, 3), quaternions xyzw (n, 4)."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as error:
        raise InputError(f"cannot read trajectory {path}: {error.strerror or error}") from None
    rows = []
    for line_number, line in enumerate(text.splitlines(), start=1):
        stripped = line.strip()
        if not stripped or stripped.startswith("#"):
            continue
        fields = stripped.replace(",", " ").split()
        try:
            values = [float(v) for v in fields]
        except ValueError:
            values = []
        if len(values) != 8:
            raise InputError(
                f"{path}, line {line_number}: expected 8 numbers 'timestamp tx ty tz qx qy qz qw'"
            )
        rows.append(values)
    table = np.array(rows, dtype=np.float64).reshape(-1, 8)
    return table[:, 0], table[:, 1:4], table[:, 4:8]
