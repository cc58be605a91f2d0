"""FFTW plans searched once per machine and kept on disk, so that every process uses the same.

FFTW chooses a plan by timing candidates. Its patient search (FFTW_PATIENT) finds plans for
the tracker's (channels, rows, cols) transforms that run 1.2-1.4x faster than the measured
ones (FFTW_MEASURE) at a grid side of 50, and 1.5-2.9x faster than estimated ones, for
0.2-1.1 s of planning per shape (docs/benchmarks.md). Being chosen by timing, another plan
rounds differently: the tracker being chaotic, two processes planning on their own would
track differently. So each shape is planned once, by the first process that needs it, and
kept as FFTW wisdom in a file that every later process, and every child of `target_process`,
imports before planning:

- the file is `$AUTOTRACK_FFTW_WISDOM` when set, else
  `cache_root() / "fftw" / "wisdom-<machine>-<cpu model hash>-<pyfftw version>.json`;
- a shape this process has not planned yet is planned under an exclusive `fcntl` lock on
  `<file>.lock`: the file is imported, the plan made from wisdom alone (FFTW_WISDOM_ONLY), and
  only when the shape is missing (or only measured, by an older version) it is searched and
  the merged wisdom written back atomically. Two processes planning one shape at once
  therefore end with one plan;
- a file that cannot be locked, read, parsed or written gives estimated plans (FFTW_ESTIMATE)
  for the rest of the process, never an error: a process never mixes wisdom imported later with
  plans estimated earlier, so its own trackers stay alike.
"""

from __future__ import annotations

import hashlib
import json
import logging
import os
import platform
import sys
import threading
import time
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from autotrack.compile_cache import cache_root
from autotrack.io.atomic import write_text
from autotrack.machine import read_cpuinfo
from autotrack.tracker import pocketfft

try:
    import fcntl
except ImportError:  # not POSIX: no lock, so no shared searched plans
    fcntl = None


def _import_pyfftw():
    """pyFFTW without its dask and scipy interfaces, which the tracker never uses: when they are
    installed, `import pyfftw` imports dask.array (~0.4 s of a fresh process's start-up) for
    `pyfftw.interfaces.dask_fft`, and scipy.fftpack, which imports scipy.fft and scipy.linalg
    (~0.35 s), for `pyfftw.interfaces.scipy_fft(pack)`. A None entry in sys.modules makes those
    optional imports fail fast; a module already imported is left alone."""
    blocked = [name for name in ("dask.array.fft", "scipy.fftpack") if name not in sys.modules]
    for name in blocked:
        sys.modules[name] = None
    try:
        import pyfftw
    finally:
        for name in blocked:
            del sys.modules[name]
    return pyfftw


pyfftw = _import_pyfftw()

WISDOM_ENV = "AUTOTRACK_FFTW_WISDOM"
"""Environment variable naming the wisdom file (the tests point it at a temporary folder)."""

WISDOM_FORMAT = 1
PLANNING_EFFORT = "FFTW_PATIENT"
"""FFTW's planning rigour for the shapes kept in the wisdom file. Wisdom of a less rigorous
search (an older version's FFTW_MEASURE) does not satisfy it: such a shape is searched again
and the file updated."""
_AXES = (-2, -1)
_log = logging.getLogger(__name__)


@dataclass(frozen=True)
class PlanSet:
    """The three plans of one (channels, rows, cols) grid; each owns its input/output arrays."""

    forward: object
    """r2c of (channels, rows, cols) float32 -> (channels, rows, cols // 2 + 1) complex64."""
    inverse: object
    """c2r back (destroys its input; calling it scales by 1 / (rows cols), `inverse_unscaled`
    leaves the scaling to the caller)."""
    h_forward: object
    """A second r2c plan on its own arrays (the same plan as `forward`)."""
    effort: str
    """PLANNING_EFFORT (from the wisdom file), "FFTW_ESTIMATE" (the fallback) or "pocketfft"."""


class _Planner:
    """This process's view of the wisdom file: which shapes it planned and how."""

    def __init__(self) -> None:
        self.lock = threading.Lock()
        self.efforts: dict[tuple[int, int, int], str] = {}
        self.disabled = False
        self.last_measure_seconds = 0.0
        self.good_wisdom: tuple[bytes, ...] | None = None
        """The wisdom of the file as last imported or saved, all this process plans from."""


