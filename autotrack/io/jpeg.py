"""JPEG frames decoded by libjpeg-turbo through simplejpeg: OpenCV's pixels, in less time.

OpenCV's `imdecode` and simplejpeg both decode with libjpeg-turbo, with its defaults (the
accurate integer inverse DCT and fancy chroma upsampling), so a frame's pixels are the same
bit for bit (`tests/test_jpeg.py` compares them on frames of every dev sequence and on
every common sampling and coding). Inside the pipeline simplejpeg decodes a 1280x720 frame in
~5 ms where `imdecode` took ~6 (docs/benchmarks.md, thirteenth round), straight into RGB or
BGR, with no conversion after it.

OpenCV stays the decoder of what simplejpeg would decode differently or not at all: a file whose
EXIF orientation OpenCV applies (any but 1, or an EXIF block this module cannot read), CMYK or
YCCK files, and whatever simplejpeg rejects (a truncated or corrupt file gets OpenCV's partial
decode or error, as before).
"""

from __future__ import annotations

import struct

import numpy as np
import simplejpeg

_COLOURS = {"YCbCr", "RGB", "Gray"}
"""JPEG colour spaces decoded here (the others, CMYK and YCCK, OpenCV converts its own way)."""

_ORIENTATION_TAG = 0x0112
_SHORT = 3  # the TIFF field type of the orientation tag


def decode_jpeg(encoded: np.ndarray | bytes, *, bgr: bool = False) -> np.ndarray | None:
    """A JPEG file's pixels as `cv2.imdecode(encoded, cv2.IMREAD_ANYCOLOR)` gives them, in RGB
    order (BGR with `bgr`), or 2-D for a grey file; None when OpenCV should decode it (not a
    JPEG, or one of the cases in the module's docstring)."""
    if len(encoded) < 4 or encoded[0] != 0xFF or encoded[1] != 0xD8:
        return None
    try:
        height, width, colour, _ = simplejpeg.decode_jpeg_header(encoded)
        if colour not in _COLOURS or exif_orientation(bytes(encoded[:65536])) != 1:
            return None
        grey = colour == "Gray"
        image = simplejpeg.decode_jpeg(
            encoded, colorspace="GRAY" if grey else ("BGR" if bgr else "RGB")
        )
    except ValueError:  # simplejpeg's error for anything libjpeg-turbo complains about
        return None
    return image.reshape(height, width) if grey else image


def exif_orientation(head: bytes) -> int | None:
    """The EXIF orientation (1-8) of a JPEG whose first bytes are `head`: 1 without an EXIF
    block or orientation tag, None when the block cannot be read (let OpenCV decide)."""
    position = 2
    while position + 4 <= len(head) and head[position] == 0xFF:
        marker = head[position + 1]
        if marker == 0xFF:  # a fill byte before a marker
            position += 1
            continue
        if marker in (0xDA, 0xD9):  # start of scan, end of image: no more headers
            return 1
        if marker == 0x01 or 0xD0 <= marker <= 0xD7:  # markers without a length
            position += 2
            continue
        (length,) = struct.unpack_from(">H", head, position + 2)
        segment = head[position + 4 : position + 2 + length]
        if marker == 0xE1 and segment.startswith(b"Exif\0\0"):
            return _tiff_orientation(segment[6:])
        position += 2 + length
    return None  # headers longer than `head`, or not a marker where one should be


def _tiff_orientation(tiff: bytes) -> int | None:
    """The orientation tag of the first image directory of an EXIF block's TIFF structure."""
    if len(tiff) < 8 or tiff[:2] not in (b"II", b"MM"):
        return None
    order = "<" if tiff[:2] == b"II" else ">"
    (directory,) = struct.unpack_from(order + "I", tiff, 4)
    if directory + 2 > len(tiff):
        return None
    (entries,) = struct.unpack_from(order + "H", tiff, directory)
    for entry in range(directory + 2, directory + 2 + 12 * entries, 12):
        if entry + 12 > len(tiff):
            return None
        tag, kind = struct.unpack_from(order + "HH", tiff, entry)
        if tag == _ORIENTATION_TAG:
            (value,) = struct.unpack_from(order + "H", tiff, entry + 8)
            return value if kind == _SHORT and 1 <= value <= 8 else None
    return 1
