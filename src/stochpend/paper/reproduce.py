"""Reproduce the paper's figures: run (or reuse) the simulations, draw, tabulate, report.

``reproduce(("fig1", "fig3"), paths=10_000, out="stochpend-reproduce")`` runs the simulations
named in each caption (:mod:`stochpend.paper.figures`), stores each as NetCDF under ``OUT/runs/``,
draws each figure as PNG and PDF, writes a table of late-time values against the predictions
(CSV, Markdown, JSON) and a self-contained HTML report ``OUT/report.html``.

Caching: each run's file name carries a SHA-256 of its parameters (physics, paths, times, seed)
and of the package version, and the file stores the full hash. A second call with the same
settings redraws from the stored files without simulating; ``force=True`` simulates again. Runs
shared by two figures (Fig. 2's (D, tau) = (1, 1) is Fig. 3's omega = 1; Fig. 4's tau = 1 is
Fig. 3's omega = 0) have the same parameters and seed and are simulated once.

Each run also stores its per-batch sums (``batch_sums``), from which the tables compute
jackknife errors of late-time fits (see :mod:`stochpend.paper.figures._common`).
"""

from __future__ import annotations

import csv
import json
import math
import platform
import shlex
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from io import BytesIO, StringIO
from pathlib import Path
from typing import Any, Protocol

import numpy as np
import xarray as xr

from stochpend._version import __version__
from stochpend.files._files import reason, write_atomic
from stochpend.paper.figures import CASES, FIGURES, GALLERY
from stochpend.paper.figures._common import COLUMNS, SUM_COMPONENTS, FigureRun, Row
from stochpend.text.progress import NoProgress, Progress

__all__ = [
    "DEFAULT_PATHS",
    "QUICK_PATHS",
    "FigureResult",
    "ReproduceProgress",
    "ReproduceResult",
    "RunRecord",
    "reproduce",
]

#: Realizations per run by default (the paper's 10^4).
DEFAULT_PATHS = 10_000
#: Realizations per run with ``quick=True``.
QUICK_PATHS = 500


class ReproduceProgress(Protocol):
    """What :func:`reproduce` reports to: an overall bar, one bar per simulation, and lines.

    ``start``/``update``/``finish`` drive the overall bar (work in path-time units, summed
    over the runs to simulate); ``simulation(description)`` returns a :class:`Progress` for one
    simulation; ``log(message)`` receives, before any work, one "cost: ..." line per run to
    simulate and their total, then one line per finished figure. A plain
    :class:`~stochpend.text.progress.Progress` is accepted too (it then gets only the overall bar).
    """

    def start(self, total: float, description: str) -> None: ...

    def update(self, done: float) -> None: ...

    def finish(self) -> None: ...

    def simulation(self, description: str) -> Progress: ...

    def log(self, message: str) -> None: ...


@dataclass
class RunRecord:
    """One stored simulation and where it came from in this call."""

    key: str
    figure_run: FigureRun
    path: Path
    cache_key: str
    status: str  # "simulated", "cached" (read from disk) or "shared" (used by an earlier figure)
    attrs: dict[str, Any]
    nonfinite_paths: int
    #: The discretisation bias of <E> at the run's last output time: (bias, its error, verdict
    #: of stochpend.bias.assess), or None for a run without the estimate.
    late_bias: tuple[float, float, int] | None = None

    @property
    def wall_time_s(self) -> float:
        try:
            return float(self.attrs.get("wall_time_s", math.nan))
        except (TypeError, ValueError):
            return math.nan

    @property
    def path_steps(self) -> float:
        try:
            return float(self.attrs.get("path_steps", math.nan))
        except (TypeError, ValueError):
            return math.nan


@dataclass
class FigureResult:
    """One figure: its files, caption, table and runs."""

    name: str
    title: str
    caption: str
    png: Path
    pdf: Path
    table_csv: Path
    rows: list[Row]
    runs: list[RunRecord]
    wall_time_s: float
    fit_method: str = ""


