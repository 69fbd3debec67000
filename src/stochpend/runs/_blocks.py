"""A sweep's unit of work: a :class:`Task` (batches of one parameter set), the
:class:`BlockResult` it returns, and :func:`run_block`, the function every engine runs (in this
process, on Dask threads or on a remote Dask worker).

Below :mod:`stochpend.sweep`, which plans and merges, and the Dask backend, which ships tasks to
workers: both import it, neither imports the other's caller.
"""

from __future__ import annotations

import time as _time
from dataclasses import dataclass

import numba
import numpy as np

from stochpend.engine.runner import run_batches
from stochpend.model.settings import SimulationConfig
from stochpend.numerics._sources import BUILD
from stochpend.runs.lifecycle import numba_threads as numba_threads_of
from stochpend.text.progress import Progress

__all__ = ["BlockResult", "Task", "run_block"]


@dataclass(frozen=True)
class Task:
    """One unit of work: batches ``b0 .. b1 - 1`` of parameter set ``set_index``."""

    set_index: int
    b0: int
    b1: int
    paths: int


@dataclass
class BlockResult:
    """What a task returns: the sums of its batches (all a merge needs), and its cost."""

    set_index: int
    b0: int
    b1: int
    sums: np.ndarray  # (b1 - b0, n_times, N_SUMS)
    hist: np.ndarray  # (n_times, n_bins + 2)
    path_steps: int
    paths: int
    seconds: float
    #: The final passage times of its paths for each first passage (n_passages, paths), None
    #: without (stochpend.model.passage): the per-path values the law of a passage time is read from.
    passage: np.ndarray | None = None


def run_block(config: SimulationConfig, set_index: int, b0: int, b1: int, *,
              numba_threads: int | None = None, expect_version: str | None = None,
              progress: Progress | None = None, backend: str = "cpu",
              precision: str = "float64", plugins: tuple[str, ...] = ()) -> BlockResult:
    """Simulate batches ``b0 .. b1 - 1`` of one set on ``backend``: the function every engine
    runs (a Dask worker that owns a GPU runs its blocks with ``backend="cuda"``). ``plugins``:
    what the client loaded (:func:`stochpend.plugins.loaded`), loaded here first, so that a
    worker process knows the set's noise."""
    from stochpend.model import plugins as _plugins

    for name in plugins:
        _plugins.load(name)
    if expect_version is not None and expect_version != BUILD:
        raise ValueError(f"a worker runs stochpend {BUILD}, the client stochpend {expect_version}: "
                         f"install the same stochpend everywhere")
    started = _time.perf_counter()
    # A worker may have fewer threads than the client asked for: as many as it has.
    threads = None if numba_threads is None else max(1, min(int(numba_threads), numba.config.NUMBA_NUM_THREADS))
    with numba_threads_of(threads):
        acc, path_steps = run_batches(config, b0, b1, backend=backend, precision=precision,
                                      progress=progress)
    p0 = b0 * config.batch_size
    paths = min(b1 * config.batch_size, config.paths) - p0
    passage = None if acc.passage is None else acc.passage[:, p0:p0 + paths].copy()
    return BlockResult(set_index, b0, b1, acc.sums[b0:b1].copy(), acc.hist, int(path_steps), paths,
                       _time.perf_counter() - started, passage)
