"""Statistics of the golden CPU runs (tests/statistical/test_golden.py's CASES), saved as a fixture.

Usage: ``python tests/golden/make_golden.py OUT.npz`` (from the repository root).

Saved per case: the output times and every variable of ``simulate(**case, bias_paths=0)``
(the bias estimate's variables are left out: issue 19 changed them on purpose, and its own
tests cover them). tests/statistical/test_golden.py compares every array bit for bit, on the
machine's own instruction set and on the x86-64-v3 baseline (``make test-baseline``).

tests/golden/stats.npz was made by this script at the commit that added it (issue 37), on a
2-core AMD EPYC (Zen 4, AVX-512), numba 0.68.1, numpy 2.4.6, glibc's FMA variants of the C
library's functions; the same file comes out with the kernels compiled for x86-64-v3 and numpy
held to AVX2 (docs/development.md, "What is bit-identical, and where").
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))


def arrays() -> dict[str, np.ndarray]:
    """``{"case/variable": values}`` of every golden case, computed now."""
    import stochpend
    from tests.statistical.test_golden import CASES

    out: dict[str, np.ndarray] = {}
    for name, case in CASES.items():
        ds = stochpend.simulate(**case, bias_paths=0)
        out[f"{name}/time"] = ds["time"].values
        for variable in ds.data_vars:
            out[f"{name}/{variable}"] = ds[variable].values
    return out


if __name__ == "__main__":
    if len(sys.argv) != 2:
        raise SystemExit("usage: python tests/golden/make_golden.py OUT.npz")
    np.savez_compressed(sys.argv[1], **arrays())
