"""``stochpend simulate --target-error EPS``: the command's side of :mod:`stochpend.runs.multilevel`
(the table on stdout, notes and warnings on stderr, the file with ``--out``)."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

from stochpend.cli._common import console, note, results


def parse_target_times(text: str | None) -> list[float] | None:
    """``--target-times`` as a list of times (None: not given); one line for text that is not."""
    if text is None:
        return None
    try:
        return [float(x) for x in str(text).split(",") if x.strip()]
    except ValueError:
        raise ValueError(f"target_times={text!r} is not accepted: a comma-separated list of the run's "
                         "output times, e.g. 1,10") from None


def simulate_target(config: Any, *, target_error: float, target_confidence: float, target_statistics: str | None,
                    target_times: Any, backend: str, precision: str, max_path_steps: Any, accuracy: str,
                    rtol: Any, out: Path | None, overwrite: bool, quiet: bool, config_file: Path | None,
                    ctx: Any, max_seconds: Any = None, checkpoint: Path | None = None,
                    checkpoint_every: float | None = None) -> None:
    """Validate (one line, exit 2, before any work), run, print the table, write ``out``.
    ``checkpoint``: save the run at its round boundaries every ``checkpoint_every`` seconds and
    on Ctrl-C (:func:`stochpend.runs.checkpoint.run_target_checkpointed`; ``stochpend resume``)."""
    from stochpend.files import io
    from stochpend.runs import multilevel
    from stochpend.runs.simulate import resolve_backend

    if isinstance(target_times, str):
        target_times = parse_target_times(target_times)
    target = multilevel.check_run(config, target_error, target_confidence, target_statistics, target_times,
                                  accuracy=accuracy, rtol=rtol, precision=precision,
                                  max_path_steps=max_path_steps, max_seconds=max_seconds, cli=True)
    backend = resolve_backend(backend, note=note)
    if checkpoint is not None:  # writes `out` itself, then removes the checkpoint (as simulate --checkpoint)
        from stochpend.cli._checkpoint import checkpointed
        from stochpend.runs import checkpoint as ck

        ds = checkpointed(ck.run_target_checkpointed, config, target, checkpoint_path=checkpoint,
                          every_s=checkpoint_every, out=out, overwrite=overwrite, backend=backend,
                          max_path_steps=max_path_steps, max_seconds=max_seconds, note=None if quiet else note)
        report(ds, out, quiet)
        return
    ds = multilevel.target_run(config, target, backend=backend, max_path_steps=max_path_steps,
                               max_seconds=max_seconds, note=None if quiet else note)
    ds.attrs["command_line"] = " ".join(["stochpend", *sys.argv[1:]])
    if config_file is not None and ctx is not None:
        ds.attrs["config_file"] = str(config_file)
        ds.attrs["config_text"] = ctx.meta.get("stochpend.config_text", "")
    if out is not None:
        io.to_netcdf(ds, out, overwrite=overwrite)
    report(ds, out, quiet)


def report(ds: Any, out: Path | None, quiet: bool) -> None:
    """A target result's table on stdout (unless ``quiet``), the entries not certified and the
    file written on stderr."""
    from stochpend.runs import multilevel

    if not quiet:
        for line in multilevel.summary_lines(ds):
            results.print(line, markup=False, highlight=False, soft_wrap=True)
    missed = int(ds.attrs["target_entries"]) - int(ds.attrs["target_certified"])
    if missed:
        console.print(f"[yellow]{missed} of {ds.attrs['target_entries']} (statistic, time) entries are not "
                      "certified to the target: the table says what certifying each would cost[/]",
                      highlight=False, soft_wrap=True)
    if out is not None and not quiet:
        from stochpend.text._terminal import markup

        console.print(f"wrote {markup(out)}", highlight=False, soft_wrap=True)
