"""A Dask sweep that loses a worker mid-sweep, against the same sweep in process (test_faults.py).

Usage: ``python _fault_dask.py BACKEND OUT.json`` (BACKEND: ``cpu``, or ``cuda`` with
NUMBA_ENABLE_CUDASIM=1 in the environment, which the worker processes inherit).

A LocalCluster of two worker processes runs the sweep; a worker plugin makes the worker that
starts the sweep's third task kill itself with SIGKILL (once in the whole cluster: a marker
file), so a task is lost in flight after others have finished. Dask reschedules it on a
worker the nanny restarts. Written to OUT.json: whether every variable is bit-identical to
the in-process sweep, and what happened to the worker.
"""

from __future__ import annotations

import faulthandler
import json
import os
import signal
import sys
import tempfile
from pathlib import Path

import distributed
import numpy as np

SPECS = {
    "cpu": {
        "base": {"noise": "ou", "omega": 1.0, "paths": 60, "t_max": 4.0, "n_times": 5, "seed": 2,
                 "n_batches": 12},
        "grid": {"D": [1.0, 10.0], "tau": [0.1, 1.0]},
    },
    # The simulator runs ~1e3 path-steps a second: a handful of paths, two output times.
    "cuda": {
        "base": {"noise": "ou", "omega": 1.0, "paths": 4, "t_max": 1.0, "times": [0.5, 1.0],
                 "h_max": 0.1, "seed": 2, "n_batches": 2},
        "case": [{"D": 1.0, "tau": 1.0}, {"D": 4.0, "tau": 0.5}],
    },
}
TASKS_PER_SET = {"cpu": 3, "cuda": 2}
KILL_AT_TASK = 3  # the worker that starts the third task dies


class KillAtNthTask(distributed.WorkerPlugin):
    """Kill (SIGKILL) the worker that starts the sweep's n-th task; once per cluster."""

    def __init__(self, folder: str, n: int) -> None:
        self.folder = folder
        self.n = n

    def transition(self, key, start, finish, **kwargs):
        if finish != "executing" or not str(key).startswith("stochpend-block-"):
            return
        started = Path(self.folder) / "started"
        with open(started, "a") as f:
            f.write(f"{key}\n")
        if len(started.read_text().splitlines()) < self.n:
            return
        try:
            fd = os.open(Path(self.folder) / "killed", os.O_CREAT | os.O_EXCL | os.O_WRONLY)
        except FileExistsError:  # already done once: the rescheduled task runs normally
            return
        os.write(fd, f"{os.getpid()} {key}".encode())
        os.close(fd)
        os.kill(os.getpid(), signal.SIGKILL)


def main(backend: str, out_path: str) -> None:
    from stochpend.sweep import load_spec, sweep

    # Never hang silently: after 240 s, print every thread's stack and exit (the test shows it).
    faulthandler.dump_traceback_later(240, exit=True)

    spec = load_spec(SPECS[backend])
    reference = sweep(spec, backend=backend, tasks_per_set=TASKS_PER_SET[backend])
    folder = tempfile.mkdtemp(prefix="stochpend-fault-dask-")
    report: dict = {}
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                  dashboard_address=None) as cluster, distributed.Client(cluster) as client:
        before = client.run(os.getpid)
        client.register_plugin(KillAtNthTask(folder, KILL_AT_TASK))
        ds = sweep(spec, scheduler=client, backend=backend, tasks_per_set=TASKS_PER_SET[backend])
        client.wait_for_workers(2, timeout=120)  # the nanny restarts the killed one
        after = client.run(os.getpid)
        killed = Path(folder, "killed")
        victim = int(killed.read_text().split()[0]) if killed.exists() else None
        report.update(
            killed=killed.exists(), victim=victim, workers_before=sorted(before.values()),
            workers_after=sorted(after.values()),
            tasks_started=len(Path(folder, "started").read_text().splitlines()),
            n_tasks=int(ds.attrs["sweep_tasks"]), backend=str(ds.attrs["backend"]),
        )
    report["different"] = [
        name for name in reference.variables
        if not np.array_equal(reference[name].values, ds[name].values,
                              equal_nan=reference[name].dtype.kind == "f")
    ]
    report["same_variables"] = sorted(reference.variables) == sorted(ds.variables)
    Path(out_path).write_text(json.dumps(report))


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2])
