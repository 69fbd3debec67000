"""Command line for scaling out: ``sweep``, ``resume``, and checkpoints for ``simulate``.

Registered on the main app by :mod:`stochpend.cli`::

    app.command("sweep")(sweep_command)
    app.command("resume")(resume_command)

``simulate --checkpoint FILE --checkpoint-every 5m`` calls :func:`simulate_with_checkpoint`.
"""

from __future__ import annotations

import math
import os
import re
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Annotated, Any

import typer
from rich.table import Table

from stochpend.cli import _common as common
from stochpend.cli._checkpoint import checkpointed, interruptible
from stochpend.cli._common import handles_errors
from stochpend.cli._types import file_name, integer
from stochpend.text._terminal import markup

__all__ = [
    "SweepProgressBar",
    "parse_duration",
    "resume_command",
    "simulate_with_checkpoint",
    "sweep_command",
    "sweep_table",
]


_UNITS = {"ms": 1e-3, "s": 1.0, "sec": 1.0, "m": 60.0, "min": 60.0, "h": 3600.0, "d": 86400.0}
_NUMBER = r"(?:\d+(?:\.\d*)?|\.\d+)"
_TOKEN = re.compile(rf"\s*({_NUMBER})\s*(ms|sec|min|s|m|h|d)?\s*")


def parse_duration(text: str, name: str = "checkpoint_every") -> float:
    """'30s', '5m', '1h', '1h30m', '0.2s', '90' (seconds) -> seconds (> 0)."""
    accepted = "a duration > 0 such as 30s, 5m, 1h or 1h30m (a bare number is seconds)"
    pos, total, parts, bare = 0, 0.0, 0, 0
    while pos < len(text):
        m = _TOKEN.match(text, pos)
        if m is None or m.end() == pos:
            raise ValueError(f"{name}={text!r} is not accepted: {accepted}")
        total += float(m.group(1)) * _UNITS[m.group(2) or "s"]
        parts += 1
        bare += m.group(2) is None
        pos = m.end()
    # A number without a unit only alone ('90'): '1.5.5s' or '1 2 3' are typing errors, not sums.
    if parts == 0 or (bare and parts > 1) or not math.isfinite(total) or total <= 0:
        raise ValueError(f"{name}={text!r} is not accepted: {accepted}")
    return total


# -- checkpoints -----------------------------------------------------------------------------
def simulate_with_checkpoint(
    config: Any,
    *,
    checkpoint_path: Path,
    every_s: float,
    out: Path | None,
    overwrite: bool,
    progress: Any,
    threads: int | None = None,
    backend: str = "cpu",
    precision: str = "float64",
    command_line: str | None = None,
    bias_paths: int | None = None,
    accuracy: str = "fixed",
    rtol: float | None = None,
    max_path_steps: float | None = None,
) -> Any:
    """Run ``config`` with checkpoints; write ``out``; return the Dataset (for the table).

    Refuses, before any work, an existing checkpoint file (it belongs to an interrupted run:
    ``stochpend resume`` it) or an unwritable ``out``. Every backend and precision checkpoints
    (the checkpoint records them; ``resume`` continues on the same), as do ``bias_paths`` and
    the level ``accuracy="auto"`` chose (its pilot runs first). Ctrl-C
    (SIGTERM) saves the state, prints where and exits with code 130 (143). On success the result is written
    to ``out`` (with ``command_line`` in its attributes) and the checkpoint file is removed.
    """
    from stochpend.runs import checkpoint
    from stochpend.runs.simulate import check_precision, resolve_backend

    backend = resolve_backend(backend)
    check_precision(precision, backend)
    return checkpointed(checkpoint.run_checkpointed, config, checkpoint_path=checkpoint_path, every_s=every_s,
                        out=out, overwrite=overwrite, threads=threads, progress=progress, command_line=command_line,
                        backend=backend, precision=precision, bias_paths=bias_paths, accuracy=accuracy, rtol=rtol,
                        max_path_steps=max_path_steps)


