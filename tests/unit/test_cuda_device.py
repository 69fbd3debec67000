"""On a real GPU only (skipped elsewhere, CI included): Philox as the CUDA kernels compile it.

The simulator runs rng's Python functions, so it cannot test the CUDA-target implementation of
rng.mulhilo (one mul.wide.u32, registered by stochpend.engine.cuda). Here a kernel computes
the Random123 known answers and draws of paths and counters with high words, which must equal
the CPU's exactly (words), to the last bits (float64 normals: libdevice's log/sin/cos against
glibc's) and to float32 round-off (float32 normals). Run on the GPU machine with
``python -m pytest -q tests/unit/test_cuda_device.py``.
"""

from __future__ import annotations

import numba
import numpy as np
import pytest

from stochpend.engine import cuda as gpu
from stochpend.numerics import rng
from stochpend.numerics.mathlib import LIBM
from tests.unit.test_rng import KAT, _words

pytestmark = pytest.mark.gpu

try:  # a module global, as numba.cuda kernels expect
    from numba import cuda
except Exception:  # pragma: no cover
    cuda = None


def _require_gpu() -> None:
    ok, why = gpu.availability()
    if not ok or gpu._simulator_enabled():
        pytest.skip(f"needs a real GPU: {why}")
    if not gpu.PHILOX_MUL_WIDE_U32:
        pytest.skip("the mul.wide.u32 Philox is registered with NVIDIA's numba-cuda only")


def test_philox_known_answers_and_draws_on_the_device():
    _require_gpu()
    normals32 = rng.normals_with(LIBM, np.float32)

    @cuda.jit
    def kernel(inputs, words, paths, counters, key, draws, z64, z32):
        i = cuda.grid(1)
        if i < inputs.shape[0]:
            w = rng.philox4x32_10(inputs[i, 0], inputs[i, 1], inputs[i, 2], inputs[i, 3],
                                  inputs[i, 4], inputs[i, 5])
            for j in range(4):
                words[i, j] = w[j]
        if i < paths.shape[0]:
            d = rng.draw_words(key[0], key[1], paths[i], counters[i])
            for j in range(4):
                draws[i, j] = d[j]
            z64[i, 0], z64[i, 1] = rng.draw_normals(key[0], key[1], paths[i], counters[i])
            z32[i, 0], z32[i, 1] = normals32(key[0], key[1], paths[i], counters[i])

    inputs = np.array([_words(c) + _words(k) for c, k, _ in KAT], dtype=np.uint64)
    n = 4096
    i = np.arange(n, dtype=np.uint64)
    paths = i * np.uint64(2654435761) + (i % np.uint64(3)) * np.uint64(2**32)
    counters = i * np.uint64(40503) + (i % np.uint64(2)) * np.uint64(2**33 + 5)
    key = np.array(rng.seed_to_key(2**40 + 99), dtype=np.uint64)
    words = np.zeros((len(KAT), 4), dtype=np.uint64)
    draws = np.zeros((n, 4), dtype=np.uint64)
    z64 = np.zeros((n, 2))
    z32 = np.zeros((n, 2), dtype=np.float32)
    with gpu._quiet():  # 32 blocks: numba-cuda's own NumbaPerformanceWarning, an error under pytest
        kernel[(n + 127) // 128, 128](inputs, words, paths, counters, key, draws, z64, z32)

    for row, (_, _, expected) in zip(words, KAT, strict=True):
        assert [int(w) for w in row] == [int(w, 16) for w in expected.split()]
    cpu_words = numba.njit(rng.draw_words)
    cpu64 = numba.njit(rng.draw_normals)
    cpu32 = numba.njit(normals32)
    want_words = np.array([cpu_words(key[0], key[1], p, c) for p, c in zip(paths, counters, strict=True)], dtype=np.uint64)
    np.testing.assert_array_equal(draws, want_words)
    want64 = np.array([cpu64(key[0], key[1], p, c) for p, c in zip(paths, counters, strict=True)])
    np.testing.assert_allclose(z64, want64, rtol=1e-13, atol=1e-13)
    want32 = np.array([cpu32(key[0], key[1], p, c) for p, c in zip(paths, counters, strict=True)], dtype=np.float32)
    np.testing.assert_allclose(z32, want32, rtol=2e-6, atol=2e-6)
