"""The machine description that speed figures carry (autotrack.machine) and the FFTW wisdom
file's CPU key, read from /proc/cpuinfo texts of three kinds of CPU."""

from __future__ import annotations

import pytest

from autotrack import machine


def _cpuinfo(model: str, flags: str, processors: int = 2, family: str = "25") -> str:
    """A /proc/cpuinfo text listing `processors` alike x86 CPUs."""
    return "".join(
        f"processor\t: {index}\nvendor_id\t: X\ncpu family\t: {family}\nmodel\t\t: 1\n"
        f"model name\t: {model}\nflags\t\t: fpu sse2 {flags}\n\n"
        for index in range(processors)
    )


ZEN3 = _cpuinfo("AMD EPYC 7B13", "sse4_2 avx avx2 fma")
SKYLAKE_SP = _cpuinfo("Intel(R) Xeon(R) Platinum 8175M", "sse4_2 avx avx2 avx512f avx512bw", 4, "6")
NEOVERSE = "processor\t: 0\nBogoMIPS\t: 243.75\nFeatures\t: fp asimd evtstrm crc32\n\n"


@pytest.mark.parametrize(
    ("text", "simd", "avx512", "cpu"),
    [
        (ZEN3, "AVX2", False, "AMD EPYC 7B13 (family 25, model 1)"),
        (SKYLAKE_SP, "AVX-512", True, "Intel(R) Xeon(R) Platinum 8175M (family 6, model 1)"),
        (NEOVERSE, "NEON", False, None),
    ],
)
def test_the_description_names_the_cpu_and_its_widest_simd(text, simd, avx512, cpu):
    described = machine.describe_machine(machine.cpu_fields(machine.cpuinfo_lines(text)))
    assert described["simd"] == simd and described["avx512"] is avx512
    if cpu is not None:
        assert described["cpu"] == cpu
    assert described["logical_cores"] and described["python"]
    assert set(described["libraries"]) == set(machine.LIBRARIES)
    line = machine.machine_line(described)
    assert line.startswith(f"{described['cpu']}, {described['logical_cores']} logical cores, ")
    assert (f"{simd} (no AVX-512)" in line) == (simd not in ("AVX-512", "NEON"))
    assert f"numba {described['libraries']['numba']}" in line


def test_only_the_first_cpus_lines_are_read():
    lines = machine.cpuinfo_lines(ZEN3.replace("avx2", "avx2 first", 1))
    assert machine.cpu_fields(lines)["flags"].endswith("avx2 first fma")
    assert machine.simd_level("fpu sse2") == "unknown"