@handles_errors
def resume_command(
    checkpoint: Annotated[Path, typer.Argument(parser=file_name, help="A checkpoint written by 'stochpend simulate --checkpoint'.")],
    out: Annotated[Path | None, typer.Option("--out", "-o", parser=file_name, help="Write the result here instead of the original command's --out.", show_default="the original command's --out")] = None,
    overwrite: Annotated[bool, typer.Option("--overwrite", help="Replace an existing output file.")] = False,
    threads: Annotated[int | None, typer.Option(parser=integer, help="CPU threads (results do not depend on it).", show_default="every CPU")] = None,
    max_path_steps: Annotated[float | None, typer.Option("--max-path-steps", help="Refuse runs needing more than this many path-steps, as for 'simulate' (give the original run's value again: it is not read from the file).", show_default="1e13")] = None,
    break_lock: Annotated[bool, typer.Option("--break-lock", help="Take the checkpoint's lock from a run on another host that is gone, or run without a lock on a file system that has none.")] = False,
    plugin: Annotated[list[str] | None, typer.Option("--plugin", metavar="NAME", help="Load a plugin first (an installed stochpend plugin or a module's dotted name), for a run of a noise or model from outside stochpend: a checkpoint names its pieces, it never loads them.", show_default="none")] = None,
    quiet: Annotated[bool, typer.Option("--quiet", "-q", help="No progress bar and no table.")] = False,
    debug: Annotated[bool, typer.Option("--debug", help="Show tracebacks.")] = False,
) -> None:
    """Continue an interrupted 'simulate --checkpoint' run; write its result where it would have."""
    from stochpend.runs import checkpoint as ck

    common.load_plugins(plugin)  # before the checkpoint is read: it names its noise, never loads it
    with ck.owned(checkpoint, break_lock=break_lock):  # one resume at a time, refused in one line
        _resume_owned(checkpoint, out, overwrite, threads, quiet, max_path_steps)


def _resume_owned(checkpoint: Path, out: Path | None, overwrite: bool, threads: int | None, quiet: bool,
                  max_path_steps: float | None) -> None:
    from stochpend.files import io
    from stochpend.runs import checkpoint as ck
    state = ck.read(checkpoint)  # verifies checksum, version and configuration first
    targeted = isinstance(state, ck.TargetCheckpoint)  # simulate --target-error's (stochpend.runs.multilevel)
    if not isinstance(state, ck.TargetCheckpoint):
        ck.check_work(state, max_path_steps)
    # The checkpoint names its output only within its own directory, and never overwrites by
    # its own say: --overwrite must be on this command line.
    target = out if out is not None else (None if state.out is None else ck.own_out(checkpoint, state.out))
    if target is not None:
        io.check_output_path(target, overwrite=overwrite)
        ck.check_not_checkpoint(target, checkpoint)
    kwargs: dict[str, Any] = {"out": target, "overwrite": overwrite, "max_path_steps": max_path_steps}
    if threads is not None:
        from stochpend.runs.lifecycle import check_threads

        check_threads(threads)  # before the 'resuming' line: a refusal is its only line
        kwargs["threads"] = threads
    # The real destination, before any work (the recorded command line is only a reminder).
    dest = "writing no file" if target is None else f"writing {markup(target)}"
    if not quiet:
        if isinstance(state, ck.TargetCheckpoint):
            done = f"{len(state.journal.rounds)} rounds done"
        else:
            st = state.state
            done = f"{100 * (st.done_work + float(st.t.sum())) / (state.config.paths * state.config.t_max):.0f}% done"
        common.console.print(f"resuming {markup(state.command_line or 'run')} from {markup(checkpoint)} "
                          f"({done}); {dest}", highlight=False, soft_wrap=True)
    if targeted:
        from stochpend.cli._target import report

        kwargs["note"] = None if quiet else common.note
        report(interruptible(_resume, checkpoint_path=checkpoint, **kwargs), target, quiet)
        return
    progress = common.RichProgress(enabled=not quiet and common.console.is_terminal, long_run=True)
    ds = interruptible(_resume, checkpoint_path=checkpoint, progress=progress, **kwargs)
    if not quiet:
        common.results.print(common.summary_table(ds, width=common.results.width, more=common.rows_hint(target)))
        if target is not None:
            common.console.print(f"wrote {markup(target)}", highlight=False, soft_wrap=True)


