"""Machine-code patterns that make a numba kernel slow, in every kernel of the package.

Compiles every `@njit` kernel afresh (a temporary numba cache: numba shows no assembly for
kernels loaded from its cache) by tracking `tracker.warmup`'s synthetic target in colour and in
grey, then counts, per kernel and signature, the instructions that have cost us before:

- `vmaskmovps`/`vmaskmovpd` stores: LLVM emits them for a loop that stores conditionally,
  which includes `a[i] = x if c else a[i]` (storing back the value just loaded counts as no
  store); AMD's Zen cores run them at a fraction of a plain store's rate (docs/history.md,
  eighteenth round). Masked loads (a load only one branch of a select uses) are counted too,
  not flagged: they cost far less;
- `vgather`: gathers, slower than scalar loads on most x86 cores;
- and, for context, the packed (SIMD) and scalar float arithmetic: a hot loop with no packed
  instructions did not vectorise (an in-place call whose output overlaps an input makes LLVM's
  run-time overlap check take the scalar loop: the same code shows both versions, so compare
  timings too).

    python benchmarks/kernel_asm.py [--all]

Only kernels with masked stores or gathers are listed unless `--all` is given.
"""

from __future__ import annotations

import argparse
import os
import re
import sys
import tempfile
import warnings

PATTERNS = {
    "masked stores": re.compile(r"\bvmaskmovp[sd]\s+%[xy]mm\d+,\s*%[xy]mm\d+,\s*[^%\s]"),
    "masked loads": re.compile(r"\bvmaskmovp[sd]\s+[^%\s][^,]*,"),
    "gather": re.compile(r"\bvgather\w+"),
    "packed": re.compile(r"\bv(?:add|sub|mul|div|fmadd\w*)p[sd]\b"),
    "scalar": re.compile(r"\bv(?:add|sub|mul|div|fmadd\w*)s[sd]\b"),
}


def _name(kernel) -> str:
    return f"{kernel.py_func.__module__}.{kernel.py_func.__qualname__}"


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--all", action="store_true", help="list every compiled kernel")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as cache:
        os.environ["NUMBA_CACHE_DIR"] = cache  # before numba is imported: compile afresh
        from autotrack.tracker.kernel_loading import package_kernels
        from autotrack.tracker.warmup import warm_up  # imports every module with kernels

        print(f"compiled by tracking the warm-up target: {warm_up():.1f} s")
        flagged = 0
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # numba warns for kernels it has no assembly of
            kernels = sorted(package_kernels(), key=_name)
            for kernel in kernels:
                for signature, assembly in kernel.inspect_asm().items():
                    counts = {key: len(p.findall(assembly)) for key, p in PATTERNS.items()}
                    suspect = counts["masked stores"] or counts["gather"]
                    flagged += bool(suspect)
                    if suspect or args.all:
                        described = ", ".join(f"{key} {count}" for key, count in counts.items())
                        arguments = ", ".join(str(t) for t in signature)[:100]
                        print(f"{_name(kernel)}({arguments}): {described}")
        print(f"{len(kernels)} kernels, {flagged} signatures with masked stores or gathers")
    return 0


if __name__ == "__main__":
    sys.exit(main())