@dataclass
class ReproduceResult:
    """Everything :func:`reproduce` produced."""

    out: Path
    figures: dict[str, FigureResult]
    report: Path
    tables_md: Path
    results_json: Path
    wall_time_s: float
    settings: dict[str, Any]
    versions: dict[str, str]
    runs: dict[str, RunRecord] = field(default_factory=dict)

    @property
    def files(self) -> list[Path]:
        out = [self.report, self.tables_md, self.results_json]
        for f in self.figures.values():
            out += [f.png, f.pdf, f.table_csv]
        out += [r.path for r in self.runs.values()]
        return out


FIT_METHOD = (
    "Extrapolation t → ∞: weighted least-squares fit of value(t) = a + b·t^(-p) over the last decade "
    "of output times (weights 1/stderr²), reporting a. p = 1/2 for coloured noise (corrections of "
    "relative size (t/t_c)^(-1/2) and ω²/⟨E⟩ ∝ t^(-1/2)), p = 1 for white noise (⟨E⟩ = Dt/4 + const). "
    "Its error is the delete-one-batch jackknife of the whole fit (refit on each leave-one-batch-out "
    "ensemble), which accounts for the strong correlation between times of the same paths; the "
    "least-squares formula would not. 'Other model' is the same fit with the other exponent (p = 1 "
    "instead of 1/2 or vice versa): the spread between the two is the model uncertainty. Coloured-noise "
    "fits are made only when the last decade starts after the slowest time scale t* = max(t_c, τ²ω⁴/D). "
    "Deviations are (value − prediction)/stderr."
)


# ---------------------------------------------------------------------------------------------
# The entry point
# ---------------------------------------------------------------------------------------------


def _prepare_out(out: Path) -> None:
    """Create ``out`` and ``out/runs`` and check, before any work, that files can be written
    there (a directory in ``/sys`` or ``/proc`` is "writable" to root by its permission bits,
    and was found unwritable only after every simulation had run)."""
    from stochpend.files._files import check_output

    try:
        out.mkdir(parents=True, exist_ok=True)
        (out / "runs").mkdir(exist_ok=True)
    except OSError as exc:
        raise ValueError(f"out={str(out)!r} is not accepted: the directory cannot be created "
                         f"({reason(exc)})") from None
    for probe in (out / "report.html", out / "runs" / "run.nc"):
        check_output(probe, overwrite=True, name="out")


