"""JPEG frames decoded through simplejpeg (autotrack/io/jpeg.py): OpenCV's pixels bit for bit on
real frames and on every common encoding, and OpenCV's own decode where simplejpeg's would
differ (EXIF orientation, CMYK) or fail (a truncated file)."""

from __future__ import annotations

import io
import struct
from pathlib import Path

import cv2
import numpy as np
import pytest

from autotrack.errors import InputError
from autotrack.io.frames import read_image
from autotrack.io.jpeg import decode_jpeg, exif_orientation
from tests.conftest import SEQUENCES, needs_sequences

FRAMES_PER_SEQUENCE = 6


def _opencv(encoded: np.ndarray | bytes, bgr: bool) -> np.ndarray:
    """What `read_image` gave before simplejpeg: OpenCV's decode, in RGB unless `bgr`."""
    image = cv2.imdecode(np.frombuffer(encoded, np.uint8), cv2.IMREAD_ANYCOLOR)
    return image if bgr or image.ndim == 2 else cv2.cvtColor(image, cv2.COLOR_BGR2RGB)


def _assert_opencvs_pixels(encoded: np.ndarray | bytes) -> None:
    for bgr in (False, True):
        decoded = decode_jpeg(np.frombuffer(encoded, np.uint8), bgr=bgr)
        assert decoded is not None, "decoded by OpenCV, not simplejpeg"
        expected = _opencv(encoded, bgr)
        assert decoded.shape == expected.shape and decoded.dtype == np.uint8
        assert np.array_equal(decoded, expected)


@needs_sequences
def test_real_frames_decode_to_opencvs_pixels():
    folders = sorted(path for path in SEQUENCES.glob("*/*/img") if path.is_dir())
    assert len(folders) >= 18
    for folder in folders:
        frames = sorted(folder.glob("*.jpg"))
        for path in frames[:: max(len(frames) // FRAMES_PER_SEQUENCE, 1)]:
            _assert_opencvs_pixels(path.read_bytes())


def _texture(height: int, width: int, channels: int) -> np.ndarray:
    noise = np.random.default_rng(height * width + channels).random((height, width, channels))
    smooth = cv2.GaussianBlur((noise * 255).astype(np.uint8), (0, 0), 1.5)
    return smooth.reshape(height, width, channels) if channels > 1 else smooth


SAMPLINGS = ("411", "420", "422", "440", "444")


@pytest.mark.parametrize("sampling", SAMPLINGS)
@pytest.mark.parametrize(("height", "width"), [(72, 128), (37, 53), (17, 200)])
def test_every_chroma_sampling_and_odd_size_decodes_to_opencvs_pixels(sampling, height, width):
    factor = getattr(cv2, f"IMWRITE_JPEG_SAMPLING_FACTOR_{sampling}")
    params = [cv2.IMWRITE_JPEG_QUALITY, 90, cv2.IMWRITE_JPEG_SAMPLING_FACTOR, factor]
    _assert_opencvs_pixels(cv2.imencode(".jpg", _texture(height, width, 3), params)[1])


@pytest.mark.parametrize(
    "params",
    [
        [cv2.IMWRITE_JPEG_PROGRESSIVE, 1],
        [cv2.IMWRITE_JPEG_RST_INTERVAL, 3],
        [cv2.IMWRITE_JPEG_OPTIMIZE, 1, cv2.IMWRITE_JPEG_QUALITY, 30],
        [cv2.IMWRITE_JPEG_QUALITY, 100],
    ],
    ids=["progressive", "restart-markers", "optimised-q30", "q100"],
)
def test_progressive_restart_and_quality_variants_decode_to_opencvs_pixels(params):
    _assert_opencvs_pixels(cv2.imencode(".jpg", _texture(64, 96, 3), params)[1])
    _assert_opencvs_pixels(cv2.imencode(".jpg", _texture(64, 96, 1), params)[1])


def test_a_grey_file_is_two_dimensional(tmp_path: Path):
    path = tmp_path / "grey.jpg"
    cv2.imwrite(str(path), _texture(40, 60, 1))
    assert read_image(path).shape == (40, 60)
    assert np.array_equal(read_image(path), cv2.imread(str(path), cv2.IMREAD_ANYCOLOR))


def _with_exif(jpeg: bytes, orientation: int, order: str = "<") -> bytes:
    """`jpeg` with an APP1 EXIF block (one TIFF directory entry: the orientation) after SOI."""
    mark = b"II" if order == "<" else b"MM"
    tiff = mark + struct.pack(order + "HI", 42, 8) + struct.pack(order + "H", 1)
    tiff += struct.pack(order + "HHIHH", 0x0112, 3, 1, orientation, 0) + b"\0\0\0\0"
    payload = b"Exif\0\0" + tiff
    return jpeg[:2] + b"\xff\xe1" + struct.pack(">H", len(payload) + 2) + payload + jpeg[2:]


@pytest.mark.parametrize("order", ["<", ">"])
def test_exif_orientation_is_opencvs_to_apply(tmp_path: Path, order):
    plain = cv2.imencode(".jpg", _texture(40, 60, 3))[1].tobytes()
    upright, rotated = _with_exif(plain, 1, order), _with_exif(plain, 6, order)
    assert exif_orientation(plain) == 1 and exif_orientation(upright) == 1
    assert exif_orientation(rotated) == 6
    _assert_opencvs_pixels(upright)
    assert decode_jpeg(np.frombuffer(rotated, np.uint8)) is None
    path = tmp_path / "rotated.jpg"
    path.write_bytes(rotated)
    image = read_image(path)
    assert image.shape == (60, 40, 3)  # OpenCV turned it by 90 degrees
    assert np.array_equal(image, _opencv(rotated, bgr=False))
    broken = rotated.replace(b"Exif\0\0" + (b"II" if order == "<" else b"MM"), b"Exif\0\0XX")
    assert exif_orientation(broken) is None and decode_jpeg(np.frombuffer(broken, np.uint8)) is None


def test_cmyk_files_and_truncated_files_stay_opencvs(tmp_path: Path):
    from PIL import Image

    cmyk = io.BytesIO()
    Image.fromarray(_texture(30, 40, 3)).convert("CMYK").save(cmyk, "JPEG")
    assert decode_jpeg(np.frombuffer(cmyk.getvalue(), np.uint8)) is None
    path = tmp_path / "cmyk.jpg"
    path.write_bytes(cmyk.getvalue())
    assert np.array_equal(read_image(path), _opencv(cmyk.getvalue(), bgr=False))

    whole = cv2.imencode(".jpg", _texture(120, 160, 3))[1].tobytes()
    truncated = whole[: len(whole) // 2]
    assert decode_jpeg(np.frombuffer(truncated, np.uint8)) is None
    path = tmp_path / "truncated.jpg"
    path.write_bytes(truncated)
    expected = cv2.imdecode(np.frombuffer(truncated, np.uint8), cv2.IMREAD_ANYCOLOR)
    if expected is None:
        with pytest.raises(InputError, match="cannot decode image file"):
            read_image(path)
    else:  # libjpeg-turbo's partial decode, as OpenCV gives it
        assert np.array_equal(read_image(path, bgr=True), expected)
