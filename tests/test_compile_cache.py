"""Compiled kernels are cached where the process can write."""

from __future__ import annotations

import os
import subprocess
import sys

import numpy as np
import pytest

from autotrack import compile_cache


@pytest.fixture
def clean_env(monkeypatch, tmp_path):
    monkeypatch.delenv("NUMBA_CACHE_DIR", raising=False)
    monkeypatch.setenv(compile_cache.CACHE_ENV, str(tmp_path / "user-cache"))
    return tmp_path


def test_writable_install_keeps_numbas_default(clean_env):
    package = clean_env / "pkg"
    assert compile_cache.configure_numba_cache(package) == package / "__pycache__"
    assert "NUMBA_CACHE_DIR" not in os.environ


def test_read_only_install_falls_back_to_the_user_cache(clean_env):
    blocker = clean_env / "not-a-folder"
    blocker.write_text("a file where the package folder should be")  # unwritable even for root
    folder = compile_cache.configure_numba_cache(blocker / "pkg")
    assert folder == clean_env / "user-cache" / "numba"
    assert os.environ["NUMBA_CACHE_DIR"] == str(folder)
    assert compile_cache.is_writable_dir(folder)


def test_unwritable_numba_cache_dir_is_replaced(clean_env, monkeypatch):
    blocker = clean_env / "file"
    blocker.write_text("x")
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(blocker / "numba"))
    folder = compile_cache.configure_numba_cache(clean_env / "pkg")
    assert folder == clean_env / "user-cache" / "numba"


def test_spectrum_transform_returns_a_new_spectrum_each_call():
    from autotrack.tracker.dcf import SpectrumTransform, to_spectrum

    transform = SpectrumTransform(3, (12, 10))
    maps = np.random.default_rng(0).random((3, 12, 10)).astype(np.float32)
    spectrum = transform.forward(maps)
    np.testing.assert_allclose(spectrum, to_spectrum(maps), atol=1e-5)
    assert transform.forward(maps) is not spectrum
    np.testing.assert_allclose(transform.inverse_scratch(spectrum), maps, atol=1e-5)


@pytest.mark.slow
def test_second_process_loads_the_cached_kernels(tmp_path):
    """A fresh process with an empty cache folder writes the kernels; the next one reuses them."""
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "numba"))
    env[compile_cache.CACHE_ENV] = str(tmp_path / "cache")
    script = (
        "import numpy as np; from autotrack import AutoTrack, preset;"
        "f = np.zeros((64, 96, 3), np.uint8); f[20:40, 30:60] = 200;"
        "t = AutoTrack(preset('autotrack')); t.init(f, (30, 20, 30, 20)); t.update(f);"
        "from autotrack.tracker.fhog import _fhog_into; print(len(_fhog_into.stats.cache_hits))"
    )
    first = subprocess.run([sys.executable, "-c", script], env=env, capture_output=True, text=True)
    assert first.returncode == 0, first.stderr
    assert list((tmp_path / "numba").rglob("*.nbi")), "no kernel was cached"
    second = subprocess.run([sys.executable, "-c", script], env=env, capture_output=True, text=True)
    assert second.returncode == 0, second.stderr
    assert int(second.stdout.split()[-1]) >= 1  # loaded from the cache, not compiled


def test_tracker_import_leaves_out_modules_tracking_does_not_need():
    """A fresh process importing the tracker does not import dask (through pyFFTW's optional
    dask interface) or scipy.io, and dask.array.fft still imports afterwards."""
    pytest.importorskip("dask.array")
    script = (
        "import sys\n"
        "import autotrack\n"
        "from autotrack import AutoTrack\n"
        "heavy = [m for m in ('dask', 'scipy.io') if m in sys.modules]\n"
        "print(','.join(heavy))\n"
        "import dask.array.fft\n"
        "print(callable(dask.array.fft.fft_wrap))\n"
    )
    done = subprocess.run(
        [sys.executable, "-c", script], capture_output=True, text=True, check=True
    )
    assert done.stdout.split("\n")[:2] == ["", "True"]
