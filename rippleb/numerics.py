"""Portable numerics: the same bits from the same seeds on every x86-64 CPU with AVX2.

A published row must re-run to the last bit on a reader's machine. Three libraries under
rippleb pick their floating-point code by the CPU they find (``docs/reproducibility.md``
has the measurements):

* **numpy** dispatches its elementwise functions at run time: on a CPU with AVX-512 its
  ``exp``, ``log``, ``tanh``, ``arctan``, ``power`` ... run other code than on an AVX2 CPU
  and differ in the last bit. The simulator feeds such values through the closed-loop
  joint, where one last bit flips an encoder count and grows to 0.1-3 % of a row's error.
* **OpenBLAS** (numpy's and scipy's) chooses its kernels per CPU (``SkylakeX``,
  ``Haswell``, ``Zen``...): the methods' least-squares fits differ by 1e-15..1e-11.
* **OpenBLAS** splits a long dot product over its threads, one partial sum each: the
  thread count (by default the machine's core count) changes the order of the sum.
* **numba** compiles the kernels for the host CPU, but without fast-math nor contraction
  of ``a * b + c`` into FMA, so its code rounds the same everywhere (measured: host,
  ``haswell`` and ``generic`` give bit-identical rows).

:func:`pin` therefore caps numpy's dispatch at X86_V3 (AVX2 + FMA, what every machine of
this kind has) and fixes OpenBLAS's kernels at ``Haswell`` (AVX2 + FMA) on one thread,
through the two libraries' own environment variables. Both are read once, when the library loads, so
:func:`pin` must run before numpy is imported: ``import rippleb`` calls it first thing.
A process that imported numpy before rippleb runs the host's native paths; its rows say
so (:func:`state`, the ``numerics`` column) and the runner warns.
``RIPPLEB_NATIVE_NUMERICS=1`` leaves the libraries alone (for speed measurements).
"""

from __future__ import annotations

import ctypes
import functools
import os
import sys

#: numpy's dispatch targets above X86_V3 (numpy 2.x names, and the 1.x names of the same
#: AVX-512 groups); names a numpy does not know are ignored by it.
NUMPY_ABOVE_AVX2 = ("X86_V4", "AVX512F", "AVX512CD", "AVX512_KNL", "AVX512_KNM", "AVX512_SKX",
                    "AVX512_CLX", "AVX512_CNL", "AVX512_ICL", "AVX512_SPR", "AVX512_FP16")
#: OpenBLAS's kernel family for every CPU with AVX2 and FMA.
OPENBLAS_CORE = "Haswell"
#: Set to 1 to leave numpy's and OpenBLAS's CPU dispatch as the libraries choose.
NATIVE_SWITCH = "RIPPLEB_NATIVE_NUMERICS"
PORTABLE = "portable"
#: Set to ``avx2`` or ``avx512`` to make :func:`machine` describe a CPU of that kind in
#: place of this one (the test suite's ``--fake-cpu``, docs/reproducibility.md): the
#: numbers are still computed by this CPU, only what rippleb reads of it is faked.
FAKE_CPU_SWITCH = "RIPPLEB_FAKE_CPU"
#: The description each fake CPU gives: LLVM's SIMD features and numba's CPU name of a
#: Haswell (AVX2 + FMA) and of a Skylake-X (AVX-512 F/CD/BW/DQ/VL).
FAKE_CPUS = {
    "avx2": ("avx avx2 fma", "haswell"),
    "avx512": ("avx avx2 avx512bw avx512cd avx512dq avx512f avx512vl fma", "skylake-avx512"),
}


def pinned_environment(environ=None) -> dict[str, str]:
    """The variables :func:`pin` sets, given the current ``environ`` (a user's own
    ``NPY_DISABLE_CPU_FEATURES`` entries are kept)."""
    environ = os.environ if environ is None else environ
    disabled = environ.get("NPY_DISABLE_CPU_FEATURES", "").replace(",", " ").split()
    disabled += [name for name in NUMPY_ABOVE_AVX2 if name not in disabled]
    return {"NPY_DISABLE_CPU_FEATURES": " ".join(disabled), "OPENBLAS_CORETYPE": OPENBLAS_CORE,
            "OPENBLAS_NUM_THREADS": "1"}


def native_requested() -> bool:
    """Whether :data:`NATIVE_SWITCH` asks for the libraries' own CPU dispatch."""
    return os.environ.get(NATIVE_SWITCH, "") not in ("", "0")


def pin() -> bool:
    """Set the portable paths in ``os.environ`` for numpy and OpenBLAS, unless numpy is
    already loaded (then it is too late: returns False) or :data:`NATIVE_SWITCH` is set.

    Child processes (the runner's rows, a local Dask cluster's workers) inherit them.
    """
    if native_requested() or "numpy" in sys.modules:
        return False
    os.environ.update(pinned_environment())
    return True


def numpy_targets() -> list[str]:
    """numpy's dispatch targets that are enabled in this process (``X86_V3``...)."""
    try:
        from numpy._core import _multiarray_umath as umath
    except ImportError:  # numpy 1.x
        from numpy.core import _multiarray_umath as umath
    return [name for name in umath.__cpu_dispatch__ if umath.__cpu_features__.get(name)]


