"""Run pytest as an AVX2-only x86-64 machine computes: the kernels compiled for the x86-64-v3
baseline (STOCHPEND_CPU_TARGET=baseline) and numpy's CPU dispatch held to AVX2
(NPY_DISABLE_CPU_FEATURES: every dispatch target above X86_V3 this machine has; OpenBLAS's
Haswell kernels). On an AVX-512 machine this is what a laptop or an AVX2 server will see; on an
AVX2 machine it is the machine itself with the kernels compiled for the baseline.

Usage: ``python tests/golden/run_baseline.py [pytest arguments]`` (``make test-baseline``).
"""

from __future__ import annotations

import os
import subprocess
import sys


def numpy_above_avx2() -> list[str]:
    """numpy's dispatch targets above X86_V3 that this machine supports (only those may be named)."""
    from numpy._core._multiarray_umath import __cpu_dispatch__, __cpu_features__

    above = [t for t in __cpu_dispatch__ if t not in ("X86_V2", "X86_V3") and __cpu_features__.get(t, False)]
    return above


def main(args: list[str]) -> int:
    from stochpend.numerics import _cputarget

    why = _cputarget._host_supports_baseline()
    if why is not None:  # nothing to emulate: this machine cannot run x86-64-v3 code
        print(f"baseline: not run, {why} (the golden tests skip on such a machine too)", file=sys.stderr)
        return 0
    env = dict(os.environ, STOCHPEND_CPU_TARGET="baseline", OPENBLAS_CORETYPE="Haswell",
               NPY_DISABLE_CPU_FEATURES=" ".join(numpy_above_avx2()))
    print(f"baseline: STOCHPEND_CPU_TARGET=baseline NPY_DISABLE_CPU_FEATURES={env['NPY_DISABLE_CPU_FEATURES']!r} "
          "OPENBLAS_CORETYPE=Haswell", file=sys.stderr)
    return subprocess.call([sys.executable, "-m", "pytest", *args], env=env)


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