def reproduce(
    figures: str | Iterable[str] = ("fig1", "fig2", "fig3", "fig4"),
    *,
    paths: int | None = None,
    t_max: float | None = None,
    out: str | Path = "stochpend-reproduce",
    quick: bool = False,
    force: bool = False,
    progress: ReproduceProgress | Progress | None = None,
    threads: int | None = None,
    max_path_steps: float | None = None,
    backend: str = "cpu",
    precision: str = "float64",
) -> ReproduceResult:
    """Run, cache, draw and tabulate the paper's figures and write an HTML report.

    Parameters
    ----------
    figures : str or iterable of str
        Any of "fig1" ... "fig4", "exponents" (the scaling-exponent table), or "all" (these
        five); or a named long run for a GPU, "fig4-crossover" or "fig2-long"
        (:mod:`stochpend.paper.figures.cases`); or the family's gallery, "family-boltzmann",
        "family-kramers", "family-washboard", "family-random-frequency", or "family" (these
        four; not part of "all", docs/family.md). Before simulating, one line per run to simulate
        gives its cost (``progress.log``: "cost: ...").
    paths : int, optional
        Realizations per run; default 10^4 (the paper's), or 500 with ``quick``.
    t_max : float, optional
        Final time of every run of the selected figures (default: each caption's run has its
        own, see the figure modules' ``CONFIG`` and ``docs/reproduction.md``).
    out : path
        Output directory (created): ``runs/*.nc``, ``figN.png``, ``figN.pdf``,
        ``figN_table.csv``, ``tables.md``, ``results.json``, ``report.html``.
    quick : bool
        Small ensembles and short times (t_max = 100): a smoke test, not a reproduction.
    force : bool
        Simulate again even when a stored run matches.
    progress : ReproduceProgress, optional
        Receives the overall and per-simulation progress and one line per figure.
    threads : int, optional
        CPU threads for the simulations (results do not depend on it).
    max_path_steps : float, optional
        Work limit of each run (:func:`stochpend.runs.resources.check`; default 1e13 path-steps).
    backend : {"cpu", "cuda", "auto"}
        Where the simulations run (``stochpend.simulate``'s meaning); "auto" picks the GPU when
        one is usable. Stored runs are reused only for the same backend and precision.
    precision : {"float64", "float32"}
        float32 needs the CUDA backend.

    Returns
    -------
    ReproduceResult

    Raises
    ------
    ValueError
        An unknown figure name or a parameter outside its accepted range (one line).
    """
    started = time.perf_counter()
    names = _figure_names(figures)
    same = _same_settings(quick, paths, t_max, backend, precision)
    paths, t_max = _checked_size(paths, t_max, quick)
    from stochpend.runs.lifecycle import check_precision, check_threads, resolve_backend

    check_threads(threads)

    backend = resolve_backend(backend)
    check_precision(precision, backend)
    where = (backend, precision)
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise ValueError(f"out={str(out)!r} is not accepted: it exists and is not a directory")
    try:
        import matplotlib  # noqa: F401
    except ImportError:  # pragma: no cover - matplotlib is in the test extra
        raise ValueError("matplotlib is not installed: pip install 'stochpend[plot]'") from None

    figure_runs = {name: _module(name).runs(paths, t_max, quick) for name in names}
    estimates = _estimates(figure_runs, backend=backend, precision=precision,
                           max_path_steps=max_path_steps, threads=threads)

    _prepare_out(out)
    progress = progress or NoProgress()
    log = getattr(progress, "log", None) or (lambda message: None)
    _note_partial_report(out, names, same, log)

    # Which runs need simulating (for the overall bar).
    unique: dict[Path, FigureRun] = {}
    for name_runs in figure_runs.values():
        for s in name_runs:
            unique.setdefault(_run_path(out, s, where), s)
    preloaded = {} if force else {p: _load_cached(p, s, where, log) for p, s in unique.items()}
    to_simulate = {p: s for p, s in unique.items() if preloaded.get(p) is None}
    total_work = float(sum(s.paths * s.t_max for s in to_simulate.values()))
    for line in _cost_lines(figure_runs, estimates, set(to_simulate.values()), out, where):
        log(line)
    progress.start(max(total_work, 1.0), f"reproduce {' '.join(names)}")
    done_work = 0.0

    loaded: dict[Path, xr.Dataset] = {}
    records: dict[Path, RunRecord] = {}
    results: dict[str, FigureResult] = {}
    try:
        for name in names:
            module = _module(name)
            fig_started = time.perf_counter()
            datasets: dict[str, xr.Dataset] = {}
            fig_runs: list[RunRecord] = []
            for s in figure_runs[name]:
                path = _run_path(out, s, where)
                ds: xr.Dataset | None
                if path in loaded:
                    ds = loaded[path]
                    status = "shared"
                else:
                    ds = None if path in to_simulate else preloaded.get(path)
                    status = "cached"
                    if ds is None:
                        sub = _SubProgress(progress, done_work, f"{name} {s.key}")
                        ds = _simulate(s, progress=sub, threads=threads, where=where,
                                       max_path_steps=max_path_steps)
                        done_work += s.paths * s.t_max
                        progress.update(done_work)
                        from stochpend.files import io

                        io.to_netcdf(ds, path, overwrite=True)
                        status = "simulated"
                    loaded[path] = ds
                rec = RunRecord(s.key, s, path, s.cache_key(__version__, *where), status, dict(ds.attrs),
                                int(ds["nonfinite_paths"].values[-1]), _late_bias(ds))
                records.setdefault(path, rec)
                fig_runs.append(rec)
                datasets[s.key] = ds
            results[name] = _draw_and_tabulate(module, out, figure_runs[name], datasets, fig_runs, fig_started)
            n_sim = sum(r.status == "simulated" for r in fig_runs)
            log(f"{name}: {len(fig_runs)} runs ({n_sim} simulated, {len(fig_runs) - n_sim} reused), "
                f"{results[name].wall_time_s:.1f} s -> {results[name].png}")
    finally:
        progress.finish()

    result = ReproduceResult(
        out=out, figures=results, report=out / "report.html", tables_md=out / "tables.md",
        results_json=out / "results.json", wall_time_s=time.perf_counter() - started,
        settings={"figures": names, "paths": paths, "t_max": t_max, "quick": quick, "force": force,
                  "out": str(out), "backend": backend, "precision": precision},
        versions=versions(), runs={r.path.name: r for r in records.values()},
    )
    _write_outputs(result)
    return result


