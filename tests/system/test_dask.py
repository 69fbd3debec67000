"""The Dask engine: every scheduler gives the same bits; a killed worker changes nothing."""

from __future__ import annotations

import os
import signal
import threading
import time

import numpy as np
import pytest

pytest.importorskip("dask", reason="the `dask` extra is not installed (pip install 'stochpend[dask]')")
distributed = pytest.importorskip("distributed", reason="the `dask` extra is not installed (pip install 'stochpend[dask]')")

from stochpend.sweep import load_spec, sweep  # noqa: E402

pytestmark = pytest.mark.dask

SPEC = {
    "description": "tiny Fig. 2",
    "base": {"noise": "ou", "omega": 1.0, "paths": 60, "t_max": 4.0, "n_times": 5, "seed": 2, "n_batches": 12},
    "grid": {"D": [1.0, 10.0, 100.0], "tau": [0.1, 1.0, 10.0]},
}


def _assert_identical(a, b):
    assert set(a.data_vars) == set(b.data_vars)
    for name in a.variables:
        assert np.array_equal(a[name].values, b[name].values, equal_nan=a[name].dtype.kind == "f"), name


@pytest.fixture(scope="module")
def reference():
    """The sweep in this process, one task a set (no Dask involved)."""
    return sweep(SPEC)


@pytest.mark.parametrize(("scheduler", "workers"), [("sync", None), ("threads", 2), ("threads", 3)])
def test_embedded_schedulers_are_bit_identical(reference, scheduler, workers):
    ds = sweep(SPEC, scheduler=scheduler, workers=workers, tasks_per_set=5)
    _assert_identical(reference, ds)
    assert ds.attrs["sweep_engine"] == f"dask-{scheduler}" and ds.attrs["sweep_tasks"] == 9 * 5


def test_local_cluster_two_workers_is_bit_identical(reference):
    notes = []

    class Notes:
        def start(self, total, description):
            pass

        def update(self, done):
            pass

        def finish(self):
            pass

        def note(self, text):
            notes.append(text)

    ds = sweep(SPEC, scheduler="local", workers=2, tasks_per_set=3, progress=Notes())
    _assert_identical(reference, ds)
    assert ds.attrs["sweep_engine"] == "dask-distributed" and ds.attrs["sweep_workers"] == 2
    assert any(n.startswith("Dask dashboard: http") for n in notes)
    # The workers, asked before their first kernel, name the target their kernels compiled for:
    # this machine's, as this process's (512-bit vectors on an AVX-512 host: stochpend.numerics._cputarget).
    assert ds.attrs["sweep_worker_cpu_targets"] == ds.attrs["cpu_target"]


class TaskCounter:
    """Progress that records the tasks done, so the test can act in the middle of a sweep."""

    def __init__(self):
        self.done = 0
        self.total = None
        self.event = threading.Event()

    def start(self, total, description):
        pass

    def update(self, done):
        pass

    def finish(self):
        pass

    def tasks(self, done, total):
        self.done, self.total = done, total
        if done >= 3:
            self.event.set()


def test_killed_worker_changes_nothing(reference):
    """SIGKILL one of two worker processes mid-sweep: Dask reschedules, the bits are the same."""
    spec = load_spec(SPEC)
    cluster = distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True,
                                       dashboard_address=":0")  # a free port: 8787 may be a parallel test's
    client = distributed.Client(cluster)
    try:
        pids = client.run(os.getpid)
        assert len(pids) == 2
        counter = TaskCounter()
        outcome = {}

        def work():
            try:
                outcome["ds"] = sweep(spec, scheduler=client, tasks_per_set=12, progress=counter)
            except BaseException as exc:  # reported in the main thread
                outcome["error"] = exc

        thread = threading.Thread(target=work)
        thread.start()
        deadline = time.monotonic() + 60
        while not counter.event.wait(0.05) and thread.is_alive() and time.monotonic() < deadline:
            pass
        if "error" in outcome:  # e.g. workers refused (another build): report it, not a timeout
            raise outcome["error"]
        assert counter.event.is_set(), "no task finished within 60 s"
        victim_address, victim = sorted(pids.items())[0]
        os.kill(victim, signal.SIGKILL)
        killed_at = counter.done
        thread.join(120)
        assert not thread.is_alive(), "the sweep did not finish within 120 s of the kill"
        if "error" in outcome:
            raise outcome["error"]
        assert killed_at < counter.total, "the kill landed after the sweep: make it longer"
        _assert_identical(reference, outcome["ds"])
        # The worker really died: its pid is gone and the nanny started a fresh process.
        with pytest.raises(ProcessLookupError):
            os.kill(victim, 0)
        assert victim not in client.run(os.getpid).values()
    finally:
        client.close()
        cluster.close()


