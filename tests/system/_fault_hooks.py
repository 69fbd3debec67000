"""Run the ``stochpend`` command line with a fault injected (used by test_faults.py).

Usage: ``python _fault_hooks.py HOOK [HOOK_ARG] -- ARGS...`` runs ``stochpend ARGS...`` in this
process after installing HOOK:

* ``none``: nothing (the plain command line, as ``python -m stochpend``);
* ``kill-in-out-write``: the result's temporary file is written, cut to half its size, and the
  process kills itself with SIGKILL before the rename (a crash in the middle of the write);
* ``kill-in-checkpoint-write N``: at the N-th checkpoint write, half of the new checkpoint is
  written to its temporary file and the process kills itself with SIGKILL;
* ``barrier DIR``: once the result's temporary file is written, wait until two processes
  have reached that point (files in DIR), then put it in place: two runs finishing at the
  same instant;
* ``drop-sigint``: when a checkpointed run is about to listen for signals (its lock taken),
  SIGINT arrives inside a weakref callback, where Python prints its ``KeyboardInterrupt`` and
  drops it, as when a Ctrl-C lands in the import system's module-lock callback.
"""

from __future__ import annotations

import os
import signal
import sys
import tempfile
import time
from pathlib import Path


def _kill_in_out_write() -> None:
    from stochpend import io
    from stochpend.files import _files

    def write_atomic(path, data, **kwargs):
        def half(fd):  # half of the result reaches its temporary file, then the crash
            view = memoryview(data).cast("B")
            _files.write_all(fd, view[: len(view) // 2])
            os.kill(os.getpid(), signal.SIGKILL)

        return _files.write_atomic(path, half, **kwargs)

    io.write_atomic = write_atomic


def _kill_in_checkpoint_write(n: int) -> None:
    from stochpend.runs import checkpoint

    original = checkpoint.write
    calls = [0]

    def write(path, ckpt):
        calls[0] += 1
        if calls[0] < n:
            return original(path, ckpt)
        p = Path(path)
        scratch = p.with_name(f"{p.name}.scratch")
        original(scratch, ckpt)  # the bytes the real write would have written
        data = scratch.read_bytes()
        scratch.unlink()
        fd, _ = tempfile.mkstemp(prefix=f".{p.name}.", suffix=".tmp", dir=p.parent)
        os.write(fd, data[: len(data) // 2])
        os.kill(os.getpid(), signal.SIGKILL)
        raise AssertionError("unreachable")

    checkpoint.write = write


def _barrier(folder: str) -> None:
    from stochpend.files import _files

    original = _files._put_in_place
    here = Path(folder)

    def put_in_place(tmp, p, overwrite, name):
        if name == "out":  # the result's temporary file is complete: wait for the other process
            (here / f"arrived-{os.getpid()}").touch()
            deadline = time.monotonic() + 120
            while len(list(here.glob("arrived-*"))) < 2:
                if time.monotonic() > deadline:
                    raise SystemExit("barrier: the other process never arrived")
                time.sleep(0.01)
        return original(tmp, p, overwrite, name)

    _files._put_in_place = put_in_place


def _drop_sigint() -> None:
    import weakref

    from stochpend.runs import checkpoint

    original = checkpoint.FileCheckpointer.signals

    class Box:
        pass

    def signals(self):
        box = Box()
        ref = weakref.ref(box, lambda _: signal.raise_signal(signal.SIGINT))
        del box  # the callback runs here; its KeyboardInterrupt is printed and dropped
        assert ref() is None
        return original(self)

    checkpoint.FileCheckpointer.signals = signals


def main(argv: list[str]) -> None:
    split = argv.index("--")
    hook, hook_args, args = argv[0], argv[1:split], argv[split + 1:]
    if hook == "kill-in-out-write":
        _kill_in_out_write()
    elif hook == "kill-in-checkpoint-write":
        _kill_in_checkpoint_write(int(hook_args[0]))
    elif hook == "barrier":
        _barrier(hook_args[0])
    elif hook == "drop-sigint":
        _drop_sigint()
    elif hook != "none":
        raise SystemExit(f"unknown hook {hook!r}")
    from stochpend.cli import main as cli_main

    sys.argv = ["stochpend", *args]
    cli_main()


if __name__ == "__main__":
    main(sys.argv[1:])
