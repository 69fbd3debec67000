"""Dask engine for sweeps (the optional ``dask`` extra: ``pip install 'stochpend[dask]'``).

Imported lazily by :mod:`stochpend.sweep`; an ``ImportError`` here becomes the one-line
message "scheduler=... requires the `dask` extra". Each task is
:func:`stochpend.runs._blocks.run_block` on one (parameter set, block of batches) and returns that
block's per-batch sums; the client places them (exact), so the scheduler, the number of
workers and lost-and-rescheduled tasks cannot change a bit of the result.

Schedulers:

- ``"sync"``: Dask's synchronous scheduler, in this process (mostly for debugging).
- ``"threads"``: Dask's threaded scheduler, ``workers`` threads; each task runs its Numba
  kernels on ``NUMBA_NUM_THREADS // workers`` threads (needs a thread-safe Numba threading
  layer, omp or tbb).
- ``"local"``: a ``distributed.LocalCluster`` of ``workers`` processes, one thread each.
- ``"tcp://HOST:8786"`` (any address with ``://``): an existing scheduler.
- a ``distributed.Client``: used as it is and left open.

On distributed workers each task sets its Numba threads to the host's CPUs divided by the Dask
threads on that host (measured when the sweep starts), so that workers do not oversubscribe.
"""

from __future__ import annotations

import contextlib
import importlib.util
import logging
import os
import warnings
from collections.abc import Callable, Iterator
from typing import TYPE_CHECKING, Any
from urllib.parse import urlparse

import dask
import distributed
import numba
from dask.callbacks import Callback

from stochpend.model import plugins
from stochpend.numerics._sources import BUILD
from stochpend.runs._blocks import BlockResult, Task, run_block

if TYPE_CHECKING:  # pragma: no cover - annotations only
    from stochpend.runs.sweep import SweepPlan

__all__ = ["connect"]


def _cpu_count() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except (AttributeError, OSError):  # pragma: no cover - not Linux
        return os.cpu_count() or 1


def _host(address: str) -> str:
    return urlparse(address).hostname or address


