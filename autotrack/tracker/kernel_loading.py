"""Loading the tracker's cached numba kernels without numba's whole target initialisation.

Before its first cached load numba refreshes its CPU target: it imports and registers every
implementation module it has (NumPy ufuncs, datetime, typed containers, random, ...; ~0.2 s,
a fifth of a second process's time to its first tracked frame). A cached kernel does not need
any of it: its machine code is already linked, and numba's runtime (NRT, which kernels that
allocate arrays call) is the only part of that initialisation a loaded kernel uses. Numba's
compiler still refreshes the target itself before it compiles anything (a cache miss, a new
signature, another library's kernel), so deferring the refresh changes what is imported when,
never which code runs: the kernels are the same bytes from the same cache.

Loading a kernel that uses numpy's linear algebra runs numba's BLAS check, `import
scipy.linalg.cython_blas`, which imports all of scipy.linalg first (~0.1-0.3 s). The check only
needs the compiled module, so it is loaded from its file beforehand (`scipy_binaries`) and the
check finds it there.
"""

from __future__ import annotations

import sys
from types import ModuleType

from numba.core.caching import FunctionCache
from numba.core.dispatcher import Dispatcher
from numba.core.runtime import nrt

from autotrack.scipy_binaries import load_compiled


class _CacheWithoutRefresh(FunctionCache):
    """numba's per-function cache, loading a kernel after initialising only the runtime."""

    def load_overload(self, sig, target_context):
        nrt.rtsys.initialize(target_context)  # what a loaded kernel needs of the refresh
        with self._guard_against_spurious_io_errors():
            return self._load_overload(sig, target_context)


def _supported() -> bool:
    """The numba internals this relies on are there (numba 0.5x-0.6x); otherwise no change."""
    return all(
        callable(getattr(FunctionCache, name, None))
        for name in ("load_overload", "_load_overload", "_guard_against_spurious_io_errors")
    ) and callable(getattr(nrt.rtsys, "initialize", None))


def kernels_of(*modules: ModuleType) -> list[Dispatcher]:
    """The numba kernels (`@njit` dispatchers) at the top level of `modules`, each once (a kernel
    one module imports from another is listed once)."""
    kernels: dict[int, Dispatcher] = {}
    for module in modules:
        for value in vars(module).values():
            if isinstance(value, Dispatcher):
                kernels.setdefault(id(value), value)
    return list(kernels.values())


def package_kernels(package: str = "autotrack") -> list[Dispatcher]:
    """`kernels_of` every module of `package` imported so far."""
    return kernels_of(*_imported_modules(package))


def load_without_refresh(*modules: ModuleType) -> int:
    """Make the cached `@njit(cache=True)` kernels defined at the top level of `modules` load
    without numba's target refresh; returns how many kernels now do."""
    if not _supported():
        return 0
    load_compiled("scipy.linalg.cython_blas")  # what numba's BLAS check imports
    count = 0
    for kernel in kernels_of(*modules):
        if type(kernel._cache) is FunctionCache:
            kernel._cache.__class__ = _CacheWithoutRefresh
            count += 1
    return count


def load_package_without_refresh(package: str = "autotrack") -> int:
    """`load_without_refresh` for every module of `package` imported so far."""
    return load_without_refresh(*_imported_modules(package))


def _imported_modules(package: str) -> list[ModuleType]:
    prefix = package + "."
    return [m for name, m in list(sys.modules.items()) if name.startswith(prefix) and m]
