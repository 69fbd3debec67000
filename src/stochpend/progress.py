"""Progress reporting protocol: the library calls it, only the command line draws bars."""

from __future__ import annotations

from typing import Protocol


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