_planner = _Planner()


def wisdom_path() -> Path:
    """The wisdom file this process reads and writes."""
    configured = os.environ.get(WISDOM_ENV)
    if configured:
        return Path(configured).expanduser()
    return cache_root() / "fftw" / f"wisdom-{_machine_key()}-{pyfftw.__version__}.json"


def _machine_key() -> str:
    """The CPU kind: FFTW wisdom names SIMD codelets, and a plan is only valid on like CPUs."""
    found = read_cpuinfo(("model name", "flags"))  # the first CPU's lines: not the CPU count
    model = (platform.processor() or "") + found.get("model name", "") + found.get("flags", "")
    digest = hashlib.sha256(model.encode()).hexdigest()[:12]
    return f"{platform.machine() or 'cpu'}-{digest}"


def _make_plans(shape: tuple[int, int, int], flags: tuple[str, ...]) -> tuple:
    channels, rows, cols = shape
    spectrum_shape = (channels, rows, cols // 2 + 1)

    def r2c():
        real = pyfftw.empty_aligned(shape, np.float32)
        spectrum = pyfftw.empty_aligned(spectrum_shape, np.complex64)
        return pyfftw.FFTW(real, spectrum, axes=_AXES, direction="FFTW_FORWARD", flags=flags)

    inverse = pyfftw.FFTW(
        pyfftw.empty_aligned(spectrum_shape, np.complex64),
        pyfftw.empty_aligned(shape, np.float32),
        axes=_AXES,
        direction="FFTW_BACKWARD",
        flags=(*flags, "FFTW_DESTROY_INPUT"),
    )
    return r2c(), inverse, r2c()


@contextmanager
def _locked(path: Path):
    """An exclusive lock on `path`.lock for the block (raises OSError when impossible)."""
    if fcntl is None:
        raise OSError("no fcntl on this platform")
    path.parent.mkdir(parents=True, exist_ok=True)
    descriptor = os.open(f"{path}.lock", os.O_RDWR | os.O_CREAT, 0o644)
    try:
        fcntl.flock(descriptor, fcntl.LOCK_EX)
        yield
    finally:
        os.close(descriptor)  # closing releases the lock


def _import_file(path: Path) -> None:
    """Import the wisdom in `path` (none yet is fine); ValueError when it is not valid."""
    try:
        text = path.read_text(encoding="ascii")
    except FileNotFoundError:
        return
    try:
        content = json.loads(text)
        wisdom = tuple(part.encode("ascii") for part in content["wisdom"])
    except (ValueError, KeyError, TypeError, AttributeError, UnicodeError) as error:
        raise ValueError(f"unreadable FFTW wisdom in {path}: {error}") from error
    if content.get("format") != WISDOM_FORMAT or len(wisdom) != 3:
        raise ValueError(f"unknown FFTW wisdom format in {path}")
    if not all(pyfftw.import_wisdom(wisdom)):
        raise ValueError(f"FFTW rejected the wisdom in {path} (another FFTW or CPU)")


def _save_file(path: Path) -> None:
    wisdom = [part.decode("ascii") for part in pyfftw.export_wisdom()]
    write_text(path, json.dumps({"format": WISDOM_FORMAT, "wisdom": wisdom}))


def _plan_from_file(shape: tuple[int, int, int], path: Path) -> tuple:
    """Plans from the file's wisdom, searching (and saving) the shape if it is missing."""
    with _locked(path):
        _import_file(path)
        try:
            return _make_plans(shape, (PLANNING_EFFORT, "FFTW_WISDOM_ONLY"))
        except RuntimeError:
            pass  # not planned on this machine yet
        start = time.perf_counter()
        plans = _make_plans(shape, (PLANNING_EFFORT,))
        _planner.last_measure_seconds = time.perf_counter() - start
        _save_file(path)
        return plans


def largest_prime_factor(n: int) -> int:
    """The largest prime dividing n (n itself for a prime, 1 for n < 2)."""
    largest, factor = 1, 2
    while factor * factor <= n:
        while n % factor == 0:
            largest, n = factor, n // factor
        factor += 1
    return max(largest, n) if n > 1 else largest


def prefers_pocketfft(side: int) -> bool:
    """Whether a grid side transforms faster with pocketfft than with a searched FFTW plan.

    FFTW is fastest on even sides made of small primes; on odd sides and sides with a large
    prime factor its plans (Rader, generic codelets) are 1.1-1.6x slower than pocketfft's
    (the table in docs/benchmarks.md, 42 channels, sides 38-50). A rule on the side, not a
    timing, so the choice is the same in every process and on every machine.
    """
    return side % 2 == 1 or largest_prime_factor(side) > 11


class PocketPlan:
    """pocketfft behind the part of a pyFFTW plan the tracker uses: an input array
    of its own, and a call that transforms it (or the array given) into a new array (an output
    array, if given, is not used)."""

    def __init__(self, input_array: np.ndarray, inverse_size: tuple[int, int] | None = None):
        self.input_array = input_array
        self._inverse_size = inverse_size

    def __call__(self, input_array: np.ndarray | None = None, output_array=None) -> np.ndarray:
        source = self.input_array if input_array is None else input_array
        if self._inverse_size is None:
            return pocketfft.rfft2(source)
        return pocketfft.irfft2(source, self._inverse_size)


def inverse_unscaled(plan: object) -> tuple[np.ndarray, np.float32]:
    """An inverse plan's maps of its own input array, before pyFFTW's 1 / N scaling, and that
    scale: pyFFTW's call multiplies its output by float32(1 / N) in a pass of its own, which
    the caller folds into its next pass over the maps (the same float32 product, so the same
    bits). pocketfft scales inside its transform: its maps, and a scale of 1."""
    if isinstance(plan, PocketPlan):
        return plan(), np.float32(1.0)
    plan.execute()
    return plan.output_array, np.float32(1.0 / plan.N)


def _pocket_plans(shape: tuple[int, int, int]) -> PlanSet:
    channels, rows, cols = shape
    spectrum = np.empty((channels, rows, cols // 2 + 1), np.complex64)
    return PlanSet(
        PocketPlan(np.empty(shape, np.float32)),
        PocketPlan(spectrum, (rows, cols)),
        PocketPlan(np.empty(shape, np.float32)),
        effort="pocketfft",
    )


def plans_for(channels: int, grid_size: tuple[int, int]) -> PlanSet:
    """Forward, inverse and second forward plans of (channels, *grid_size), one thread each:
    pocketfft where `prefers_pocketfft`, FFTW plans (searched, or estimated) elsewhere."""
    shape = (int(channels), int(grid_size[0]), int(grid_size[1]))
    if prefers_pocketfft(shape[1]) or prefers_pocketfft(shape[2]):
        return _pocket_plans(shape)
    with _planner.lock:
        effort = _planner.efforts.get(shape)
        if effort == PLANNING_EFFORT:
            plans = _make_plans(shape, (PLANNING_EFFORT, "FFTW_WISDOM_ONLY"))
        elif effort is None and not _planner.disabled:
            path = wisdom_path()
            try:
                plans, effort = _plan_from_file(shape, path), PLANNING_EFFORT
                _planner.good_wisdom = pyfftw.export_wisdom()
            except (OSError, ValueError) as error:
                _log.warning("FFTW plans estimated, not searched (%s)", error)
                _fall_back()
        if _planner.disabled and effort != PLANNING_EFFORT:
            plans, effort = _make_plans(shape, ("FFTW_ESTIMATE",)), "FFTW_ESTIMATE"
        _planner.efforts[shape] = effort
    return PlanSet(*plans, effort=effort)


def _fall_back() -> None:
    """Estimated plans from now on, and in-memory wisdom back to what the file held when it
    last worked: a shape measured but not saved must not leak into the estimated plans."""
    _planner.disabled = True
    pyfftw.forget_wisdom()
    if _planner.good_wisdom is not None:
        pyfftw.import_wisdom(_planner.good_wisdom)


def planned_shapes() -> dict[tuple[int, int, int], str]:
    """(channels, rows, cols) -> effort of every FFTW shape this process has planned."""
    with _planner.lock:
        return dict(_planner.efforts)


def last_measure_seconds() -> float:
    """Wall-clock seconds the last shape measured by this process took to plan (0 if none)."""
    return _planner.last_measure_seconds
