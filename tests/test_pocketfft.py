"""pocketfft.py gives scipy.fft's results bit for bit, for every call form the tracker makes,
and `scipy_binaries.load_compiled` loads a compiled module once, shared with a later import."""

from __future__ import annotations

import sys

import numpy as np
import pytest
import scipy.fft

from autotrack.scipy_binaries import load_compiled
from autotrack.tracker import pocketfft
from tests.processes import printed_by_fresh_python

SIDES = (50, 46, 38, 45)  # the tracker's grid sides: smooth, 2 x 23, 2 x 19, odd


def _maps(shape, dtype=np.float32, seed=0) -> np.ndarray:
    return np.random.default_rng(seed).standard_normal(shape).astype(dtype)


def _same(got: np.ndarray, expected: np.ndarray) -> None:
    assert got.dtype == expected.dtype and got.shape == expected.shape
    assert got.tobytes() == expected.tobytes()


@pytest.mark.parametrize("side", SIDES)
def test_grid_transforms_equal_scipy_fft(side):
    maps = _maps((42, side, side))
    spectrum = pocketfft.rfft2(maps)
    _same(spectrum, scipy.fft.rfft2(maps, workers=1))
    _same(pocketfft.irfft2(spectrum, (side, side)), scipy.fft.irfft2(spectrum, s=(side, side)))
    wide = _maps((3, side, side + 7), seed=1)  # rows != cols, the inverse's last size odd
    wide_spectrum = pocketfft.rfft2(wide)
    _same(wide_spectrum, scipy.fft.rfft2(wide, axes=(-2, -1)))
    _same(
        pocketfft.irfft2(wide_spectrum, wide.shape[1:]),
        scipy.fft.irfft2(wide_spectrum, s=wide.shape[1:], axes=(-2, -1)),
    )
    response = _maps((side, side), seed=2)
    _same(pocketfft.fft2(response), scipy.fft.fft2(response, workers=1))
    _same(pocketfft.fft2(response.astype(np.float64)), scipy.fft.fft2(response.astype(np.float64)))


def test_views_padding_and_one_axis_transforms_equal_scipy_fft():
    maps = _maps((6, 40, 52))
    strided = maps[::2, 1:-1, ::2]  # not contiguous
    _same(pocketfft.rfft2(strided), scipy.fft.rfft2(strided))
    _same(pocketfft.rfft2(maps, (64, 70)), scipy.fft.rfft2(maps, s=(64, 70), workers=1))
    samples = _maps((33, 744), seed=3)  # the scale filter: scales x feature dimensions
    _same(pocketfft.rfft(samples, axis=0), scipy.fft.rfft(samples, axis=0, workers=1))
    _same(pocketfft.fft(samples, axis=0), scipy.fft.fft(samples, axis=0, workers=1))
    label = np.exp(-0.5 * np.arange(-16, 17) ** 2 / 9.0)  # float64, the labels' form
    _same(pocketfft.fft(label), scipy.fft.fft(label))
    spectrum = scipy.fft.fft(samples, axis=0)
    for values in (spectrum[:, 0], spectrum[:, 0].astype(np.complex128)):
        _same(pocketfft.ifft(values), scipy.fft.ifft(values, workers=1))
    counts = np.arange(24).reshape(4, 6)  # integers: promoted to float64, as scipy does
    _same(pocketfft.rfft2(counts), scipy.fft.rfft2(counts))
    _same(pocketfft.fft(counts, axis=0), scipy.fft.fft(counts, axis=0))


def test_wrong_inputs_are_refused_with_a_message():
    spectrum = pocketfft.rfft2(_maps((2, 10, 12)))
    with pytest.raises(
        ValueError, match=r"10 x 14 grid has shape \(10, 8\) in its last two axes, not \(10, 7\)"
    ):
        pocketfft.irfft2(spectrum, (10, 14))
    with pytest.raises(ValueError, match="do not fit a 8 x 8 grid"):
        pocketfft.rfft2(_maps((10, 12)), (8, 8))
    with pytest.raises(TypeError, match="real values"):
        pocketfft.rfft2(spectrum)
    with pytest.raises(TypeError, match="real values"):
        pocketfft.rfft(spectrum, axis=0)


def test_load_compiled_reuses_a_loaded_module_and_falls_back_to_an_import():
    binding = load_compiled("scipy.fft._pocketfft.pypocketfft")
    assert binding is sys.modules["scipy.fft._pocketfft.pypocketfft"]
    assert load_compiled("scipy.fft._pocketfft.pypocketfft") is binding
    # a pure-Python module has no extension file: the ordinary import
    helper = load_compiled("scipy.fft._pocketfft.helper")
    assert helper.__file__.endswith(".py")
    with pytest.raises(ModuleNotFoundError):
        load_compiled("scipy.no_such_module")


def test_a_later_scipy_fft_import_shares_the_loaded_binding():
    """In a fresh process the tracker's FFTs load pocketfft's binding alone; an import of
    scipy.fft afterwards uses that same module (one copy of the binary) and agrees bit for bit."""
    script = (
        "import sys\n"
        "import numpy as np\n"
        "from autotrack.tracker import pocketfft\n"
        "loaded = sys.modules['scipy.fft._pocketfft.pypocketfft']\n"
        "print('scipy.fft' in sys.modules)\n"
        "import scipy.fft\n"
        "from scipy.fft._pocketfft import basic\n"
        "print(basic.pfft is loaded)\n"
        "x = np.random.default_rng(0).random((3, 20, 22)).astype(np.float32)\n"
        "print(scipy.fft.rfft2(x).tobytes() == pocketfft.rfft2(x).tobytes())\n"
    )
    assert printed_by_fresh_python(script) == ["False", "True", "True"]


def test_two_threads_loading_one_module_load_its_file_once():
    """The second thread waits for the first one's load and gets the same module (in a fresh
    process, where scipy.optimize's MINPACK is not loaded yet)."""
    script = (
        "import threading\n"
        "from autotrack import scipy_binaries\n"
        "original = scipy_binaries._extension_spec\n"
        "entered, release, lookups, results = threading.Event(), threading.Event(), [], []\n"
        "def slow_lookup(name):\n"
        "    lookups.append(name)\n"
        "    entered.set()\n"
        "    release.wait(10)\n"
        "    return original(name)\n"
        "scipy_binaries._extension_spec = slow_lookup\n"
        "def load():\n"
        "    results.append(scipy_binaries.load_compiled('scipy.optimize._minpack'))\n"
        "first = threading.Thread(target=load)\n"
        "first.start()\n"
        "entered.wait(10)\n"
        "second = threading.Thread(target=load)\n"
        "second.start()\n"
        "second.join(0.3)\n"
        "release.set()\n"
        "first.join()\n"
        "second.join()\n"
        "print(len(lookups), len(results), results[0] is results[1])\n"
    )
    assert printed_by_fresh_python(script) == ["1", "2", "True"]
