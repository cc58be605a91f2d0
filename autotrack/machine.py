"""The machine a speed figure was measured on: CPU model, logical cores, SIMD level, versions.

Frames per second mean little without the CPU: the tracker's compiled kernels and FFTs
use the widest SIMD the CPU has, and the same code runs about twice as fast on a CPU with
AVX-512 as on one with AVX2 only (docs/benchmarks.md, twelfth round). `autotrack bench` writes
this description into its JSON summary and prints it under its table; the speed benchmark
prints it first.
"""

from __future__ import annotations

import os
import platform
from importlib import metadata
from pathlib import Path

CPUINFO = Path("/proc/cpuinfo")

SIMD_LEVELS = (
    ("avx512f", "AVX-512"),
    ("avx2", "AVX2"),
    ("avx", "AVX"),
    ("sse4_2", "SSE4.2"),
    ("asimd", "NEON"),
)
"""(/proc/cpuinfo flag, name), widest first: the first flag the CPU has names its SIMD level."""

LIBRARIES = ("numpy", "numba", "opencv-contrib-python-headless", "scipy")
"""The libraries whose builds set the speed of a frame, in the description's order."""


CPU_KEYS = ("model name", "cpu family", "model", "flags", "Features")
"""The /proc/cpuinfo keys read (x86 names the SIMD extensions in `flags`, Arm in `Features`)."""


def cpuinfo_lines(cpuinfo: str, keys: tuple[str, ...] = CPU_KEYS) -> dict[str, str]:
    """The first CPU's line for each of `keys` in a /proc/cpuinfo text, whole (newline
    included), by key; a key the text lacks is absent."""
    lines: dict[str, str] = {}
    for line in cpuinfo.splitlines(keepends=True):
        key = line.split(":", 1)[0].strip()
        if key in keys and key not in lines:
            lines[key] = line
    return lines


def read_cpuinfo(keys: tuple[str, ...] = CPU_KEYS) -> dict[str, str]:
    """`cpuinfo_lines` of this machine's /proc/cpuinfo ({} where there is none)."""
    try:
        return cpuinfo_lines(CPUINFO.read_text(encoding="utf-8", errors="replace"), keys)
    except OSError:
        return {}


def cpu_fields(lines: dict[str, str]) -> dict[str, str]:
    """The values of `cpuinfo_lines`' lines, by key."""
    return {
        key: line.split(":", 1)[1].strip() if ":" in line else "" for key, line in lines.items()
    }


def simd_level(flags: str) -> str:
    """The widest SIMD instruction set named in a CPU's flags ("unknown" when none is)."""
    present = set(flags.split())
    return next((name for flag, name in SIMD_LEVELS if flag in present), "unknown")


def describe_machine(fields: dict[str, str] | None = None) -> dict[str, object]:
    """This machine as a JSON-ready dict: cpu, logical_cores, simd, avx512, os, python and the
    versions of `LIBRARIES` (None for one not installed). `fields`: the `cpu_fields` to describe
    instead of this machine's."""
    fields = cpu_fields(read_cpuinfo()) if fields is None else fields
    flags = fields.get("flags", fields.get("Features", ""))
    cpu = fields.get("model name") or platform.processor() or platform.machine() or None
    if cpu is not None and fields.get("cpu family") and fields.get("model"):
        cpu += f" (family {fields['cpu family']}, model {fields['model']})"
    versions: dict[str, str | None] = {}
    for name in LIBRARIES:
        try:
            versions[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            versions[name] = None
    return {
        "cpu": cpu,
        "logical_cores": os.cpu_count(),
        "simd": simd_level(flags),
        "avx512": "avx512f" in flags.split(),
        "os": f"{platform.system()} {platform.release()}",
        "python": platform.python_version(),
        "libraries": versions,
    }


def machine_line(machine: dict[str, object]) -> str:
    """`describe_machine`'s dict as one line: 'AMD EPYC (family 25, model 1), 2 logical cores,
    AVX2 (no AVX-512); Python 3.11.7, numpy 2.4.6, ...'."""
    simd = str(machine["simd"])
    if simd != "AVX-512" and simd != "NEON":
        simd += " (no AVX-512)"
    libraries = machine.get("libraries") or {}
    versions = ", ".join(
        f"{name.removesuffix('-contrib-python-headless')} {version}"
        for name, version in libraries.items()  # type: ignore[union-attr]
        if version is not None
    )
    return (
        f"{machine['cpu'] or 'unknown CPU'}, {machine['logical_cores']} logical cores, {simd}; "
        f"Python {machine['python']}" + (f", {versions}" if versions else "")
    )
