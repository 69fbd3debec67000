"""The command line's side of a checkpointed run (``simulate --checkpoint``, with or without
``--target-error``, and ``resume``): the checks before any work, the lock, and the one line
and exit code of an interruption. Its own module so that the commands that checkpoint
(:mod:`stochpend.cli._scale`, :mod:`stochpend.cli._target`) import it, not each other."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

import typer

from stochpend.cli import _common as common
from stochpend.text._terminal import markup


def checkpointed(run: Any, *args: Any, checkpoint_path: Path, out: Path | None, overwrite: bool,
                 command_line: str | None = None, **kwargs: Any) -> Any:
    """``run(*args, checkpoint_path=..., out=..., ...)``, a run that checkpoints
    (:func:`stochpend.runs.checkpoint.run_checkpointed`, ``run_target_checkpointed``), after the checks
    every such run needs before any work (``out`` writable, the checkpoint a new file, its lock
    held) and with Ctrl-C's exit (:func:`interruptible`)."""
    from stochpend.files import io
    from stochpend.runs import checkpoint

    if out is not None:
        io.check_output_path(out, overwrite=overwrite)
    # The name and the place first (the lock file goes beside it); whether it exists is checked
    # under the lock, so that of two runs started together the second hears who holds it.
    io.check_output_path(checkpoint_path, overwrite=True, name="checkpoint")
    with checkpoint.owned(checkpoint_path):  # a second run on this checkpoint is refused
        checkpoint.check_checkpoint_path(checkpoint_path, out=out)
        if command_line is None:
            command_line = " ".join(["stochpend", *sys.argv[1:]])
        return interruptible(run, *args, checkpoint_path=checkpoint_path, out=out, overwrite=overwrite,
                              command_line=command_line, **kwargs)


def interruptible(fn: Any, *args: Any, checkpoint_path: Path, **kwargs: Any) -> Any:
    """``fn(*args, checkpoint_path=..., **kwargs)`` with a checkpointed run's exits: saved on
    Ctrl-C or SIGTERM, one line with the resume advice and exit 128 + N."""
    from stochpend.files._files import placed
    from stochpend.runs.checkpoint import CheckpointInterrupt, resume_advice
    progress = kwargs.get("progress")
    try:
        return fn(*args, checkpoint_path=checkpoint_path, **kwargs)
    except CheckpointInterrupt as exc:
        common._stop_listening()  # saved: a second Ctrl-C now only repeats the exit (I3)
        if progress is not None:
            progress.finish()
        advice = resume_advice(exc.path, kwargs.get("out"))
        common.console.print(f"[yellow]interrupted:[/] state saved to {markup(exc.path)}; continue with: "
                          f"{markup(advice)}", highlight=False, soft_wrap=True)
        raise typer.Exit(exc.exit_code) from None
    except KeyboardInterrupt as exc:
        common._stop_listening()
        if progress is not None:
            progress.finish()
        last = (f"; the last checkpoint is kept: continue with: {markup(resume_advice(checkpoint_path, kwargs.get('out')))}"
                if Path(checkpoint_path).exists() else "")
        signum = getattr(exc, "signum", 2)
        out = kwargs.get("out")
        if out is not None and placed(out) and not Path(checkpoint_path).exists():
            common.console.print(f"[yellow]interrupted[/] by signal {signum} after the result was written: "
                                 f"{markup(out)} is complete (its checkpoint is removed)",
                                 highlight=False, soft_wrap=True)
            raise typer.Exit(128 + signum) from None
        common.console.print(f"[yellow]interrupted[/] by signal {signum} (no new checkpoint){last}",
                          highlight=False, soft_wrap=True)
        raise typer.Exit(128 + signum) from None