def _resume(*, checkpoint_path: Path, **kwargs: Any) -> Any:
    from stochpend.runs.checkpoint import resume

    return resume(checkpoint_path, **kwargs)


# -- sweeps ----------------------------------------------------------------------------------
class SweepProgressBar:
    """Rich bar for sweeps: tasks done, paths done, elapsed, ETA; prints notes (dashboard).

    Implements :class:`stochpend.text.progress.Progress` (in paths) plus ``tasks`` and ``note``.
    """

    def __init__(self, enabled: bool, quiet: bool = False) -> None:
        self.enabled = enabled
        self.quiet = quiet
        self._progress: Any = None
        self._task: Any = None
        self._tasks = (0, 0)

    def start(self, total: float, description: str) -> None:
        if not self.enabled:
            return
        from rich.progress import BarColumn, Progress, TaskProgressColumn, TextColumn, TimeElapsedColumn, TimeRemainingColumn
        self._progress = Progress(
            TextColumn("{task.description}"), BarColumn(), TaskProgressColumn(),
            TextColumn("tasks {task.fields[tasks]}"), TextColumn("paths {task.completed:.0f}/{task.total:.0f}"),
            TimeElapsedColumn(), TextColumn("ETA"), TimeRemainingColumn(), console=common.console,
            transient=True,
        )
        self._progress.start()
        self._task = self._progress.add_task(description, total=total, tasks=f"{self._tasks[0]}/{self._tasks[1]}")

    def update(self, done: float) -> None:
        if self._progress is not None:
            self._progress.update(self._task, completed=done)

    def tasks(self, done: int, total: int) -> None:
        self._tasks = (done, total)
        if self._progress is not None:
            self._progress.update(self._task, tasks=f"{done}/{total}")

    def note(self, text: str) -> None:
        if not self.quiet:
            common.console.print(text, highlight=False, soft_wrap=True)

    def finish(self) -> None:
        if self._progress is not None:
            self._progress.stop()
            self._progress = None


def sweep_table(ds: Any) -> Table:
    """One row per parameter set: the swept values and the statistics at the last time."""
    from stochpend.runs._sweep_sets import flat_sets  # not stochpend.sweep: Numba

    fmt = common._fmt
    sets = flat_sets(ds)
    swept = list(sets[0]["params"]) if sets else []
    if "target_error" in ds.attrs and "n_samples" in ds:
        return _target_sweep_table(ds, sets, swept)
    noise = ds.attrs.get("noise")
    table = Table(title=f"stochpend sweep: {len(sets)} parameter sets"
                        + (f" ({markup(ds.attrs['description'])})" if ds.attrs.get("description") else ""))
    noises = set(ds["noise"].values.ravel().tolist()) if "noise" in ds.variables else {noise}
    scaled = {frozenset({"ou"}): "<E2>/(Dt/tau^2)", frozenset({"white"}): "<E>/(Dt/4)"}.get(
        frozenset(noises), "<E2>/(Dt/tau^2) (ou), <E>/(Dt/4) (white)")
    # the bias estimate of each set ("estimating the discretisation bias" had no column to show)
    has_bias = "mean_E_bias" in ds and "mean_E_bias_stderr" in ds
    for col in (*swept, "t", "<E>", *(["bias <E>"] if has_bias else []), "<E2>", scaled, "S", "F", "non-finite"):
        table.add_column(col, justify="right", no_wrap=True)
    for s in sets:
        row = ds.isel(s["index"]).isel(time=-1)
        t = float(row["times"] if "times" in row.coords else row["time"])
        D = float(row["D"]) if "D" in row else float(ds.attrs.get("D", float("nan")))
        nz = str(row["noise"].item()) if "noise" in row else noise
        if nz == "ou":
            tau = float(row["tau"]) if "tau" in row else float(ds.attrs["tau"])
            norm = D * t / tau**2
            val, se = float(row.mean_E2) / norm, float(row.mean_E2_stderr) / norm
        else:
            norm = D * t / 4.0
            val, se = float(row.mean_E) / norm, float(row.mean_E_stderr) / norm
        se_shown: float | None = se
        if not norm > 0:
            val, se_shown = float("nan"), None
        bias_cell = []
        if has_bias:
            verdict = int(row["mean_E_bias_verdict"]) if "mean_E_bias_verdict" in row else None
            bias_cell = [common._bias_cell(float(row.mean_E_bias), float(row.mean_E_bias_stderr), verdict)]
        table.add_row(
            *(f"{v:g}" if isinstance(v, float) else str(v) for v in s["params"].values()),
            f"{t:.4g}", fmt(float(row.mean_E), float(row.mean_E_stderr)), *bias_cell,
            fmt(float(row.mean_E2), float(row.mean_E2_stderr)), fmt(val, se_shown),
            fmt(float(row.skewness), float(row.skewness_stderr)), fmt(float(row.flatness), float(row.flatness_stderr)),
            str(int(row.nonfinite_paths)),
        )
    workers = ds.attrs.get("sweep_workers")
    table.caption = (f"{ds.attrs.get('sweep_tasks')} tasks on {ds.attrs.get('sweep_engine')} "
                     f"({workers} worker{'' if str(workers) == '1' else 's'}); wall time "
                     f"{float(ds.attrs['wall_time_s']):.3g} s, {float(ds.attrs['path_steps']):.3g} path-steps."
                     + (" bias <E>: the estimated discretisation bias at the last time (value minus "
                        "zero-step limit); '!' significant, 'unresolved' where the estimate cannot tell."
                        if has_bias else ""))
    return table


