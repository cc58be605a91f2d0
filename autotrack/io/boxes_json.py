"""boxes.json: the first boxes of a localisation run, `{landmark id: [x, y, w, h]}` or a list of
boxes whose landmarks the correspondence search finds (0-based pixels)."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

from autotrack.errors import BoxError, InputError
from autotrack.io.ids import checked_identifier

Box = tuple[float, float, float, float]


def read_boxes_json(path: str | Path) -> dict[str, Box] | list[Box]:
    """The boxes of `path`: landmark id -> box, or a list of boxes (landmarks unknown)."""
    path = Path(path)
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except OSError as error:
        raise InputError(f"cannot read boxes file {path}: {error.strerror or error}") from None
    except (json.JSONDecodeError, UnicodeDecodeError) as error:
        line = getattr(error, "lineno", None)
        where = f" (line {line})" if line is not None else ""
        raise InputError(f"boxes file {path} is not valid JSON{where}") from None
    if isinstance(data, dict):
        return {
            checked_identifier(k, f"{path}: landmark id", BoxError): _box(
                v, path, f"the box of {k!r}"
            )
            for k, v in data.items()
        }
    if isinstance(data, list):
        return [_box(v, path, f"box {i + 1}") for i, v in enumerate(data)]
    raise InputError(f"{path}: expected {{landmark id: [x, y, w, h]}} or a list of boxes")


def _box(value: Any, path: Path, where: str) -> Box:
    if (
        not isinstance(value, list)
        or len(value) != 4
        or not all(isinstance(v, int | float) and not isinstance(v, bool) for v in value)
    ):
        raise BoxError(f"{path}: {where} must be [x, y, w, h] (four numbers, 0-based pixels)")
    x, y, w, h = (float(v) for v in value)
    if w <= 0 or h <= 0 or not all(math.isfinite(v) for v in (x, y, w, h)):
        raise BoxError(f"{path}: {where} needs a positive width and height")
    return (x, y, w, h)
