"""scipy's compiled modules loaded from their files, without the scipy subpackages around them.

The library calls a few compiled routines of scipy: pocketfft's transforms, MINPACK's
Levenberg-Marquardt for the weighted pose refinement, and (through numba's BLAS check)
`scipy.linalg.cython_blas`. Importing them the usual way runs the `__init__` of their
subpackages first: `import scipy.fft` costs 0.27-0.29 s of a fresh process (its Python layer,
scipy._lib's array-API machinery, and scipy.special for the DCT helpers), `scipy.linalg`
another 0.08-0.3 s, and `scipy.optimize` ~0.45 s (a stall of the first frame that refines a
pose with unequal weights). The extension files themselves load in about a millisecond.

`load_compiled` loads such a module from its file and registers it in `sys.modules` under its
own name, so a later ordinary import of the subpackage (the app's, a user's) finds it there and
reuses the same module rather than loading the binary twice. When the file is not where this
layout of scipy puts it, it falls back to the ordinary import: slower, never wrong.
"""

from __future__ import annotations

import importlib
import importlib.machinery
import importlib.util
import sys
import threading
from pathlib import Path
from types import ModuleType


def load_compiled(name: str) -> ModuleType:
    """The compiled extension module `name` (a dotted path such as
    "scipy.fft._pocketfft.pypocketfft"), loaded from its file without importing the packages
    it sits in (the top-level package is only located, not imported)."""
    module = sys.modules.get(name)
    if module is not None:
        return module
    with _loading:  # two threads asking at once load the file once
        module = sys.modules.get(name)
        if module is not None:
            return module
        spec = _extension_spec(name)
        if spec is None:
            return importlib.import_module(name)
        module = importlib.util.module_from_spec(spec)
        sys.modules[name] = module
        try:
            spec.loader.exec_module(module)
        except BaseException:
            del sys.modules[name]
            raise
        return module


_loading = threading.Lock()


def _extension_spec(name: str) -> importlib.machinery.ModuleSpec | None:
    """The spec of the extension file for `name`, or None when there is no such file."""
    top, *parts = name.split(".")
    if not parts:
        return None
    top_spec = importlib.util.find_spec(top)  # locates the package without importing it
    if top_spec is None or not top_spec.submodule_search_locations:
        return None
    for location in top_spec.submodule_search_locations:
        folder = Path(location, *parts[:-1])
        for suffix in importlib.machinery.EXTENSION_SUFFIXES:
            path = folder / (parts[-1] + suffix)
            if path.is_file():
                loader = importlib.machinery.ExtensionFileLoader(name, str(path))
                return importlib.util.spec_from_file_location(name, path, loader=loader)
    return None