def _target_sweep_table(ds: Any, sets: Sequence[dict[str, Any]], swept: list[str]) -> Table:
    """A sweep of targets: per set, each statistic at the last time with its total error and
    how many of its times are certified; the set's path-steps."""
    names = [n for n in str(ds.attrs.get("target_statistics", "")).split(",") if n and n in ds]
    table = Table(title=f"stochpend sweep: {len(sets)} parameter sets, target {float(ds.attrs['target_error']):g} "
                        f"at {100 * float(ds.attrs['target_confidence']):g} %"
                        + (f" ({markup(ds.attrs['description'])})" if ds.attrs.get("description") else ""))
    # "rel" as a percentage (4.9%, not 4.90e-02): one swept parameter and two statistics fit 80
    # columns; more wrap within their cells (folded), never cut to "…"
    for col in (*swept, "t", *(c for name in names for c in (name, "rel", "cert")), "path-steps"):
        table.add_column(col, justify="right", overflow="fold")
    for s in sets:
        row = ds.isel(s["index"])
        last = row.isel(time=-1)
        t = float(last["times"] if "times" in last.coords else last["time"])
        cells = []
        for name in names:
            cells += [f"{float(last[name]):.6g}", f"{100.0 * float(last[f'{name}_relative_total_error']):.3g}%",
                      f"{int(row[f'{name}_certified'].sum())}/{row.sizes['time']}"]
        table.add_row(*(f"{v:g}" if isinstance(v, float) else str(v) for v in s["params"].values()),
                      f"{t:.4g}", *cells, f"{float(row['path_steps']):.3g}")
    table.caption = (f"rel: the total error (statistical + discretisation bias bound) over |estimate| at "
                     f"the last time; cert: the times certified to the target. Wall time "
                     f"{float(ds.attrs['wall_time_s']):.3g} s, {float(ds.attrs['path_steps']):.3g} path-steps.")
    return table


