"""A kernel loaded from Numba's on-disk cache computes what it computed when it was compiled.

Numba names each compiled function ``<qualname>$<n>``, ``n`` a counter unique in one process
only; a cached kernel refers to the integrator's pieces (``build.<locals>.advance_path``) by
those names. Without care, process B that compiles another Spec's pieces first gives them the
names the writer process A gave the cached kernel's pieces, and the cached kernel, once
loaded, calls B's functions: other noise, wrong numbers, no error. (Seen in the test suite:
the fixed-step OU kernel computed with the dichotomous noise's step after the bias estimate
of a dichotomous run.) ``stochpend._jitcache`` draws the counter's start at random per process.
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np

import stochpend

HELPER = Path(__file__).with_name("_jitcache_check.py")
ROOT = Path(__file__).resolve().parents[2]


def _run(cache: Path, out: Path, *noises: str) -> np.ndarray:
    src = Path(stochpend.__file__).resolve().parents[1]
    env = {**os.environ, "NUMBA_CACHE_DIR": str(cache),
           "PYTHONPATH": os.pathsep.join([str(src), str(ROOT), *filter(None, [os.environ.get("PYTHONPATH")])])}
    env.pop("NUMBA_ENABLE_CUDASIM", None)
    r = subprocess.run([sys.executable, str(HELPER), str(out), *noises], capture_output=True, text=True,
                       env=env, timeout=600)
    assert r.returncode == 0, r.stderr
    return np.load(out)


def test_a_cached_kernel_never_calls_another_processes_pieces(tmp_path):
    cache = tmp_path / "numba-cache"
    cache.mkdir()
    # A: compiles and caches the OU kernels alone.
    ou_alone = _run(cache, tmp_path / "a.npy", "ou")
    # B: compiles the dichotomous kernels first (the same compile sequence as A, so without the
    # fix its pieces get A's numbers), then loads the OU kernels from A's cache.
    ou_after = _run(cache, tmp_path / "b.npy", "dichotomous", "ou")
    assert any(cache.rglob("*.nbc")), "nothing was cached: the test does not test the cache"
    np.testing.assert_array_equal(ou_after, ou_alone)