# ---------------------------------------------------------------------------------------------
# Pieces


def _same_settings(quick: bool, paths: Any, t_max: Any, backend: str, precision: str) -> str:
    """The settings as given, as options: the advice to rebuild the full report repeats them, so
    that it reuses the runs stored now (a run is reused only for the same paths, t_max and
    backend)."""
    return "".join([" --quick" if quick else "", "" if paths is None else f" --paths {paths}",
                    "" if t_max is None else f" --t-max {t_max!r}",
                    "" if backend == "cpu" else f" --backend {shlex.quote(str(backend))}",
                    "" if precision == "float64" else f" --precision {shlex.quote(str(precision))}"])


def _note_partial_report(out: Path, names: list[str], same: str, log: Callable[[str], None]) -> None:
    """A partial run's report holds its own figures only: say so before replacing a fuller one."""
    if (out / "report.html").exists() and set(names) != set(_figure_names("all")):
        log(f"note: {str(out / 'report.html')!r} is replaced by a report of {' '.join(names)} only; "
            f"`stochpend reproduce all{same} --out {shlex.quote(str(out))}` rebuilds the full one "
            "(the runs stored with these settings are reused)")


def _write_outputs(result: ReproduceResult) -> None:
    """tables.md, results.json and report.html of a finished reproduction."""
    _write_tables_md(result)
    _write_results_json(result)
    from stochpend.paper.report import write_report

    write_report(result)


def _checked_size(paths: Any, t_max: Any, quick: bool) -> tuple[int, float | None]:
    """``reproduce``'s paths (its default: the paper's, or the quick one) and t_max (None: each
    figure's own), validated."""
    if paths is None:
        paths = QUICK_PATHS if quick else DEFAULT_PATHS
    if isinstance(paths, bool) or not isinstance(paths, (int, np.integer)) or paths < 2:
        raise ValueError(f"paths={paths!r} is not accepted: an integer >= 2 (the jackknife needs 2 batches)")
    paths = int(paths)
    if t_max is not None:
        try:
            t_max = float(t_max)
        except (TypeError, ValueError):
            raise ValueError(f"t_max={t_max!r} is not accepted: a finite number > 0.1") from None
        if not math.isfinite(t_max) or t_max <= 0.1:
            raise ValueError(f"t_max={t_max!r} is not accepted: a finite number > 0.1 (times start at 0.01)")
    return paths, t_max


def _estimates(figure_runs: dict[str, list[FigureRun]], *, backend: str, precision: str,
               max_path_steps: float | None, threads: int | None) -> dict[tuple[str, str], Any]:
    """Every run validated before any work (a one-line ValueError naming the parameter), and
    its cost: ``resources.Estimate`` by (figure, run key)."""
    from stochpend.model.settings import SimulationConfig
    from stochpend.runs import resources

    estimates: dict[tuple[str, str], resources.Estimate] = {}
    for name, name_runs in figure_runs.items():
        for s in name_runs:
            estimates[name, s.key] = resources.check(
                SimulationConfig.build(**s.simulate_kwargs()), backend=backend, precision=precision,
                max_path_steps=max_path_steps, threads=threads)
    return estimates


# ---------------------------------------------------------------------------------------------


def _module(name: str) -> Any:
    return FIGURES[name] if name in FIGURES else GALLERY[name] if name in GALLERY else CASES[name]