@handles_errors
def sweep_command(
    spec: Annotated[Path, typer.Argument(parser=file_name, help="The sweep, a TOML file: [base], then [grid] or [[case]] (docs/scale-out.md).")],
    out: Annotated[Path | None, typer.Option("--out", "-o", parser=file_name, help="Write the results as NetCDF (atomically).", show_default="none: no file")] = None,
    overwrite: Annotated[bool, typer.Option("--overwrite", help="Replace an existing --out file.")] = False,
    scheduler: Annotated[str | None, typer.Option(help="Where tasks run: default in this process; 'threads' or 'sync' (Dask, no server); 'local' (a Dask LocalCluster); or a scheduler address, e.g. tcp://HOST:8786.", show_default="none: this process")] = None,
    workers: Annotated[int | None, typer.Option(parser=integer, help="Threads ('threads') or worker processes ('local'), >= 1.", show_default="the CPU count")] = None,
    tasks_per_set: Annotated[int | None, typer.Option("--tasks-per-set", parser=integer, help="Blocks of batches per parameter set, >= 1 (results do not depend on it).", show_default="about 8 per worker thread")] = None,
    max_path_steps: Annotated[float | None, typer.Option("--max-path-steps", help="Refuse sweeps needing more than this many path-steps in all, the sum of paths x t_max / h_max (inf: no limit).", show_default="1e13")] = None,
    backend: Annotated[str, typer.Option(help="Where each block runs: cpu, cuda (the GPU of the process or Dask worker running it) or auto.")] = "cpu",
    precision: Annotated[str, typer.Option(help="float64 or float32 (float32 needs --backend cuda).")] = "float64",
    bias_paths: Annotated[int | None, typer.Option("--bias-paths", parser=integer, help="Coupled coarse/fine pairs estimating each set's discretisation bias, in this process after the blocks (0: none).", show_default="each set's paths/48, at least 64")] = None,
    target_error: Annotated[float | None, typer.Option("--target-error", help="Run every set as 'simulate --target-error' runs it (its own seed), one after another in this process: the relative total error of each target statistic at each output time (--scheduler, --tasks-per-set, --bias-paths are not used; --max-path-steps bounds each set).", show_default="the file's target_error; none")] = None,
    target_confidence: Annotated[float | None, typer.Option("--target-confidence", help="Confidence of --target-error's total error, in (0.5, 1).", show_default="the file's; 0.95")] = None,
    target_statistics: Annotated[str | None, typer.Option("--target-statistics", metavar="NAMES", help="With --target-error: the statistics to control, comma-separated.", show_default="the file's; mean_E,mean_E2")] = None,
    target_times: Annotated[str | None, typer.Option("--target-times", metavar="TIMES", help="With --target-error: the output times to control, comma-separated, among every set's.", show_default="the file's; every output time")] = None,
    plugin: Annotated[list[str] | None, typer.Option("--plugin", metavar="NAME", help="Load a plugin first (an installed stochpend plugin or a module's dotted name); the Dask workers load it too. A sweep file names pieces, it never loads them.", show_default="none")] = None,
    quiet: Annotated[bool, typer.Option("--quiet", "-q", help="No progress bar and no table.")] = False,
    debug: Annotated[bool, typer.Option("--debug", help="Show tracebacks.")] = False,
) -> None:
    """Run a grid or list of parameter sets (TOML) as one job; save one NetCDF with the swept dims."""
    from stochpend.files import io
    from stochpend.runs.sweep import check_scheduler, load_spec, sweep, targets
    common.load_plugins(plugin)  # before the file is read: it names pieces, never loads them
    if out is not None:
        io.check_output_path(out, overwrite=overwrite)
    plan = load_spec(spec)  # the whole file is validated before any work
    if bias_paths is not None:
        from stochpend.runs.bias import check_bias_paths

        check_bias_paths(bias_paths, 0)
    from stochpend.cli._target import parse_target_times
    from stochpend.runs.simulate import check_precision, resolve_backend

    given: dict[str, Any] = {"target_error": target_error, "target_confidence": target_confidence,
             "target_statistics": target_statistics, "target_times": parse_target_times(target_times)}
    sets = targets(plan, given, precision=precision, max_path_steps=max_path_steps)
    if sets is None:  # a target run's work is its plan's (checked by the sweep, set by set), not paths x steps
        _check_resources(plan, spec, max_path_steps)
        check_scheduler(scheduler)
    backend = resolve_backend(backend, note=common.note)
    check_precision(precision, backend)
    # Processes or threads on this machine: no more than it has CPUs (--workers 1e6 would start a
    # million processes). A remote scheduler's workers are its own.
    local = scheduler is None or not scheduler.startswith(("tcp://", "tls://", "inproc://", "ucx://"))
    most = os.cpu_count() or 1
    if workers is not None and (workers < 1 or (local and workers > most)):
        common.fail(f"workers={workers!r} is not accepted: an integer in [1, {most}] (this machine's CPUs)")
    if local and backend == "cpu" and sets is None:  # a long sweep says what it will cost before it starts (as simulate)
        line = sweep_estimate(plan, pairs=bias_paths != 0)
        if line is not None:
            common.console.print(f"estimate: {markup(line)}", highlight=False, soft_wrap=True)
    progress = SweepProgressBar(enabled=not quiet and common.console.is_terminal, quiet=quiet)
    try:
        ds = sweep(plan, scheduler=scheduler, workers=workers, progress=progress,
                   tasks_per_set=tasks_per_set, backend=backend, precision=precision, bias_paths=bias_paths,
                   max_path_steps=max_path_steps, **given)
    except KeyboardInterrupt:
        progress.finish()
        raise
    ds.attrs["command_line"] = " ".join(["stochpend", *sys.argv[1:]])
    if out is not None:
        io.to_netcdf(ds, out, overwrite=overwrite)
    if not quiet:
        common.results.print(sweep_table(ds))
        if out is not None:
            common.console.print(f"wrote {markup(out)}", highlight=False, soft_wrap=True)


