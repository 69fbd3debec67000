"""Progress reporting protocol: the library calls it, only the command line draws bars."""

from __future__ import annotations

from typing import Any, Protocol


class Progress(Protocol):
    """Receives the fraction of work done; ``total`` and ``done`` are in path-time units."""

    def start(self, total: float, description: str) -> None: ...

    def update(self, done: float) -> None: ...

    def finish(self) -> None: ...


class NoProgress:
    """The default: reports nothing."""

    def start(self, total: float, description: str) -> None:
        pass

    def update(self, done: float) -> None:
        pass

    def finish(self) -> None:
        pass


class Bar:
    """A progress bar for the Python API (``simulate(..., progress=True)``): Rich's, which draws
    in a terminal and in a Jupyter notebook alike, on standard error; one bar per phase (the
    simulation, then the bias estimate), removed when the phase ends."""

    def __init__(self) -> None:
        self._progress: Any = None
        self._task: Any = None

    def start(self, total: float, description: str) -> None:
        from rich.console import Console
        from rich.progress import BarColumn, TaskProgressColumn, TextColumn, TimeElapsedColumn, TimeRemainingColumn
        from rich.progress import Progress as RichProgress

        self.finish()
        self._progress = RichProgress(
            TextColumn("{task.description}"), BarColumn(), TaskProgressColumn(),
            TimeElapsedColumn(), TextColumn("ETA"), TimeRemainingColumn(),
            console=Console(stderr=True), transient=True)
        self._progress.start()
        self._task = self._progress.add_task(description, total=total)

    def update(self, done: float) -> None:
        if self._progress is not None:
            self._progress.update(self._task, completed=done)

    def finish(self) -> None:
        if self._progress is not None:
            self._progress.stop()
            self._progress = None


def resolve(progress: Progress | bool | None) -> Progress:
    """``progress`` as the API accepts it: an object of the :class:`Progress` protocol, ``True``
    (a :class:`Bar`), or ``False``/``None`` (nothing)."""
    if progress is True:
        return Bar()
    if progress is None or progress is False:
        return NoProgress()
    for method in ("start", "update", "finish"):
        if not callable(getattr(progress, method, None)):
            raise ValueError(f"progress={progress!r} is not accepted: True, False, or an object with "
                             "start(total, description), update(done) and finish() methods")
    return progress
