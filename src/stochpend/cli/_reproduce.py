"""The ``stochpend reproduce`` command (registered in :mod:`stochpend.cli`).

Kept in its own module so that the command line stays a thin layer over
:func:`stochpend.paper.reproduce.reproduce`; Rich is imported here and in ``cli`` only.
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Any

import typer

from stochpend.cli._common import console, handles_errors, note, results
from stochpend.cli._types import file_name, integer
from stochpend.text._terminal import plain

__all__ = ["RichReproduceProgress", "reproduce_command"]


class RichReproduceProgress:
    """Rich bars for :func:`stochpend.paper.reproduce.reproduce`: an overall bar and one per simulation.

    Implements :class:`stochpend.paper.reproduce.ReproduceProgress`; ``log`` prints a line above the
    bars (one per finished figure). With ``enabled=False`` only the lines are printed.
    """

    def __init__(self, enabled: bool) -> None:
        self.enabled = enabled
        self._progress: Any = None
        self._overall: Any = None

    def _ensure(self) -> None:
        if self._progress is None and self.enabled:
            from rich.progress import (
                BarColumn,
                Progress,
                TaskProgressColumn,
                TextColumn,
                TimeElapsedColumn,
                TimeRemainingColumn,
            )

            self._progress = Progress(
                TextColumn("{task.description}"), BarColumn(), TaskProgressColumn(),
                TimeElapsedColumn(), TextColumn("ETA"), TimeRemainingColumn(), console=console,
                transient=True,
            )
            self._progress.start()

    # overall bar
    def start(self, total: float, description: str) -> None:
        self._ensure()
        if self._progress is not None:
            self._overall = self._progress.add_task(f"[bold]{description}", total=total)

    def update(self, done: float) -> None:
        if self._progress is not None and self._overall is not None:
            self._progress.update(self._overall, completed=done)

    def finish(self) -> None:
        if self._progress is not None:
            self._progress.stop()
            self._progress = None
            self._overall = None

    # one bar per simulation
    def simulation(self, description: str) -> Any:
        return _SimulationBar(self, description)

    def log(self, message: str) -> None:
        if self._progress is not None:
            # Lines name files (paths the user chose): plain text, never markup.
            self._progress.console.print(plain(message), markup=False, highlight=False, soft_wrap=True)
        else:
            console.print(plain(message), markup=False, highlight=False, soft_wrap=True)


class _SimulationBar:
    def __init__(self, owner: RichReproduceProgress, description: str) -> None:
        self.owner = owner
        self.description = description
        self.task: Any = None

    def start(self, total: float, description: str) -> None:
        self.owner._ensure()
        if self.owner._progress is not None:
            self.task = self.owner._progress.add_task(f"  {self.description}", total=total)

    def update(self, done: float) -> None:
        if self.task is not None and self.owner._progress is not None:
            self.owner._progress.update(self.task, completed=done)

    def finish(self) -> None:
        if self.task is not None and self.owner._progress is not None:
            self.owner._progress.remove_task(self.task)
        self.task = None


@handles_errors
def reproduce_command(
    figures: Annotated[list[str] | None, typer.Argument(metavar="FIGURE...",
        help="Figures to reproduce: fig1, fig2, fig3, fig4, exponents (the scaling-exponent table, docs/scaling.md) or all (default all); "
             "or a long run for a GPU: fig4-crossover (tau = 0.01 to t = 1e5), fig2-long ((D, tau) = (1, 10) to t = 1e5); or the family's gallery (docs/family.md): family-boltzmann, "
             "family-kramers, family-washboard, family-random-frequency, or family (the four; not part of all).")] = None,
    paths: Annotated[int | None, typer.Option(
        parser=integer, help="Realizations per run.", show_default="10000, as in the paper; 500 with --quick")] = None,
    t_max: Annotated[float | None, typer.Option(
        "--t-max", help="Final time of every run of the chosen figures "
                        "(e.g. 'fig4 --t-max 1e5 --paths 1000' shows the tau = 0.01 crossover).",
        show_default="per run, see docs/reproduction.md")] = None,
    out: Annotated[Path, typer.Option(
        "--out", "-o", parser=file_name, help="Output directory: runs/*.nc, figN.png/.pdf, tables, report.html.")] = Path("stochpend-reproduce"),
    quick: Annotated[bool, typer.Option(
        "--quick", help="Small ensembles and short times (t_max = 100): a smoke test, not a reproduction.")] = False,
    force: Annotated[bool, typer.Option(
        "--force", help="Simulate again even when a stored run matches (default: reuse cached NetCDF).")] = False,
    threads: Annotated[int | None, typer.Option(parser=integer, help="CPU threads (results do not depend on it).", show_default="every CPU")] = None,
    max_path_steps: Annotated[float | None, typer.Option("--max-path-steps", help="Refuse runs needing more than this many path-steps each, paths x t_max / h_max (inf: no limit).", show_default="1e13")] = None,
    backend: Annotated[str, typer.Option(help="cpu, cuda (an NVIDIA GPU) or auto (the GPU when one is usable).")] = "cpu",
    precision: Annotated[str, typer.Option(help="float64 or float32 (float32 needs --backend cuda).")] = "float64",
    quiet: Annotated[bool, typer.Option("--quiet", "-q", help="No progress bars and no tables.")] = False,
    debug: Annotated[bool, typer.Option("--debug", help="Show tracebacks.")] = False,
) -> None:
    """Reproduce the paper's figures: simulate (or reuse), draw PNG/PDF, tabulate, write report.html."""
    from rich.table import Table

    from stochpend.paper.figures import COLUMNS
    from stochpend.paper.reproduce import reproduce
    from stochpend.runs.simulate import resolve_backend

    backend = resolve_backend(backend, note=note)  # 'auto' on a broken CUDA stack: a note
    progress = RichProgressOrLines(enabled=not quiet and console.is_terminal, quiet=quiet)
    result = reproduce(figures or ["all"], paths=paths, t_max=t_max, out=out, quick=quick, force=force,
                       progress=progress, threads=threads, max_path_steps=max_path_steps,
                       backend=backend, precision=precision)
    if quiet:
        return
    for f in result.figures.values():
        from stochpend.text.equations import with_numbers

        table = Table(title=with_numbers(f.title), show_lines=False)
        for col in COLUMNS:
            table.add_column(col, overflow="fold")
        for row in f.rows:  # the paper's Eq. numbers, as the report shows them (not "eq:scalEcolor")
            table.add_row(*(with_numbers(c) if isinstance(c, str) else c for c in row.cells()))
        results.print(table)
    console.print(f"wall time {result.wall_time_s:.1f} s; report: {result.report}")


class RichProgressOrLines(RichReproduceProgress):
    """Bars on a terminal; otherwise (or with --quiet) plain lines, or nothing."""

    def __init__(self, enabled: bool, quiet: bool) -> None:
        super().__init__(enabled)
        self.quiet = quiet

    def log(self, message: str) -> None:
        if not self.quiet:
            super().log(message)