def _cost_lines(figure_runs: dict[str, list[FigureRun]], estimates: dict, to_simulate: set, out: Path,
                where: tuple[str, str]) -> list[str]:
    """One line per run to simulate, then the total: the lower bound on the work and a duration
    at the assumed rate (:func:`stochpend.runs.resources.estimate`), and for the named long runs
    (:data:`stochpend.paper.figures.CASES`) the cost model's figure too."""
    from stochpend.model.settings import SimulationConfig
    from stochpend.runs import resources

    lines = []
    lower = model = seconds = 0.0
    seen: set[Path] = set()
    counted: set = set()  # kernels compiled for an earlier run of this call
    for name, name_runs in figure_runs.items():
        estimator = getattr(_module(name), "expected_path_steps", None)
        for s in name_runs:
            path = _run_path(out, s, where)
            if s not in to_simulate or path in seen:
                continue
            seen.add(path)
            # A cold kernel cache: the first run of each model compiles its kernels (no pairs:
            # reproduce runs without the bias estimate).
            est = resources.with_compile(estimates[name, s.key],
                                         SimulationConfig.build(**s.simulate_kwargs()), pairs=False,
                                         counted=counted)
            steps = float(estimator(s)) if estimator is not None else est.min_path_steps
            lower += est.min_path_steps
            model += steps
            seconds += steps / est.rate + est.compile_seconds
            text = f"cost: {name} {s.key} ({s.paths} paths to t = {s.t_max:g}): {est.describe()}"
            if estimator is not None:
                from stochpend.runs.resources import format_seconds

                text += (f"; about {steps:.3g} path-steps by the cost model of docs/reproduction.md, "
                         f"roughly {format_seconds(steps / est.rate)} at ~{est.rate:.2g} path-steps/s")
            lines.append(text)
    if lines:
        from stochpend.runs.resources import format_seconds

        lines.append(f"cost: {len(lines)} run(s) to simulate on {where[0]} ({where[1]}): at least "
                     f"{lower:.3g} path-steps, about {model:.3g} expected, roughly {format_seconds(seconds)}")
    return lines


def _figure_names(figures: str | Iterable[str]) -> list[str]:
    items = [figures] if isinstance(figures, str) else list(figures)
    names: list[str] = []
    for item in items:
        for part in str(item).replace(",", " ").split():
            chosen = list(FIGURES) if part == "all" else list(GALLERY) if part == "family" else [part]
            for c in chosen:
                if c not in FIGURES and c not in CASES and c not in GALLERY:
                    raise ValueError(f"figure={part!r} is not accepted: one of {', '.join([*FIGURES, *CASES])}, all; "
                                     f"or the family's gallery, {', '.join(GALLERY)}, family")
                if c not in names:
                    names.append(c)
    if not names:
        raise ValueError("figures=[] is not accepted: name at least one of fig1, fig2, fig3, fig4, exponents, all")
    return names


def _run_path(out: Path, figure_run: FigureRun, where: tuple[str, str] = ("cpu", "float64")) -> Path:
    return out / "runs" / f"{figure_run.key}-n{figure_run.paths}-T{figure_run.t_max:g}-{figure_run.cache_key(__version__, *where)[:12]}.nc"


def _late_bias(ds: xr.Dataset) -> tuple[float, float, int] | None:
    """(bias, error, verdict) of <E> at the last output time (the report's runs table)."""
    from stochpend.runs import bias

    if "mean_E_bias" not in ds:
        return None
    assessment = bias.assess_dataset(ds)
    verdict = int(assessment.verdict["mean_E"][-1]) if assessment is not None else bias.INCONCLUSIVE
    return float(ds["mean_E_bias"].values[-1]), float(ds["mean_E_bias_stderr"].values[-1]), verdict