def openblas_cores() -> list[str]:
    """The kernel family of each OpenBLAS library loaded (numpy's and scipy's)."""
    cores = []
    for lib in _openblas_libraries():
        getter = _symbol(lib, "get_corename")
        if getter is not None:
            getter.restype = ctypes.c_char_p
            cores.append(getter().decode(errors="replace"))
    return sorted(set(cores))


def openblas_threads(set_to: int | None = None) -> int | None:
    """The thread count of the OpenBLAS libraries numpy and scipy loaded (None if none),
    after setting it to ``set_to`` if given (as threadpoolctl does, without the dependency).

    It decides numbers, not only speed: a dot product split over two threads sums in
    another order than over one.
    """
    counts = []
    for lib in _openblas_libraries():
        getter, setter = _symbol(lib, "get_num_threads"), _symbol(lib, "set_num_threads")
        if getter is None or setter is None:
            continue
        if set_to is not None:
            setter(ctypes.c_int(int(set_to)))
        counts.append(int(getter()))
    return max(counts) if counts else None


def _symbol(lib, name: str):
    """``openblas_<name>`` of ``lib`` under any of the prefixes and suffixes the numpy and
    scipy wheels build it with (``scipy_openblas_get_corename64_``...)."""
    for prefix in ("scipy_openblas_", "openblas_"):
        for suffix in ("64_", ""):
            found = getattr(lib, f"{prefix}{name}{suffix}", None)
            if found is not None:
                return found
    return None


def _openblas_libraries() -> list:
    import numpy  # noqa: F401 - load both libraries before reading them
    import scipy.linalg  # noqa: F401

    libraries = []
    for path in _loaded_openblas():
        try:
            libraries.append(ctypes.CDLL(path))
        except OSError:
            continue
    return libraries


def _loaded_openblas() -> list[str]:
    try:
        with open("/proc/self/maps") as fh:
            paths = {line.split()[-1] for line in fh if "/" in line}
    except OSError:
        return []
    return sorted(p for p in paths if "openblas" in p.rsplit("/", 1)[-1].lower())


@functools.cache  # fixed once numpy and OpenBLAS are loaded; asked for every row
def state() -> str:
    """``portable`` when this process runs the pinned paths, else what it runs instead,
    in one short line (the ``numerics`` column of every row)."""
    targets = numpy_targets()
    above = [t for t in targets if t in NUMPY_ABOVE_AVX2]
    cores, threads = openblas_cores(), openblas_threads()
    foreign = [c for c in cores if c != OPENBLAS_CORE]
    if not above and not foreign and threads in (None, 1) and "X86_V3" in targets:
        return PORTABLE
    return (f"native: numpy {'+'.join(targets) or 'baseline'}, "
            f"OpenBLAS {'/'.join(cores) or 'none'} x{threads}")


def machine() -> dict[str, str]:
    """What decides the numbers besides the versions: the CPU's SIMD features (as LLVM,
    under numba, detects them), the CPU numba compiles for, numpy's enabled dispatch
    targets, OpenBLAS's kernels and the C library (its ``libm`` serves numba's
    ``math.exp``...), and :func:`state`."""
    import platform

    fake = fake_cpu()
    simd, cpu = FAKE_CPUS[fake] if fake else _host_cpu()
    described = {"cpu_simd": simd, "numba_cpu": cpu, "numpy_dispatch": " ".join(numpy_targets()),
                 "openblas": " ".join(openblas_cores()), "libc": " ".join(platform.libc_ver()),
                 "numerics": state()}
    return {**described, "fake_cpu": fake} if fake else described


def _host_cpu() -> tuple[str, str]:
    """This CPU's AVX and FMA features as LLVM detects them, and the CPU numba compiles for."""
    import llvmlite.binding as llvm
    from numba.core import config

    features = llvm.get_host_cpu_features().flatten().split(",")
    simd = sorted(f[1:] for f in features if f.startswith("+") and f[1:].startswith(("avx", "fma")))
    return " ".join(simd), config.CPU_NAME or llvm.get_host_cpu_name()


def other_cpu_kind() -> str:
    """The kind of :data:`FAKE_CPUS` this host is not: ``avx2`` on a CPU with AVX-512,
    ``avx512`` on one without (the suite's ``--fake-cpu other``)."""
    simd, _ = _host_cpu()
    return "avx2" if "avx512f" in simd.split() else "avx512"


def fake_cpu() -> str | None:
    """The fake CPU :data:`FAKE_CPU_SWITCH` asks for (None: describe this one)."""
    name = os.environ.get(FAKE_CPU_SWITCH, "").strip().lower()
    if not name:
        return None
    if name not in FAKE_CPUS:
        from rippleb.errors import InputError

        raise InputError(f"{FAKE_CPU_SWITCH}={name!r} is not a CPU rippleb can fake; "
                         f"use one of {', '.join(FAKE_CPUS)}")
    return name