def test_given_client_is_left_open(reference, monkeypatch):
    # a free dashboard port: 8787 may be a parallel test's (a warning, an error under pytest)
    with distributed.LocalCluster(n_workers=1, threads_per_worker=2, processes=False,
                                  dashboard_address=":0") as cluster, distributed.Client(cluster) as client:
        ds = sweep(SPEC, scheduler=client, tasks_per_set=2)
        _assert_identical(reference, ds)
        assert client.status == "running"
        # Workers with other code (another version, or an edited tree) are refused up front.
        import stochpend.runs.dask as backend

        monkeypatch.setattr(backend, "BUILD", "0.0.0 (code 000000000000)")
        with pytest.raises(ValueError, match=r"is not accepted: worker .* runs stochpend .*, this is stochpend 0.0.0"):
            sweep(SPEC, scheduler=client)


def test_unreachable_scheduler_is_one_line():
    import dask

    refused = r"scheduler='tcp://127.0.0.1:9' is not accepted: cannot connect"
    # A connect timeout of 2 s: the refusal comes after it (no wall time is asserted: issue 37).
    with dask.config.set({"distributed.comm.timeouts.connect": "2s"}), pytest.raises(ValueError, match=refused):
        sweep(SPEC, scheduler="tcp://127.0.0.1:9")


@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM])
def test_an_interrupted_local_cluster_sweep_ends_in_one_line(tmp_path, signum):
    """NEW50: Ctrl-C of 'sweep --scheduler local --workers 2' printed 72 lines with 4 tracebacks
    (cancelled tasks, 'Worker process still alive after 4.0 seconds, killing') before
    'interrupted'; SIGTERM once a CommClosedError traceback. Now the one line alone."""
    import subprocess
    import sys
    from pathlib import Path

    src = Path(__file__).resolve().parents[2] / "src"
    env = {k: v for k, v in os.environ.items() if k != "NUMBA_ENABLE_CUDASIM"}
    env["PYTHONPATH"] = os.pathsep.join([str(src), *filter(None, [env.get("PYTHONPATH")])])
    spec = tmp_path / "long.toml"
    spec.write_text("[base]\npaths = 100000\nt_max = 400.0\nn_times = 3\n[grid]\nD = [0.5, 1.0, 1.5, 2.0]\n")
    proc = subprocess.Popen(
        [sys.executable, "-m", "stochpend", "sweep", str(spec), "--scheduler", "local", "--workers", "2",
         "--bias-paths", "0", "--out", str(tmp_path / "l.nc")],
        stderr=subprocess.PIPE, text=True, cwd=tmp_path, env=env,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    try:
        first = proc.stderr.readline()  # the estimate, then the dashboard line: the cluster is up
        if first.startswith("estimate: "):
            first = proc.stderr.readline()
        assert first.startswith("Dask dashboard: "), first
        time.sleep(3)  # the workers are inside their first blocks
        proc.send_signal(signum)
        _, err = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    assert proc.returncode == 128 + signum, err
    assert err == "interrupted\n", err
    assert not (tmp_path / "l.nc").exists()
