"""Compiled kernels are cached where the process can write."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time

import numpy as np
import pytest

from autotrack import compile_cache, userdirs
from tests.conftest import shared_sequence_dir


@pytest.fixture
def clean_env(monkeypatch, tmp_path):
    monkeypatch.delenv("NUMBA_CACHE_DIR", raising=False)
    monkeypatch.setenv(userdirs.CACHE_ENV, str(tmp_path / "user-cache"))
    return tmp_path


def _package(folder, callee_body="return x + 1"):
    """A package `pkg` in `folder` whose kernel `b.g` calls the kernel `a.f` of another module."""
    package = folder / "pkg"
    package.mkdir(parents=True, exist_ok=True)
    (package / "__init__.py").write_text("")
    (package / "a.py").write_text(
        f"from numba import njit\n\n@njit(cache=True)\ndef f(x):\n    {callee_body}\n"
    )
    (package / "b.py").write_text(
        "from numba import njit\nfrom pkg.a import f\n\n"
        "@njit(cache=True)\ndef g(x):\n    return f(x) * 10\n"
    )
    return package


def test_kernels_go_to_a_folder_named_by_the_sources(clean_env):
    package = _package(clean_env)
    folder = compile_cache.configure_numba_cache(package)
    digest = compile_cache.source_digest(package)
    assert folder == clean_env / "user-cache" / "numba" / f"kernels-{digest}"
    assert os.environ["NUMBA_CACHE_DIR"] == str(folder)
    assert compile_cache.is_writable_dir(folder)
    # A child process inherits the folder as it is (no folder nested in it).
    assert compile_cache.configure_numba_cache(package) == folder
    (package / "a.py").write_text((package / "a.py").read_text().replace("+ 1", "+ 2"))
    assert compile_cache.source_digest(package) != digest


def test_a_writable_numba_cache_dir_holds_the_folder(clean_env, monkeypatch):
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(clean_env / "mine"))
    folder = compile_cache.configure_numba_cache(_package(clean_env))
    assert folder.parent == clean_env / "mine" and folder.name.startswith("kernels-")


def test_unwritable_numba_cache_dir_is_replaced(clean_env, monkeypatch):
    blocker = clean_env / "file"
    blocker.write_text("x")
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(blocker / "numba"))
    folder = compile_cache.configure_numba_cache(_package(clean_env))
    assert folder.parent == clean_env / "user-cache" / "numba"


def test_folders_of_old_sources_are_dropped_after_an_hour(clean_env, monkeypatch):
    """The two newest other kernel folders stay; older ones go once unwritten for an hour."""
    base = clean_env / "user-cache" / "numba"
    now = time.time()
    ages = {"kernels-a": 60, "kernels-b": 120, "kernels-c": 600, "kernels-d": 7200}
    for name, age in [*ages.items(), ("unrelated", 9000)]:
        (base / name).mkdir(parents=True)
        os.utime(base / name, (now - age, now - age))
    folder = compile_cache.configure_numba_cache(_package(clean_env))
    left = sorted(p.name for p in base.iterdir())
    assert left == sorted(["kernels-a", "kernels-c", "kernels-b", folder.name, "unrelated"])
    os.utime(base / "kernels-c", (now - 8000, now - 8000))
    monkeypatch.delenv("NUMBA_CACHE_DIR")  # a new process, not a child of this one
    compile_cache.configure_numba_cache(_package(clean_env))
    assert sorted(p.name for p in base.iterdir()) == sorted(
        ["kernels-a", "kernels-b", folder.name, "unrelated"]
    )


def test_a_changed_callee_module_is_compiled_again(tmp_path):
    """numba keys a cached kernel on its own file: without the digest folder, `g` would keep
    calling the old `f` from its cache after a.py changed."""
    package = _package(tmp_path)
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "numba"))
    script = (
        "import sys; from pathlib import Path\n"
        "from autotrack.compile_cache import configure_numba_cache\n"
        f"sys.path.insert(0, {str(tmp_path)!r})\n"
        f"configure_numba_cache(Path({str(package)!r}))\n"
        "from pkg.b import g\n"
        "print(g(1))\n"
    )
    outputs = []
    for body in ("return x + 1", "return x + 1", "return x + 2"):
        _package(tmp_path, body)
        done = subprocess.run([sys.executable, "-c", script], env=env, capture_output=True)
        assert done.returncode == 0, done.stderr.decode()
        outputs.append(int(done.stdout.split()[-1]))
    assert outputs == [20, 20, 30]


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
    env[userdirs.CACHE_ENV] = str(tmp_path / "cache")
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
    """A fresh process importing the tracker and the pipeline does not import dask (through
    pyFFTW's optional dask interface), scipy.io, or scipy.spatial (rotations load where a
    quaternion is first converted), and dask.array.fft still imports afterwards."""
    pytest.importorskip("dask.array")
    script = (
        "import sys\n"
        "import autotrack\n"
        "from autotrack import AutoTrack\n"
        "import autotrack.pipeline\n"
        "heavy = [m for m in ('dask', 'scipy.io', 'scipy.spatial') if m in sys.modules]\n"
        "print(','.join(heavy))\n"
        "import dask.array.fft\n"
        "print(callable(dask.array.fft.fft_wrap))\n"
    )
    done = subprocess.run(
        [sys.executable, "-c", script], capture_output=True, text=True, check=True
    )
    assert done.stdout.split("\n")[:2] == ["", "True"]


_NUMBA_TARGET_MODULES = (  # imported only by numba's CPU-target refresh
    "numba.np.polynomial.polynomial_core",
    "numba.typed.typeddict",
    "numba.np.random.generator_core",
)
_SCIPY_SUBPACKAGES = (  # the tracker loads the compiled modules it uses without these
    "scipy.fft",
    "scipy.linalg",
    "scipy.special",
    "scipy.fftpack",
)

_TRACK_AND_REPORT = (
    "import sys, json\n"
    "import numpy as np\n"
    "from autotrack import AutoTrack, preset\n"
    "from autotrack.evaluation.datasets import load_otb_sequence\n"
    "from autotrack.io.frames import read_image\n"
    "sequence = load_otb_sequence(sys.argv[1])[0]\n"
    "tracker = AutoTrack(preset('autotrack'))\n"
    "boxes = [tracker.init(read_image(sequence.frame_paths[0]), sequence.init_box).box]\n"
    "boxes += [tracker.update(read_image(p)).box for p in sequence.frame_paths[1:4]]\n"
    "refreshed = [m for m in sys.argv[2:] if m in sys.modules]\n"
    "from numba import njit\n"
    "doubled = njit(lambda n: np.arange(n) * 2)(4).tolist()  # compiles: needs the refresh\n"
    "print(json.dumps([boxes, refreshed, doubled]))\n"
)


@pytest.mark.slow
def test_second_process_loads_kernels_without_numba_target_refresh(tmp_path):
    """A first process with empty caches compiles; the second tracks the same frames without
    numba's target refresh (the implementation modules it imports stay unloaded), with the
    same boxes bit for bit, and numba still compiles a new function there (which refreshes the
    target itself). Nor does it import scipy's fft, linalg, special or fftpack subpackages
    (pocketfft's binding and cython_blas are loaded alone, `scipy_binaries`). Also the lab11
    table is kept in the user cache by the first process."""
    folder = shared_sequence_dir("DTB70", "Surfing06")
    env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp_path / "numba"))
    env[userdirs.CACHE_ENV] = str(tmp_path / "cache")
    watched = [*_NUMBA_TARGET_MODULES, *_SCIPY_SUBPACKAGES]
    command = [sys.executable, "-c", _TRACK_AND_REPORT, str(folder), *watched]
    runs = []
    for _ in range(2):
        done = subprocess.run(command, env=env, capture_output=True, text=True)
        assert done.returncode == 0, done.stderr
        runs.append(json.loads(done.stdout.splitlines()[-1]))
    (first_boxes, first_refreshed, _), (boxes, refreshed, doubled) = runs
    assert first_refreshed  # the first process compiled: numba refreshed its target
    assert list((tmp_path / "cache" / "arrays").glob("lab11-*.npy"))
    assert boxes == first_boxes
    assert refreshed == []
    assert doubled == [0, 2, 4, 6]


def test_cached_array_is_built_once_and_rebuilt_when_corrupt(clean_env):
    calls = []

    def build():
        calls.append(1)
        return np.arange(12, dtype=np.float32).reshape(3, 4) / 7

    first = compile_cache.cached_array("demo", "key 1", build)
    second = compile_cache.cached_array("demo", "key 1", build)
    assert len(calls) == 1 and second.tobytes() == first.tobytes() and second.dtype == np.float32
    compile_cache.cached_array("demo", "key 2", build)  # another key: another file
    assert len(calls) == 2
    for path in (clean_env / "user-cache" / "arrays").glob("demo-*.npy"):
        path.write_bytes(b"\x93NUMPY truncated")
    assert compile_cache.cached_array("demo", "key 1", build).tobytes() == first.tobytes()
    assert len(calls) == 3


def test_lab11_table_from_the_cache_is_the_built_table():
    from autotrack.tracker import features

    table = features.lab11_table()
    assert not table.flags.writeable
    assert table.tobytes() == features.build_lab11_table().tobytes()