def _load_cached(path: Path, figure_run: FigureRun, where: tuple[str, str] = ("cpu", "float64"),
                 log: Callable[[str], None] = lambda message: None) -> xr.Dataset | None:
    """The stored run if it exists, its checksum holds and its stored hash matches the figure run;
    else None (it is simulated again). A damaged or unverifiable stored run is never reused:
    ``log`` says so."""
    if not path.is_file():
        return None
    import warnings

    from stochpend.files import io
    from stochpend.text._warnings import StochpendWarning

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error", StochpendWarning)  # no checksum: not reused
            ds = io.open_results(path)
    except (io.DamagedResults, StochpendWarning) as exc:
        log(f"note: {exc}; simulating it again")
        return None
    except ValueError:
        return None
    if ds.attrs.get("reproduce_cache_key") != figure_run.cache_key(__version__, *where) or "batch_sums" not in ds:
        return None
    return ds


class _SubProgress:
    """One simulation's bar; also advances the overall bar by the simulation's work."""

    def __init__(self, parent: Any, offset: float, description: str) -> None:
        self.parent = parent
        self.offset = offset
        factory = getattr(parent, "simulation", None)
        self.inner: Progress = factory(description) if factory is not None else NoProgress()
        self.description = description
        self.high = 0.0

    def start(self, total: float, description: str) -> None:
        self.inner.start(total, self.description)

    def update(self, done: float) -> None:
        self.inner.update(done)
        # The bias estimate after the run starts again from 0 (its own, smaller work): the
        # overall bar holds at the run's work instead of going back.
        self.high = max(self.high, done)
        self.parent.update(self.offset + self.high)

    def finish(self) -> None:
        self.inner.finish()


def _simulate(figure_run: FigureRun, *, progress: Progress, threads: int | None = None,
              where: tuple[str, str] = ("cpu", "float64"), max_path_steps: float | None = None) -> xr.Dataset:
    """Simulate one run; the Dataset of :func:`stochpend.simulate` plus ``batch_sums``.

    The run of :func:`stochpend.runs.simulate.run` (:func:`stochpend.runs.lifecycle.execute`: same
    configuration, numbers, bias estimate with its default pairs, and attributes), keeping the
    per-batch sums, which the tables need for jackknife errors of late-time fits.
    """
    from stochpend.model.settings import SimulationConfig
    from stochpend.runs.lifecycle import RunOptions, execute

    config = SimulationConfig.build(**figure_run.simulate_kwargs())
    ds, sums = execute(RunOptions.build(config, backend=where[0], precision=where[1], threads=threads,
                                 max_path_steps=max_path_steps), progress=progress)
    ds["batch_sums"] = (
        ("batch", "time", "sum_component"),
        np.asarray(sums.sums, dtype=np.float64),
        {"long_name": "per-batch power sums (for jackknife errors of derived quantities)",
         "components": ", ".join(SUM_COMPONENTS)},
    )
    ds = ds.assign_coords(sum_component=("sum_component", _sum_components(config)))
    ds.attrs["reproduce_cache_key"] = figure_run.cache_key(__version__, *where)
    ds.attrs["reproduce_run_key"] = figure_run.key
    ds.attrs["reproduce_label"] = figure_run.label
    ds.attrs["command_line"] = "stochpend reproduce"
    return ds


def _sum_components(config: Any) -> list[str]:
    """Names of the per-batch sums' columns: the table's, then one per user observable and two
    per per-path accumulator (``displacement[0]``, ``displacement[1]``: its sum and square)."""
    from stochpend.model import observables

    names = list(SUM_COMPONENTS)
    for name in config.observables:
        k = observables.n_user_columns((observables.get(name),))
        names += [name] if k == 1 else [f"{name}[{i}]" for i in range(k)]
    return names