#: A parameter set's own cost in a sweep beyond its path-steps (seconds, a lower bound): its
#: blocks' tasks, statistics and results, and with the bias estimate (``pairs``) its coupled
#: pairs. Sets of 2 paths took 3.3 ms (9 ms with the bias estimate) of CPU each on 2 loaded
#: cores; 99 999 of them ran for about an hour with no estimate line, their 2e5 path-steps
#: being 0.03 s of work (hostile-turn4 NEW03).
SET_SECONDS = 1e-3
SET_SECONDS_WITH_BIAS = 3e-3


def sweep_estimate(plan: Any, *, pairs: bool) -> str | None:
    """The ``estimate:`` line of a sweep run on this machine's CPUs (None when it is short): the
    sets' lower-bound work at the rate measured here, each set's own cost (:data:`SET_SECONDS`)
    and the compiling of each distinct kernel not in the cache
    (:func:`stochpend.runs.resources.estimate`, :func:`~stochpend.runs.resources.with_compile`)."""
    from stochpend.runs import resources

    work = seconds = compiling = 0.0
    counted: set = set()
    est = None
    for config in plan.configs:
        est = resources.with_compile(resources.estimate(config), config, pairs=pairs, counted=counted)
        work += est.min_path_steps
        seconds += est.seconds
        compiling += est.compile_seconds
    per_set = SET_SECONDS_WITH_BIAS if pairs else SET_SECONDS
    seconds += len(plan.configs) * per_set
    if est is None or seconds + compiling <= resources.LONG_RUN_S:
        return None
    comp = f", plus ~{resources.format_seconds(compiling)} compiling kernels (first use, cached after)" if compiling else ""
    return (f"{len(plan.configs)} parameter sets, at least {work:.3g} path-steps (paths x t_max / h_max), roughly "
            f"{resources.format_seconds(seconds)} on {est.workers} at ~{est.rate:.2g} path-steps/s and "
            f"~{per_set * 1e3:.0f} ms a set{comp}")


def _check_resources(plan: Any, spec: Path, max_path_steps: float | None) -> None:
    """Every parameter set must fit in memory, and all together within the work limit."""
    from stochpend.runs import resources

    limit = resources.work_limit(max_path_steps)
    n = len(plan.configs)
    total = 0.0
    for i, config in enumerate(plan.configs):
        try:
            total += resources.check(config, max_path_steps=limit).min_path_steps
        except ValueError as exc:
            raise ValueError(f"{exc} (sweep {str(spec)!r}, parameter set {i + 1} of {n})") from None
    if total > limit:
        raise ValueError(
            f"sweep={str(spec)!r} is not accepted: its {n} parameter sets need at least {total:.3g} "
            f"path-steps in all (the sum of paths x t_max / h_max), above the limit of {limit:.3g}; "
            "sweep fewer or smaller sets, or raise the limit with --max-path-steps"
        )
