"""A checkpointer that interrupts a run, for the tests of checkpoint and resume."""

from __future__ import annotations

from stochpend.runs import checkpoint as ck


class StopAfter(ck.FileCheckpointer):
    """Saves at every kernel boundary and raises KeyboardInterrupt after ``n`` saves (what a
    Ctrl-C right after a save does)."""

    def __init__(self, *args, n, **kwargs):
        super().__init__(*args, **kwargs)
        self.n = n

    def maybe_save(self, state):
        self.save(state)
        if self.saves >= self.n:
            raise KeyboardInterrupt