def _draw_and_tabulate(module: Any, out: Path, figure_runs: list[FigureRun], datasets: dict[str, xr.Dataset],
                       fig_runs: list[RunRecord], started: float) -> FigureResult:
    theory = module.theory(datasets)
    fig = module.draw(datasets, theory)
    png = out / f"{module.NAME}.png"
    pdf = out / f"{module.NAME}.pdf"
    # Each file is drawn into memory, then put in place atomically: a full disk leaves the
    # previous file or none, never a truncated one.
    image = BytesIO()
    fig.savefig(image, format="png", dpi=150)
    write_atomic(png, image.getbuffer(), overwrite=True)
    # The constrained layout is solved (in figure coordinates) by the first save: freeze it, so
    # that the PDF does not solve it again (half of the drawing time).
    fig.set_layout_engine("none")
    image = BytesIO()
    fig.savefig(image, format="pdf", metadata={"CreationDate": None})
    write_atomic(pdf, image.getbuffer(), overwrite=True)
    rows = module.table(datasets, theory)
    table_csv = out / f"{module.NAME}_table.csv"
    text = StringIO(newline="")
    w = csv.writer(text)
    w.writerow(COLUMNS)
    for r in rows:
        w.writerow(r.cells())
    write_atomic(table_csv, text.getvalue().encode("utf-8"), overwrite=True)
    return FigureResult(module.NAME, module.TITLE, module.caption(figure_runs), png, pdf, table_csv, rows,
                        fig_runs, time.perf_counter() - started, FIT_METHOD)


def versions() -> dict[str, str]:
    """Versions of the package, its dependencies and the machine."""
    import os

    import matplotlib
    import numba
    import scipy

    from stochpend.numerics import _cputarget

    return {
        "stochpend": __version__,
        "python": platform.python_version(),
        "numpy": np.__version__,
        "numba": numba.__version__,
        "cpu target": _cputarget.describe(),
        "scipy": scipy.__version__,
        "xarray": xr.__version__,
        "matplotlib": matplotlib.__version__,
        "machine": f"{platform.machine()} {platform.processor() or platform.system()}",
        "cpus": str(os.cpu_count()),
        "numba threads": str(numba.get_num_threads()),
    }


def markdown_table(rows: list[Row]) -> str:
    """The rows as a Markdown table (``|`` escaped)."""
    def esc(s: str) -> str:
        return s.replace("|", "\\|")

    lines = ["| " + " | ".join(COLUMNS) + " |", "|" + "---|" * len(COLUMNS)]
    lines += ["| " + " | ".join(esc(c) for c in r.cells()) + " |" for r in rows]
    return "\n".join(lines)


def _write_tables_md(result: ReproduceResult) -> None:
    parts = [f"# stochpend reproduce: tables\n\nstochpend {__version__}; settings: {result.settings}\n"]
    for f in result.figures.values():
        parts.append(f"## {f.title}\n\n{f.caption}\n\n{markdown_table(f.rows)}\n")
    parts.append(FIT_METHOD + "\n")
    write_atomic(result.tables_md, "\n".join(parts).encode("utf-8"), overwrite=True)


def _jsonable(x: Any) -> Any:
    if isinstance(x, dict):
        return {str(k): _jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_jsonable(v) for v in x]
    if isinstance(x, Path):
        return str(x)
    if isinstance(x, (np.integer,)):
        return int(x)
    if isinstance(x, (float, np.floating)):
        return float(x) if math.isfinite(float(x)) else None
    if isinstance(x, np.ndarray):
        return _jsonable(x.tolist())
    if isinstance(x, (str, int, bool)) or x is None:
        return x
    return str(x)


def _write_results_json(result: ReproduceResult) -> None:
    doc = {
        "settings": result.settings,
        "versions": result.versions,
        "wall_time_s": result.wall_time_s,
        "figures": {
            name: {
                "title": f.title, "caption": f.caption, "png": f.png.name, "pdf": f.pdf.name,
                "wall_time_s": f.wall_time_s, "runs": [r.path.name for r in f.runs],
                "rows": [r.to_dict() for r in f.rows],
            }
            for name, f in result.figures.items()
        },
        "runs": {
            name: {"key": r.key, "status": r.status, "seed": r.figure_run.seed, "paths": r.figure_run.paths,
                   "t_max": r.figure_run.t_max, "wall_time_s": r.wall_time_s, "path_steps": r.path_steps,
                   "nonfinite_paths": r.nonfinite_paths, "cache_key": r.cache_key}
            for name, r in result.runs.items()
        },
    }
    write_atomic(result.results_json, json.dumps(_jsonable(doc), indent=1, ensure_ascii=False).encode("utf-8"),
                 overwrite=True)
