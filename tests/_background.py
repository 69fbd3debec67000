"""Long subprocess runs started when the session starts, to run beside the other tests.

Numba's CUDA simulator runs a kernel as Python, one thread per CUDA thread: the simulator runs of
test_cuda_sim.py, test_golden_cuda.py and test_reproduce_cases.py take a minute or more each
while the test process waits, on a machine whose second core the suite otherwise leaves idle.
A test module that needs such a run defines ``background_run(folder) -> Command``; when the
collected tests include one of that module's (``tests/conftest.py``'s
``pytest_collection_finish``), its run is queued, in the order the tests come. One runs at a
time beside the tests (the next starts between two tests once it ends: :func:`poll`), so the
test process keeps a core of its own; the module's fixture collects its run with :func:`start`
(which starts it at once if it has not started) and :meth:`Run.wait`. The run is the very command the fixture used to start itself: the same
inputs, the same numbers; only the time it starts moves. Output goes to files (a full pipe
would stall a run no one reads yet). Runs still going when the session ends are killed and
their folders removed.
"""

from __future__ import annotations

import shutil
import subprocess
import tempfile
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from pathlib import Path
from types import ModuleType


@dataclass
class Command:
    argv: list[str]
    env: dict[str, str]
    cwd: Path | None = None


@dataclass
class Run:
    folder: Path
    command: Command
    proc: subprocess.Popen = field(init=False)

    def __post_init__(self) -> None:
        with open(self.folder / "stdout.txt", "wb") as out, open(self.folder / "stderr.txt", "wb") as err:
            self.proc = subprocess.Popen(self.command.argv, env=self.command.env, cwd=self.command.cwd,
                                         stdin=subprocess.DEVNULL, stdout=out, stderr=err)

    def wait(self, timeout: float) -> subprocess.CompletedProcess:
        """Wait up to ``timeout`` s more (killed then, and TimeoutExpired raised); its exit
        status and output, as ``subprocess.run(..., capture_output=True, text=True)``."""
        try:
            self.proc.wait(timeout=timeout)
        finally:
            if self.proc.poll() is None:
                self.proc.kill()
                self.proc.wait()
        read = lambda name: (self.folder / name).read_text(errors="replace")  # noqa: E731
        return subprocess.CompletedProcess(self.command.argv, self.proc.returncode, read("stdout.txt"),
                                           read("stderr.txt"))


#: Runs at once beside the tests.
AT_ONCE = 1

_RUNS: dict[str, Run] = {}
_QUEUE: dict[str, Callable[[Path], Command]] = {}


def start(key: str, make: Callable[[Path], Command]) -> Run:
    """The run of ``key`` (a module's name), started now with ``make(folder)`` unless it was."""
    if key not in _RUNS:
        _QUEUE.pop(key, None)
        folder = Path(tempfile.mkdtemp(prefix=f"stochpend-{key.rsplit('.', 1)[-1]}-"))
        _RUNS[key] = Run(folder, make(folder))
    return _RUNS[key]


def poll() -> None:
    """Start queued runs while fewer than :data:`AT_ONCE` are running."""
    while _QUEUE and sum(run.proc.poll() is None for run in _RUNS.values()) < AT_ONCE:
        key = next(iter(_QUEUE))
        start(key, _QUEUE[key])


def start_for(modules: Iterable[ModuleType | None]) -> None:
    """Queue the run of every module given that defines ``background_run``, in order, and start
    the first."""
    for module in dict.fromkeys(modules):
        make = getattr(module, "background_run", None)
        if module is not None and callable(make):
            _QUEUE.setdefault(module.__name__, make)
    poll()


def stop_all() -> None:
    _QUEUE.clear()
    for run in _RUNS.values():
        if run.proc.poll() is None:
            run.proc.kill()
            run.proc.wait()
        shutil.rmtree(run.folder, ignore_errors=True)
    _RUNS.clear()
