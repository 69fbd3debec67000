"""Shared test settings: seeds live here, tolerances are stated in standard errors."""

from __future__ import annotations

import importlib.util
import os
import signal
import time
from pathlib import Path

import pytest

# The suite's subprocesses start with tests/_simulator_site/sitecustomize.py (the CUDA simulator
# without its busy poll, the same numbers: see that file).
_SITE = str(Path(__file__).resolve().parent / "_simulator_site")
if _SITE not in os.environ.get("PYTHONPATH", "").split(os.pathsep):
    os.environ["PYTHONPATH"] = os.pathsep.join(p for p in (_SITE, os.environ.get("PYTHONPATH")) if p)

# No compile helper (stochpend.runs._compile_helper) in the suite's runs and the processes they start:
# the helper buys wall time from an idle core, and the suite keeps both cores busy, so there it
# only adds a process that imports stochpend and compiles beside the run (about 3.7 s of CPU per
# cold KernelSpec, measured; 30 helpers in a cold suite). The numbers are the same either way (the
# helper compiles the same kernel under the same name). The helper's own tests turn it back on:
# tests/system/test_compile_time.py, tests/unit/test_compile_helper.py.
os.environ.setdefault("STOCHPEND_COMPILE_HELPER", "0")

# A suite started in the background ('make test &' in a non-interactive shell) inherits SIGINT
# ignored, and stochpend keeps an ignored SIGINT ignored (tests/unit/test_checkpoint.py): the
# Ctrl-C tests need it delivered, in this process and in the runs it starts.
if signal.getsignal(signal.SIGINT) == signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.default_int_handler)


def pytest_configure(config: pytest.Config) -> None:
    """pyproject's filterwarnings ignores numba's NumbaPerformanceWarning; NVIDIA's numba-cuda
    raises its own class (numba.cuda.core.errors.NumbaPerformanceWarning, not a subclass), which
    pyproject cannot name: pytest refuses a filter whose class it cannot import, and numba-cuda is
    an optional extra. So it is added here where numba-cuda is installed (a GPU machine: the
    device tests launch small test kernels directly, which numba-cuda warns about)."""
    if importlib.util.find_spec("numba_cuda") is not None:
        config.addinivalue_line("filterwarnings", "ignore::numba.cuda.core.errors.NumbaPerformanceWarning")
    # The suite's kernels compile for the target a user's do (512-bit vectors on an AVX-512 host:
    # stochpend.numerics._cputarget), whichever test module makes the process's first Numba kernel.
    from stochpend.numerics import _cputarget

    _cputarget.configure_numba()


def _xdist_worker(config: pytest.Config) -> str | None:
    """This process's pytest-xdist worker name (``make test`` runs one worker per core, each
    test file on one worker: ``--dist loadfile``), or None outside xdist."""
    workerinput = getattr(config, "workerinput", None)
    return None if workerinput is None else str(workerinput["workerid"])


def pytest_collection_finish(session: pytest.Session) -> None:
    """Start the long simulator runs the collected tests will need (tests/_background.py).

    An xdist worker collects every test but runs only the files the scheduler sends it, so it
    cannot know which runs it will need: there each module's fixture starts its run when it first
    asks for it, and the other worker keeps the second core busy meanwhile."""
    if session.config.option.collectonly or _xdist_worker(session.config) is not None:
        return
    from tests import _background

    _background.start_for(getattr(item, "module", None) for item in session.items)


def pytest_runtest_logfinish() -> None:
    from tests import _background

    _background.poll()


def pytest_sessionfinish(session: pytest.Session) -> None:
    from tests import _background

    _background.stop_all()


#: |z| bound for statistical assertions: a correct implementation fails one such assertion
#: with probability ~6e-5, a biased one of a few standard errors fails reliably.
Z_TOL = 4.0

SEED = 20040401


@pytest.fixture(scope="session")
def seed() -> int:
    return SEED


#: ``reproduce("all")`` at toy size (the real --quick size is checked in the slow suite).
TINY_REPRODUCE = {"quick": True, "paths": 40, "t_max": 10.0}


@pytest.fixture(scope="session")
def tiny_reproduce(tmp_path_factory, request):
    """One ``reproduce("all", **TINY_REPRODUCE)`` for the session (about 20 s, most of it
    writing 24 NetCDF files): ``(result, wall seconds, report.html's text as written)``.
    tests/unit/test_reproduce.py checks its files and reruns figures into its folder (which
    rewrites report.html); tests/system/test_report_browser.py renders the text kept here.

    Under xdist the two files may run on different workers: the first to ask makes it in the
    workers' shared temporary folder, under a lock, and keeps the three values in a pickle;
    the other waits for the lock and reads them (the same objects, so the same checks)."""
    if _xdist_worker(request.config) is None:
        return _tiny_reproduce(tmp_path_factory.mktemp("reproduce"))
    import fcntl
    import pickle

    shared = tmp_path_factory.getbasetemp().parent / "tiny_reproduce"
    shared.mkdir(exist_ok=True)
    with open(shared / "lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        kept = shared / "made.pickle"
        if kept.exists():
            return pickle.loads(kept.read_bytes())
        made = _tiny_reproduce(shared / "out")
        kept.write_bytes(pickle.dumps(made))
        return made


def _tiny_reproduce(out):
    from stochpend.paper.reproduce import reproduce

    started = time.perf_counter()
    result = reproduce("all", out=out, **TINY_REPRODUCE)
    wall = time.perf_counter() - started
    return result, wall, result.report.read_text(encoding="utf-8")
