"""Compile a run's bias-pair kernel in a helper process while this process compiles the rest.

A first run (an empty kernel cache) spends most of its time compiling, and Numba compiles under
one lock per process: the run's SIMD kernel, then the bias estimate's pair kernel, each a few
seconds, one after the other on a machine with idle cores. On a machine with two or more CPUs,
:func:`start` launches ``python -m stochpend.runs._compile_helper``: it runs a two-pair bias
estimate of the same KernelSpec, which compiles the pair kernel into Numba's on-disk cache while this
process compiles and runs the ensemble; the bias estimate here then waits for the helper
(:meth:`Helper.wait`, counted as compile time) and loads the kernel instead of compiling it.

The kernel is the same code under the same name (:mod:`stochpend.numerics._jitcache`: the name carries
the KernelSpec and the code digest), so the numbers are those of a kernel compiled here, bit for bit.
Both processes may write the kernels they share (``init``, ``accumulate``) to the cache at
once; each KernelSpec's kernel has its own index, so whichever write wins holds the same code.

Off (nothing is launched) for another backend, a run without bias estimate, a user's model (its
kernels are not cached), a pair kernel or the run's kernels already cached (nothing to
overlap), one CPU, Numba's JIT disabled, or ``STOCHPEND_COMPILE_HELPER=0``. A helper that fails
or is too slow changes nothing but time: the bias estimate compiles the kernel itself.
"""

from __future__ import annotations

import dataclasses
import os
import pickle
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

__all__ = ["ENV", "Helper", "start", "wanted"]

#: Set to 0 to compile everything in the process that runs (no helper).
ENV = "STOCHPEND_COMPILE_HELPER"
#: Longest wait for the helper (seconds) before the bias estimate compiles the kernel itself.
WAIT_S = 180.0
#: The helper's command (a test replaces it with one that fails).
COMMAND = (sys.executable, "-m", "stochpend.runs._compile_helper")


class Helper:
    """A running helper process."""

    def __init__(self, process: subprocess.Popen) -> None:
        self._process = process

    def wait(self) -> float:
        """Wait for the helper to finish (at most :data:`WAIT_S`, then stop it); returns the
        seconds waited."""
        started = time.perf_counter()
        try:
            self._process.wait(timeout=WAIT_S)
        except subprocess.TimeoutExpired:
            self.stop()
        return time.perf_counter() - started

    def stop(self) -> None:
        """Stop the helper if it still runs (the run failed or was interrupted)."""
        if self._process.poll() is None:
            self._process.kill()
            self._process.wait()


def wanted(config: Any, *, backend: str, pairs: bool) -> bool:
    """Whether a run of ``config`` (``pairs``: with a bias estimate) would have its pair kernel
    compiled by the helper (see the module docstring); launches nothing, compiles nothing.
    The CLI's estimate uses it to leave the pair kernel's compile out."""
    if backend != "cpu" or not pairs or os.environ.get(ENV, "1").strip() == "0":
        return False
    if (os.cpu_count() or 1) < 2:
        return False
    import numba

    if numba.config.DISABLE_JIT:
        return False
    from stochpend.engine import cpu
    from stochpend.numerics._jitcache import in_cache

    spec = cpu.spec_for(config)
    if not spec.cacheable:
        return False
    kernels = cpu.compiled_kernels(spec, pairs=True)
    pair_kernels = [k for kind, k in kernels.items() if kind.startswith("pairs")]
    own = [k for kind, k in kernels.items() if not kind.startswith("pairs")]
    return not (all(in_cache(k) for k in pair_kernels) or all(in_cache(k) for k in own))


def start(config: Any, *, backend: str, bias_paths: int) -> Helper | None:
    """Launch the helper for ``config``'s pair kernel when it can save time (:func:`wanted`);
    None when not."""
    if not wanted(config, backend=backend, pairs=bool(bias_paths)):
        return None
    package_root = str(Path(__file__).resolve().parents[2])  # this very stochpend, not another
    env = {**os.environ,
           "PYTHONPATH": os.pathsep.join(filter(None, [package_root, os.environ.get("PYTHONPATH")])),
           ENV: "0"}
    try:
        process = subprocess.Popen(COMMAND, stdin=subprocess.PIPE, stdout=subprocess.DEVNULL,
                                   stderr=subprocess.DEVNULL, env=env)
        assert process.stdin is not None
        # Without user observables: they are registered in this process only, and the pair
        # kernel the helper is for does not depend on them.
        process.stdin.write(pickle.dumps(dataclasses.replace(config, observables=())))
        process.stdin.close()
    except (OSError, pickle.PicklingError, ValueError):
        return None
    return Helper(process)


def _main() -> None:
    """The helper: read the pickled configuration (from its parent, on stdin) and run a
    two-pair bias estimate on one thread, which compiles (and caches) its kernels."""
    config = pickle.loads(sys.stdin.buffer.read())
    import numba

    numba.set_num_threads(1)
    from stochpend.runs import bias

    bias.estimate(config, 2)


if __name__ == "__main__":  # pragma: no cover - run as a helper process
    _main()
