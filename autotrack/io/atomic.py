"""Every output file is written whole or not at all.

A run that ends with a full disk (or any write error) must neither leave a 0-byte or truncated
file nor clobber the file it was replacing. Writers therefore write a temporary file in the
same folder and rename it into place (`os.replace`, atomic on one filesystem); on any error the
temporary file is removed and the old file, if any, is untouched. Every writer of the package
writes through `write_bytes` (or `write_text`, `write_image`, `write_figure`), never
`open(path, "w")` on the final path.
"""

from __future__ import annotations

import os
import secrets
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from io import BytesIO
from pathlib import Path
from typing import Any

import numpy as np

from autotrack.errors import InputError


def _temporary_name(path: Path) -> Path:
    # The suffix stays last: OpenCV and matplotlib choose the format from it.
    return path.with_name(f".{path.stem}.{secrets.token_hex(4)}.partial{path.suffix}")


@contextmanager
def replacing(path: str | Path, *, overwrite: bool = True) -> Iterator[Path]:
    """A temporary path beside `path` to write to; renamed to `path` when the block ends
    without error, removed otherwise.

    overwrite=False: an existing `path` raises FileExistsError (checked atomically at the
    rename, so a file made meanwhile is not clobbered either). An OSError from the block names
    `path`, not the temporary file.
    """
    path = Path(path)
    temporary = _temporary_name(path)
    try:
        yield temporary
        if overwrite:
            os.replace(temporary, path)
        else:
            os.link(temporary, path)  # fails if `path` exists: nothing is replaced
            temporary.unlink()
    except OSError as error:
        temporary.unlink(missing_ok=True)
        if error.filename == str(path):
            raise
        # OSError(errno, ...) gives the matching subclass (FileExistsError, PermissionError).
        raise OSError(error.errno, error.strerror or str(error), str(path)) from error
    except BaseException:
        temporary.unlink(missing_ok=True)
        raise


def write_text(path: str | Path, text: str, *, overwrite: bool = True) -> Path:
    """`text` (UTF-8, line ends as given) to `path`, whole or not at all."""
    return write_bytes(path, text.encode("utf-8"), overwrite=overwrite)


def write_bytes(path: str | Path, data: bytes, *, overwrite: bool = True) -> Path:
    """`data` to `path`, whole or not at all: the one place the package writes a file's bytes."""
    path = Path(path)
    with replacing(path, overwrite=overwrite) as temporary, open(temporary, "xb") as handle:
        handle.write(data)
    return path


def write_figure(path: str | Path, figure: Any) -> Path:
    """A matplotlib figure, in the format `path`'s suffix names, whole or not at all."""
    buffer = BytesIO()
    figure.savefig(buffer, format=Path(path).suffix.lstrip(".") or "png")
    return write_bytes(path, buffer.getvalue())


def write_image(path: str | Path, image: np.ndarray, params: Sequence[int] = ()) -> Path:
    """`image` (OpenCV's BGR order) encoded as `path`'s suffix says, whole or not at all."""
    import cv2

    path = Path(path)
    ok, encoded = cv2.imencode(path.suffix or ".png", image, list(params))
    if not ok:
        raise InputError(f"cannot encode an image as {path.suffix or '.png'} for {path}")
    return write_bytes(path, encoded.tobytes())
