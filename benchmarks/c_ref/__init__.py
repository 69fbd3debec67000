"""Build and call the C reference (``stochpend_ref.c``) through ctypes: the fixed-step scheme
(:func:`run`) and the adaptive one, stochpend's default (:func:`run_adaptive`).

The shared library is compiled at run time into a temporary directory (nothing compiled is
kept in the repository). Two flavours:

* ``flavour="fast"`` (the benchmark's floor): ``gcc -O3 -march=native -ffast-math -fopenmp
  -mprefer-vector-width=512``. The compiler contracts multiply-adds into FMAs, replaces
  divisions by reciprocal multiplications and, in the SIMD variant, calls glibc's vector math
  (libmvec) for log/sin/cos on 8 doubles at a time. Each path-step then agrees with stochpend to
  a few ulps, not bit for bit. (gcc's default for this CPU is 256-bit vectors; asking for 512
  bits makes the SIMD variant about 1.4x faster here, see docs/performance.md.)
* ``flavour="fast256"``: the same without ``-mprefer-vector-width=512`` (gcc's default), kept
  for the record.
* ``flavour="exact"`` (the smoke test): the same source with ``-ffp-contract=off -fno-fast-math``:
  IEEE arithmetic in Numba's order and glibc's scalar libm, so the final states are identical
  to stochpend's.
"""

from __future__ import annotations

import ctypes
import shutil
import subprocess
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

SOURCE = Path(__file__).with_name("stochpend_ref.c")
FLAGS = {
    "fast": ["-O3", "-march=native", "-ffast-math", "-fopenmp", "-mprefer-vector-width=512"],
    "fast256": ["-O3", "-march=native", "-ffast-math", "-fopenmp"],
    "exact": ["-O3", "-march=native", "-fopenmp", "-ffp-contract=off", "-fno-fast-math"],
}

_CACHE: dict[str, ctypes.CDLL] = {}


def compiler() -> str | None:
    """The C compiler used (gcc), or None when there is none."""
    return shutil.which("gcc")


def build(flavour: str = "fast") -> ctypes.CDLL:
    """Compile the reference into a temporary directory and load it (cached per flavour)."""
    if flavour in _CACHE:
        return _CACHE[flavour]
    cc = compiler()
    if cc is None:
        raise RuntimeError("gcc not found: the C reference cannot be built")
    out = Path(tempfile.mkdtemp(prefix="stochpend_cref_")) / "libstochpend_ref.so"
    flags = FLAGS[flavour]
    # Compile with the flavour's flags but link without -ffast-math: linking with it adds
    # crtfastmath.o, whose constructor turns on flush-to-zero/denormals-are-zero for the whole
    # process that loads the library (pytest, the benchmark), silently changing every later
    # computation with denormals in that process.
    obj = out.with_suffix(".o")
    subprocess.run([cc, *flags, "-fPIC", "-c", "-o", str(obj), str(SOURCE)], check=True,
                   capture_output=True, text=True)
    link = [f for f in flags if f == "-fopenmp"]
    subprocess.run([cc, "-shared", *link, "-o", str(out), str(obj), "-lm"], check=True,
                   capture_output=True, text=True)
    lib = ctypes.CDLL(str(out))
    dptr = np.ctypeslib.ndpointer(dtype=np.float64, flags="C_CONTIGUOUS")
    for name in ("sp_run_scalar", "sp_run_simd"):
        fn = getattr(lib, name)
        fn.restype = ctypes.c_long
        fn.argtypes = [ctypes.c_long, ctypes.c_uint64, ctypes.c_uint64, ctypes.c_double,
                       ctypes.c_double, ctypes.c_double, ctypes.c_double, ctypes.c_double,
                       ctypes.c_int, dptr, dptr, dptr]
    lptr = np.ctypeslib.ndpointer(dtype=np.int64, flags="C_CONTIGUOUS")
    for name in ("sp_run_adaptive_scalar", "sp_run_adaptive_simd"):
        fn = getattr(lib, name)
        fn.restype = ctypes.c_long
        fn.argtypes = [ctypes.c_long, ctypes.c_uint64, ctypes.c_uint64, ctypes.c_double,
                       ctypes.c_double, ctypes.c_double, ctypes.c_double, ctypes.c_double,
                       ctypes.c_int, dptr, ctypes.c_int, dptr, dptr, dptr, lptr]
    lib.sp_micro.restype = ctypes.c_double
    lib.sp_micro.argtypes = [ctypes.c_int, ctypes.c_long]
    lib.sp_max_threads.restype = ctypes.c_int
    _CACHE[flavour] = lib
    return lib


def compile_command(flavour: str = "fast") -> str:
    """The compiler command line, for the record."""
    return " ".join(["gcc", *FLAGS[flavour], "-shared", "-fPIC"])


@dataclass
class CResult:
    x: np.ndarray
    Omega: np.ndarray
    xi: np.ndarray
    steps: int
    seconds: float

    def energy(self, omega: float) -> np.ndarray:
        return 0.5 * self.Omega**2 - omega**2 * np.cos(self.x)


def run(paths: int, t_max: float, h: float, *, D: float = 1.0, tau: float = 1.0,
        omega: float = 1.0, seed: int = 0, threads: int = 0, variant: str = "simd",
        flavour: str = "fast") -> CResult:
    """Run the reference on paths 0 .. paths-1 from t = 0 to t_max at fixed step h.

    ``threads=0`` leaves OpenMP's default. ``seconds`` is the time of the C call alone
    (initial conditions and time stepping).
    """
    lib = build(flavour)
    fn = {"simd": lib.sp_run_simd, "scalar": lib.sp_run_scalar}[variant]
    x = np.empty(paths)
    Om = np.empty(paths)
    xi = np.empty(paths)
    t0 = time.perf_counter()
    steps = fn(paths, 0, seed, D, tau, omega * omega, h, t_max, threads, x, Om, xi)
    seconds = time.perf_counter() - t0
    return CResult(x, Om, xi, int(steps), seconds)


def run_adaptive(paths: int, times, *, h_max: float = 0.05, step_c: float = 0.1,
                 D: float = 1.0, tau: float = 1.0, omega: float = 1.0, seed: int = 0,
                 threads: int = 0, variant: str = "simd", flavour: str = "fast") -> CResult:
    """Run the reference's adaptive scheme (stochpend's default step control) on paths
    0 .. paths-1 through the output times ``times`` (increasing, > 0), landing on each.

    ``steps`` is the total over paths (``CResult.path_steps`` per path); ``seconds`` the time
    of the C call alone.
    """
    lib = build(flavour)
    fn = {"simd": lib.sp_run_adaptive_simd, "scalar": lib.sp_run_adaptive_scalar}[variant]
    times = np.ascontiguousarray(times, dtype=np.float64)
    x = np.empty(paths)
    Om = np.empty(paths)
    xi = np.empty(paths)
    per_path = np.empty(paths, dtype=np.int64)
    t0 = time.perf_counter()
    steps = fn(paths, 0, seed, D, tau, omega * omega, h_max, step_c, times.size, times, threads,
               x, Om, xi, per_path)
    seconds = time.perf_counter() - t0
    result = CResult(x, Om, xi, int(steps), seconds)
    result.path_steps = per_path
    return result