class LocalSchedulerEngine:
    """Dask's embedded schedulers: no server, tasks in this process."""

    dashboard = None

    def __init__(self, scheduler: str, workers: int | None) -> None:
        self.scheduler = "sync" if scheduler == "synchronous" else scheduler
        self.workers = 1 if self.scheduler == "sync" else (workers or _cpu_count())
        self.slots = self.workers

    def info(self) -> dict[str, Any]:
        return {"engine": f"dask-{self.scheduler}", "scheduler": self.scheduler, "workers": self.workers}

    def run(self, plan: SweepPlan, tasks: list[Task], tracker: Any,
            on_result: Callable[[BlockResult], None], *, backend: str = "cpu",
            precision: str = "float64") -> None:
        numba_threads = None
        if self.scheduler == "threads":
            _check_threadsafe_numba()
            numba_threads = max(1, numba.config.NUMBA_NUM_THREADS // self.workers)
        calls = [
            dask.delayed(run_block, pure=False)(
                dask.delayed(plan.configs[t.set_index], traverse=False), t.set_index, t.b0, t.b1,
                numba_threads=numba_threads, backend=backend, precision=precision, plugins=plugins.loaded(),
            )
            for t in tasks
        ]

        def posttask(key: Any, result: Any, dsk: Any, state: Any, worker_id: Any) -> None:
            if isinstance(result, BlockResult):
                on_result(result)
                tracker.done(result)

        with Callback(posttask=posttask):
            dask.compute(*calls, scheduler=self.scheduler, num_workers=self.workers)


def _check_threadsafe_numba() -> None:
    """Concurrent kernels from several threads need the omp or tbb threading layer."""
    from stochpend.engine.runner import run_batches
    from stochpend.model.settings import SimulationConfig

    run_batches(SimulationConfig.build(paths=2, t_max=0.1, n_times=1), 0, 2)  # loads the kernels
    layer = numba.threading_layer()
    if layer not in ("omp", "tbb"):
        raise ValueError(
            f"scheduler='threads' is not accepted: Numba's {layer!r} threading layer is not thread-safe; "
            "use the default (in process), 'local', or install tbb"
        )


def _worker_facts() -> dict[str, Any]:
    from stochpend.numerics import _cputarget
    from stochpend.numerics._sources import BUILD

    return {"cpus": _cpu_count(), "build": BUILD, "cpu_target": _cputarget.describe()}


def _remote_block(config: Any, set_index: int, b0: int, b1: int, threads_by_host: dict[str, int],
                  version: str, backend: str = "cpu", precision: str = "float64",
                  plugins_: tuple[str, ...] = ()) -> BlockResult:
    """A task on a distributed worker: pick Numba threads for this host, then run the block
    (on the worker's own GPU when ``backend="cuda"``: one worker process per GPU)."""
    worker = distributed.get_worker()
    threads = threads_by_host.get(_host(worker.address))
    if threads is None:  # a worker that joined after the sweep started
        threads = max(1, _cpu_count() // max(1, worker.state.nthreads))
    return run_block(config, set_index, b0, b1, numba_threads=threads, expect_version=version,
                     backend=backend, precision=precision, plugins=plugins_)


class DistributedEngine:
    """A ``distributed`` cluster: a LocalCluster, a scheduler address, or a given Client."""

    def __init__(self, client: distributed.Client, address: str) -> None:
        self.client = client
        self.address = address
        info = client.scheduler_info(n_workers=-1)
        self.dashboard = None
        if info.get("services", {}).get("dashboard"):
            self.dashboard = client.dashboard_link
            if address == "local" and importlib.util.find_spec("bokeh") is None:
                self.dashboard += " (to see it: pip install 'bokeh>=3.1')"
        workers = info.get("workers", {})
        self.n_workers = len(workers)
        self.slots = max(1, sum(w.get("nthreads", 1) for w in workers.values()))
        facts = client.run(_worker_facts) if workers else {}
        for addr, f in facts.items():
            if f["build"] != BUILD:
                raise ValueError(
                    f"scheduler={address!r} is not accepted: worker {addr} runs stochpend {f['build']}, "
                    f"this is stochpend {BUILD}; install the same stochpend on every worker"
                )
        dask_threads: dict[str, int] = {}
        cpus: dict[str, int] = {}
        for addr, w in workers.items():
            host = _host(addr)
            dask_threads[host] = dask_threads.get(host, 0) + int(w.get("nthreads", 1))
            if addr in facts:
                cpus[host] = min(cpus.get(host, facts[addr]["cpus"]), facts[addr]["cpus"])
        self.threads_by_host = {h: max(1, cpus.get(h, 1) // n) for h, n in dask_threads.items()}
        # What each worker's kernels are compiled for: bits agree across targets by design, and
        # STOCHPEND_CPU_TARGET=baseline on every worker makes the targets one (docs/scale-out.md).
        self.cpu_targets = sorted({f.get("cpu_target", "?") for f in facts.values()})

    def info(self) -> dict[str, Any]:
        return {"engine": "dask-distributed", "scheduler": self.address, "workers": self.n_workers,
                "worker_cpu_targets": "; ".join(self.cpu_targets)}

    def run(self, plan: SweepPlan, tasks: list[Task], tracker: Any,
            on_result: Callable[[BlockResult], None], *, backend: str = "cpu",
            precision: str = "float64") -> None:
        futures = [
            self.client.submit(_remote_block, plan.configs[t.set_index], t.set_index, t.b0, t.b1,
                               self.threads_by_host, BUILD, backend, precision, plugins.loaded(), pure=False,
                               key=f"stochpend-block-{t.set_index}-{t.b0}-{os.urandom(4).hex()}")
            for t in tasks
        ]
        try:
            for future in distributed.as_completed(futures):
                result = future.result()
                on_result(result)
                tracker.done(result)
                future.release()
        except BaseException:
            self.client.cancel(futures)
            raise


@contextlib.contextmanager
def connect(scheduler: Any, workers: int | None) -> Iterator[Any]:
    """Yield an engine for ``scheduler``; close what this function started."""
    if isinstance(scheduler, distributed.Client):
        yield DistributedEngine(scheduler, str(scheduler.scheduler.address))
        return
    if scheduler in ("sync", "synchronous", "threads"):
        yield LocalSchedulerEngine(scheduler, workers)
        return
    if scheduler == "local":
        n = workers or _cpu_count()
        with warnings.catch_warnings():
            # Another cluster on this machine holds port 8787: Dask picks a free port and
            # warns; the address actually used is printed with the dashboard note.
            warnings.filterwarnings("ignore", message="Port 8787 is already in use", category=UserWarning)
            # Dask's own log is not the user's business here: on Ctrl-C or SIGTERM every
            # cancelled task and every worker killed after its 4 s grace logged a line (72 lines
            # and 4 tracebacks before 'interrupted'), and a worker whose heartbeat fell in the
            # scheduler's closing logged an ERROR with a traceback (a fresh-clone CI's SIGTERM
            # test, once). What fails in a task reaches the user as its exception, in one line.
            cluster = distributed.LocalCluster(n_workers=n, threads_per_worker=1, processes=True,
                                               dashboard_address=":8787", silence_logs=logging.CRITICAL)
        with cluster, distributed.Client(cluster) as client:
            engine = DistributedEngine(client, "local")
            engine.address = cluster.scheduler_address
            yield engine
        return
    try:
        client = distributed.Client(scheduler, timeout=dask.config.get("distributed.comm.timeouts.connect"))
    except (OSError, TimeoutError) as exc:
        raise ValueError(f"scheduler={scheduler!r} is not accepted: cannot connect ({exc})") from None
    try:
        yield DistributedEngine(client, scheduler)
    finally:
        client.close()
