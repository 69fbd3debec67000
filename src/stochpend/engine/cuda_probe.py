"""Can this CUDA stack compile and run a kernel? A tiny kernel, once per process.

``numba.cuda`` may import, find a driver and a GPU, and still fail at the first kernel
compile: numba-cuda 0.30.4 with numpy 2.5 stops with "module 'numpy' has no attribute
'row_stack'". :func:`stochpend.engine.cuda.availability` looks at the driver and the
device only, so where the backend is chosen (``stochpend.runs.simulate.resolve_backend``, and
``stochpend info``) :func:`probe` also compiles a four-thread kernel, launches it and checks
what it wrote. The answer is cached for the process (one compile, a fraction of a second on a
GPU); under Numba's CUDA simulator the kernel runs as Python.
"""

from __future__ import annotations

import functools

import numpy as np

try:  # a module global: the CUDA simulator swaps it in the kernel's globals
    from numba import cuda
except Exception:  # pragma: no cover - numba without its CUDA target (probe() says so)
    cuda = None

__all__ = ["probe"]

#: What the probe kernel writes: out[i] = 2 i + 1.
_EXPECTED = 2.0 * np.arange(4) + 1.0


def _one_line(error: BaseException) -> str:
    text = " ".join(str(error).split()).rstrip(" :")
    return f"{type(error).__name__}: {text}" if text else type(error).__name__


def _compile_and_launch() -> np.ndarray:
    """Compile the probe kernel, launch it on one block of four threads, return what it wrote."""
    if cuda is None:
        raise ImportError("numba.cuda cannot be imported")

    @cuda.jit
    def kernel(out):  # pragma: no cover - device code
        i = cuda.grid(1)
        if i < out.shape[0]:
            out[i] = 2.0 * i + 1.0

    from stochpend.engine.cuda import _quiet

    # One block of four threads: numba-cuda warns of a grid under 128 blocks (its own
    # NumbaPerformanceWarning class), which every `--backend cuda|auto` and `info` would show.
    with _quiet():
        out = cuda.device_array(_EXPECTED.size, dtype=np.float64)
        kernel[1, _EXPECTED.size](out)
        return out.copy_to_host()


@functools.lru_cache(maxsize=1)
def probe() -> tuple[bool, str]:
    """``(True, "...")`` when a kernel compiles, runs and writes the right numbers here, else
    ``(False, one-line reason)``; never raises. Call it only where
    :func:`~stochpend.engine.cuda.availability` said yes (it creates a CUDA context)."""
    try:
        got = _compile_and_launch()
    except Exception as error:
        return False, f"a test kernel fails to compile or run ({_one_line(error)})"
    if not np.array_equal(got, _EXPECTED):
        return False, f"a test kernel ran but wrote {got.tolist()} instead of {_EXPECTED.tolist()}"
    return True, "a test kernel compiled and ran"
