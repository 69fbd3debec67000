"""Start-up code of the test suite's subprocesses (tests/conftest.py puts this folder first on
PYTHONPATH): in a process that runs Numba's CUDA simulator (NUMBA_ENABLE_CUDASIM=1), the
simulator's block manager waits for its threads with a short sleep between polls.

numba-cuda's ``BlockManager.run`` polls its threads in a loop that never sleeps, so the polling
thread competes for the GIL with the simulated CUDA threads doing the work; measured on 6 cases
of tests/unit/test_cuda_sim.py, it costs a third of the process's CPU time (9.5 s against 6.8 s)
and changes no number (the simulated threads, their barriers and their order of completion are
the simulator's own; only the poll's pace changes). Any other ``sitecustomize`` on the path
still runs."""

from __future__ import annotations

import importlib.machinery
import importlib.util
import os
import sys

_HERE = os.path.dirname(os.path.abspath(__file__))


def _chain() -> None:
    """Run the next ``sitecustomize`` on the path, which this one hides."""
    path = [p for p in sys.path if os.path.abspath(p or ".") != _HERE]
    spec = importlib.machinery.PathFinder.find_spec("sitecustomize", path)
    if spec is not None and spec.loader is not None:
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)


def _patient_block_manager() -> None:
    import time

    import numpy as np
    from numba.cuda.simulator import kernel

    def run(self, grid_point, *args):  # numba-cuda 0.30's BlockManager.run, with a sleep per poll
        threads = set()
        livethreads = set()
        blockedthreads = set()
        for block_point in np.ndindex(*self._block_dim):
            def target():
                self._f(*args)
            t = kernel.BlockThread(target, self, grid_point, block_point, self._debug)
            t.start()
            threads.add(t)
            livethreads.add(t)
        while livethreads:
            time.sleep(2e-4)
            for t in livethreads:
                if t.syncthreads_blocked:
                    blockedthreads.add(t)
                elif t.exception:
                    for t_other in threads:
                        t_other.abort = True
                        t_other.syncthreads_blocked = False
                        t_other.syncthreads_event.set()
                    raise t.exception[0].with_traceback(t.exception[1])
            if livethreads == blockedthreads:
                for t in blockedthreads:
                    t.syncthreads_blocked = False
                    t.syncthreads_event.set()
                blockedthreads = set()
            livethreads = {t for t in livethreads if t.is_alive()}
        for t in threads:
            if t.exception:
                raise t.exception[0].with_traceback(t.exception[1])

    kernel.BlockManager.run = run


_chain()
if os.environ.get("NUMBA_ENABLE_CUDASIM") == "1":
    try:
        _patient_block_manager()
    except ImportError:  # numba without its CUDA simulator: the test itself will say so
        pass
