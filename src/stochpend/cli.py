"""Command line: a thin layer over the Python API (Typer + Rich).

Known errors print one red line on stderr and exit with code 2 (bad input) or 1 (a file
that cannot be written: full disk, I/O error); ``--debug`` shows the traceback. Usage errors (a value the option's type refuses, an unknown option, a missing
argument) are one such line too. Integer options accept whole numbers in scientific notation
(``--paths 1e6``). Human output goes to stderr, so that stdout stays clean for pipes.
"""

from __future__ import annotations

import functools
import math
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Annotated, Any, TypeVar

import numpy as np
import typer
from rich.console import Console
from rich.markup import escape
from rich.table import Table
from typer.core import TyperGroup

from stochpend._cli_types import integer, usage_message
from stochpend._notation import ve
from stochpend._terminal import markup

# sys.stderr is None when file descriptor 2 is closed (`2>&-`): Rich then prints nothing.
#: Progress, notes, warnings and errors: standard error.
console = Console(stderr=True, width=None if sys.stderr is not None and sys.stderr.isatty() else 140)
#: Results (tables): standard output, so that ``stochpend show run.nc > table.txt`` and pipes
#: get them; not wrapped when it is not a terminal.
results = Console(width=None if sys.stdout is not None and sys.stdout.isatty() else 200)

F = TypeVar("F", bound=Callable[..., Any])


def note(message: str) -> None:
    """Print one yellow line (a fallback the user should know about)."""
    console.print(f"[yellow]note:[/] {escape(message)}", highlight=False, soft_wrap=True)


def fail(message: str, code: int = 2) -> None:
    """Print one red line and exit."""
    console.print(f"[bold red]error:[/] {escape(message)}", highlight=False, soft_wrap=True)
    raise typer.Exit(code)


class OneLineErrorsGroup(TyperGroup):
    """The app's command group: usage errors become the project's one red line and exit
    code 2, instead of Typer's usage block and boxed message (``--help`` is unchanged).

    Both hooks are needed: the group's own arguments are parsed in ``make_context``, a
    subcommand's options in ``invoke``.
    """

    def make_context(self, *args: Any, **kwargs: Any) -> Any:
        try:
            return super().make_context(*args, **kwargs)
        except typer.TyperException as exc:
            if type(exc).__name__ == "NoArgsIsHelpError":  # 'stochpend' alone: the help
                raise
            fail(usage_message(exc))

    def invoke(self, ctx: Any) -> Any:
        from stochpend._files import signals_interrupt

        _check_numba_threads()
        try:
            with signals_interrupt():  # SIGTERM, SIGHUP: unwind, remove temporaries, exit 128+n
                return super().invoke(ctx)
        except typer.TyperException as exc:
            if type(exc).__name__ == "NoArgsIsHelpError":
                raise
            fail(usage_message(exc))


#: NUMBA_NUM_THREADS above this starts no run (1e6 made Numba's thread pool die with SIGSEGV).
MAX_NUMBA_THREADS = 4096


def _check_numba_threads() -> None:
    """NUMBA_NUM_THREADS is read when Numba is imported: 0 gave a traceback, 1e6 a segfault."""
    import os

    text = os.environ.get("NUMBA_NUM_THREADS")
    if text is None or not text.strip():
        return
    try:
        n = int(text)
    except ValueError:
        return  # Numba ignores it with its own warning and uses the CPU count
    if not 1 <= n <= MAX_NUMBA_THREADS:
        fail(f"NUMBA_NUM_THREADS={text!r} is not accepted: an integer in [1, {MAX_NUMBA_THREADS}] "
             "(the environment variable; or unset it to use every CPU)")


app = typer.Typer(
    name="stochpend",
    help="Ensembles of the stochastic pendulum with parametric white or Ornstein-Uhlenbeck noise "
    "(Mallick & Marcq 2004): simulate, compare with theory, reproduce the paper.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
    cls=OneLineErrorsGroup,
)


def _version(value: bool) -> None:
    if value:
        from stochpend import __version__

        typer.echo(f"stochpend {__version__}")
        raise typer.Exit()


@app.callback()
def _root(
    version: Annotated[bool, typer.Option("--version", callback=_version, is_eager=True,
                                          help="Print the version and exit.")] = False,
) -> None:
    """Ensembles of the stochastic pendulum with parametric white or Ornstein-Uhlenbeck noise
    (Mallick & Marcq 2004): simulate, compare with theory, reproduce the paper."""


def handles_errors(fn: F) -> F:
    """Turn the API's ValueError into one line and exit code 2, and a file that cannot be
    written or read (``OSError``: a full disk, an I/O error) into one line and exit code 1
    (traceback with --debug)."""

    @functools.wraps(fn)
    def wrapper(*args: Any, **kwargs: Any) -> Any:
        try:
            return fn(*args, **kwargs)
        except ValueError as exc:
            if "--debug" in sys.argv:
                raise
            fail(str(exc).splitlines()[0] if str(exc) else type(exc).__name__)
        except OSError as exc:
            if "--debug" in sys.argv:
                raise
            fail(" ".join(str(exc).split()) or type(exc).__name__, code=1)
        except ArithmeticError as exc:  # values each valid alone, beyond the floats together
            if "--debug" in sys.argv:
                raise
            given = [a for a in sys.argv[1:] if a.startswith("--") and a not in ("--quiet", "--debug")]
            fail(f"the values of {' '.join(given) or 'the defaults'} are not accepted: "
                 f"a result lies beyond the floating-point range ({type(exc).__name__}: {exc}); "
                 "use less extreme values")
        except KeyboardInterrupt as exc:
            console.print("[yellow]interrupted[/]")
            raise typer.Exit(128 + getattr(exc, "signum", 2)) from None

    return wrapper  # type: ignore[return-value]


def parse_times(text: str | None) -> list[float] | None:
    """'10,100,1000' -> [10.0, 100.0, 1000.0]."""
    if text is None:
        return None
    try:
        return [float(x) for x in text.split(",") if x.strip()]
    except ValueError:
        raise ValueError(f"times={text!r} is not accepted: a comma-separated list of numbers, e.g. 10,100,1000") from None


def parse_theta0(text: str) -> float | str:
    if text == "uniform":
        return text
    try:
        return float(text)
    except ValueError:
        raise ValueError(f"theta0={text!r} is not accepted: a number (radians) or 'uniform'") from None


class RichProgress:
    """A Rich progress bar with rate and ETA; implements :class:`stochpend.progress.Progress`.

    ``announce``: a line printed when the run starts (after every check), even when the bar
    is disabled (--quiet): the estimate of a long run. A long run without a bar (--quiet, or
    stderr not a terminal, e.g. a batch job's log) also prints a heartbeat every
    ``heartbeat_s`` seconds, so that a run that lasts is seen to be alive:
    ``progress: simulating 37.0 % after 5.0 min, about 8.5 min left``.
    """

    def __init__(self, enabled: bool, announce: str | None = None, heartbeat_s: float = 60.0,
                 clock: Any = None, long_run: bool = False) -> None:
        self.enabled = enabled
        self.announce = announce
        # long_run: a run known to last (a resumed checkpointed run) beats without an announce
        self.heartbeat = heartbeat_s if ((announce or long_run) and not enabled) else None
        self._clock = clock or time.monotonic
        self._progress: Any = None
        self._task: Any = None
        self._beat: tuple[float, float, str, float] | None = None  # started, total, what, next

    def start(self, total: float, description: str) -> None:
        if self.announce:
            console.print(self.announce, highlight=False, soft_wrap=True)
            self.announce = None
        if self.heartbeat is not None:
            now = self._clock()
            self._beat = (now, float(total), description, now + self.heartbeat)
        if not self.enabled:
            return
        from rich.progress import BarColumn, Progress, TaskProgressColumn, TextColumn, TimeElapsedColumn, TimeRemainingColumn

        self._progress = Progress(
            TextColumn("{task.description}"), BarColumn(), TaskProgressColumn(),
            TimeElapsedColumn(), TextColumn("ETA"), TimeRemainingColumn(), console=console, transient=True,
        )
        self._progress.start()
        self._task = self._progress.add_task(description, total=total)

    def update(self, done: float) -> None:
        if self._progress is not None:
            self._progress.update(self._task, completed=done)
        if self._beat is not None and self._clock() >= self._beat[3]:
            started, total, what, _ = self._beat
            now = self._clock()
            elapsed = now - started
            frac = min(max(done / total, 0.0), 1.0) if total > 0 else 0.0
            left = f", about {_minutes(elapsed * (1.0 - frac) / frac)} left" if frac > 0 else ""
            console.print(f"progress: {what} {100.0 * frac:.1f} % after {_minutes(elapsed)}{left}",
                          highlight=False, soft_wrap=True)
            self._beat = (started, total, what, now + self.heartbeat)

    def finish(self) -> None:
        self._beat = None
        if self._progress is not None:
            self._progress.stop()
            self._progress = None


def _minutes(seconds: float) -> str:
    return f"{seconds:.0f} s" if seconds < 120 else f"{seconds / 60.0:.1f} min"


def _fmt(value: float, se: float | None = None) -> str:
    """Value with its standard error in the one notation of every table (:func:`stochpend.
    _notation.ve`), e.g. 0.3482(22)."""
    return ve(value, se)


def shown_rows(ds: Any, max_rows: int = 12) -> list[int]:
    """The output-time indices a table of at most ``max_rows`` rows shows (evenly spread, the
    first and last always)."""
    n = ds.sizes["time"]
    shown = min(max_rows, n)
    return sorted({round(k * (n - 1) / max(shown - 1, 1)) for k in range(shown)})


def _bias_cell(value: float, bias_stderr: float, verdict: int | None) -> str:
    """The bias column: the estimate where it says something (certified small, or significant,
    marked '!'), 'unresolved' where it cannot tell (:func:`stochpend.bias.assess`)."""
    from stochpend import bias as _bias

    if verdict == _bias.INCONCLUSIVE:
        return "unresolved"
    cell = _fmt(value, bias_stderr)
    return cell + " !" if verdict == _bias.SIGNIFICANT else cell


def _scaled_column(ds: Any) -> tuple[str, str, Callable[[float], float]] | None:
    """(header, variable, normalisation of t) of the scaled column the paper predicts a constant
    for: <E>/(Dt/4) -> 1 for the pendulum with white noise (Eq. (9)), <E2>/(Dt/tau^2) -> 1/4 with
    OU noise (Eq. (55)); None for every other model, whose prefactors are not predicted."""
    attrs = ds.attrs
    if attrs.get("potential", "pendulum") != "pendulum" or attrs.get("coupling", "force") != "force":
        return None
    D = float(attrs.get("D", 1.0))
    if D <= 0:
        return None
    if attrs.get("noise") == "white":
        return "<E>/(Dt/4)", "mean_E", lambda t: D * t / 4.0
    if attrs.get("noise") == "ou":
        tau = float(attrs.get("tau", 1.0))
        return "<E2>/(Dt/tau^2)", "mean_E2", lambda t: D * t / tau**2
    return None


#: Columns a narrow terminal drops first (the last first), with what the caption then says.
_DROP_ORDER = ("non-finite", "F", "scaled", "S", "<E2>")


def summary_table(ds: Any, max_rows: int = 12, width: int | None = None) -> Table:
    """A table of the main statistics of a result at up to ``max_rows`` times, fitted to
    ``width`` columns (a terminal's; None: no limit): columns that do not fit are left out, the
    least needed first, and the caption says which and how many times are shown."""
    attrs = ds.attrs
    noise = attrs.get("noise", "ou")
    D = float(attrs.get("D", 1.0))
    tau = attrs.get("tau", "none")
    potential = attrs.get("potential", "pendulum")
    model = potential if potential != "power" else f"U = x^{2 * int(attrs.get('power_n', 2))}/{2 * int(attrs.get('power_n', 2))}"
    if potential != "pendulum":
        model += f" ({attrs.get('coupling', 'force')} coupling)"
    # Attributes come from a file: escaped (terminal control characters, Rich markup).
    title = f"stochpend: {markup(model)}, {markup(noise)} noise, D={D:g}" + (f", tau={float(tau):g}" if tau != "none" else "")
    if attrs.get("omega_noise", "none") != "none":
        title += f", W={float(attrs['omega_noise']):g}"
    title += f", omega={float(attrs.get('omega', 0.0)):g}, {int(attrs.get('paths', 0))} paths, seed {markup(attrs.get('seed'))}"
    scaled = _scaled_column(ds)
    has_bias = "mean_E_bias" in ds
    idx = shown_rows(ds, max_rows)
    verdicts = None
    if has_bias:
        from stochpend import bias as _bias

        verdicts = _bias.assess_dataset(ds)
    columns: dict[str, list[str]] = {"t": [], "<E>": []}
    if has_bias:
        columns["bias <E>"] = []
    columns["<E2>"] = []
    if scaled is not None:
        columns["scaled"] = []
    columns.update({"S": [], "F": [], "non-finite": []})
    for i in idx:
        row = ds.isel(time=i)
        t = float(row.time)
        columns["t"].append(f"{t:.4g}")
        columns["<E>"].append(_fmt(float(row.mean_E), float(row.mean_E_stderr)))
        if has_bias:
            columns["bias <E>"].append(_bias_cell(float(row.mean_E_bias), float(row.mean_E_bias_stderr),
                                                  int(verdicts.verdict["mean_E"][i]) if verdicts else None))
        columns["<E2>"].append(_fmt(float(row.mean_E2), float(row.mean_E2_stderr)))
        if scaled is not None:
            norm = scaled[2](t) if t > 0 else float("nan")
            columns["scaled"].append(_fmt(float(row[scaled[1]]) / norm, float(row[f"{scaled[1]}_stderr"]) / norm))
        columns["S"].append(_fmt(float(row.skewness), float(row.skewness_stderr)))
        columns["F"].append(_fmt(float(row.flatness), float(row.flatness_stderr)))
        columns["non-finite"].append(str(int(row.nonfinite_paths)))
    headers = {name: (scaled[0] if name == "scaled" else name) for name in columns}
    dropped = []
    if width is not None:
        def needed() -> int:  # Rich's box: one border and two spaces of padding a column
            return 1 + sum(3 + max(len(headers[n]), *(len(c) for c in cells)) for n, cells in columns.items())

        for name in _DROP_ORDER:
            if needed() <= width:
                break
            if name == "non-finite" and any(c != "0" for c in columns[name]):
                continue  # paths were lost: that stays in view
            if name in columns:
                del columns[name]
                dropped.append("non-finite (none)" if name == "non-finite" else headers[name])
    table = Table(title=title)
    for name in columns:
        table.add_column(headers[name], justify="right", no_wrap=True)
    for k in range(len(idx)):
        table.add_row(*(cells[k] for cells in columns.values()))
    n_times = ds.sizes["time"]
    caption = ""
    if len(idx) < n_times:
        caption += f"{len(idx)} of {n_times} output times shown (--rows {n_times} for all). "
    if dropped:
        caption += (f"Not shown at this width: {', '.join(dropped)} (a wider terminal or a pipe "
                    "shows them). ")
    caption += (
        f"Values as v(e): e is one standard error in the last digits (jackknife over {int(attrs.get('n_batches', 0))} batches). "
        f"Wall time {float(attrs.get('wall_time_s', float('nan'))):.3g} s, "
        f"{float(attrs.get('path_steps', 0)):.3g} path-steps."
    )
    if has_bias:
        caption += (f" bias: estimated discretisation bias (value minus zero-step limit) from "
                    f"{int(attrs.get('bias_paths', 0))} coupled pairs; '!' significant, "
                    "'unresolved' where the estimate cannot tell")
        if attrs.get("accuracy") == "auto":
            caption += (f"; accuracy auto: h_max={float(attrs.get('h_max', 0)):g}, "
                        f"c={float(attrs.get('step_c', 0)):g} (level {int(attrs.get('accuracy_level', 0))})")
        caption += "."
        from stochpend import bias as _bias

        line = _bias.summary_line(ds)
        if line:
            caption += " " + line[0].upper() + line[1:]
    table.caption = caption
    return table


def bias_warnings(ds: Any, shown: list[int] | None = None) -> list[str]:
    """The bias estimate's warnings (:func:`stochpend.bias.warnings_for`: significant biases
    only, family-wise controlled), naming times among the rows ``shown``, and what ``auto``
    could not do."""
    from stochpend import bias as _bias

    lines = _bias.warnings_for(ds, _fmt, shown)
    if ds.attrs.get("accuracy") == "auto" and not int(ds.attrs.get("accuracy_reached", 1)):
        lines.append(f"accuracy auto stopped at level {int(ds.attrs.get('accuracy_level', 0))} "
                     "(64x the steps): the bias may exceed the target; see the bias columns")
    return lines


def bias_notes(ds: Any) -> list[str]:
    """What ``accuracy="auto"`` did not certify: the times from the pilot's horizon on."""
    from stochpend import bias as _bias

    horizon = float(ds.attrs.get("accuracy_horizon", math.nan))
    if ds.attrs.get("accuracy") != "auto" or not math.isfinite(horizon):
        return []
    verdicts = _bias.assess_dataset(ds)
    need = _bias.independent_paths_to_certify(int(ds.attrs.get("paths", 0)), verdicts.width) if verdicts else 0
    return [f"accuracy auto chose the step from the times before t = {horizon:.4g}: from there on "
            "the coupled pairs have decorrelated and the bias is not certified; two independent "
            f"ensembles of {need:.2g} paths each, at the step and at half of it, would be needed"]


@app.command()
@handles_errors
def simulate(
    noise: Annotated[str, typer.Option(help="Noise: 'ou' (Ornstein-Uhlenbeck, eqOU), 'white' (defbruitblanc), 'dichotomous' (telegraph +-sqrt(D/2tau), same correlation as OU) or 'harmonic' (spectrum ~ nu^-4); docs/models.md.")] = "ou",
    D: Annotated[float, typer.Option("--D", help="Noise amplitude D >= 0 (every noise has spectral density D at zero frequency).")] = 1.0,
    tau: Annotated[float, typer.Option("--tau", help="Correlation time tau > 0 of the colored noises (ignored for white noise).")] = 1.0,
    omega_noise: Annotated[float | None, typer.Option("--omega-noise", help="Harmonic noise only: its oscillator frequency W (default 2/tau, critical damping).")] = None,
    omega: Annotated[float, typer.Option("--omega", help="Oscillator frequency omega >= 0.")] = 1.0,
    potential: Annotated[str, typer.Option(help="Oscillator: 'pendulum' (U = -cos x), 'harmonic' (x^2/2) or 'power' (x^2n/2n, see --n).")] = "pendulum",
    n: Annotated[int, typer.Option("--n", parser=integer, help="Exponent n of the power potential U = x^2n/2n (n >= 1).")] = 2,
    coupling: Annotated[str, typer.Option(help="The noise multiplies the force U'(x) ('force', the pendulum's) or x ('position', the random-frequency oscillator).")] = "force",
    paths: Annotated[int, typer.Option(parser=integer, help="Number of realizations (1e6 is accepted).")] = 10_000,
    t_max: Annotated[float, typer.Option("--t-max", help="Final time (units of the paper).")] = 1000.0,
    n_times: Annotated[int | None, typer.Option("--n-times", parser=integer, help="Number of log-spaced output times from t_max/1000 to t_max (default 40; not with --times).")] = None,
    times: Annotated[str | None, typer.Option(help="Explicit output times, comma-separated, e.g. 10,100,1000.")] = None,
    seed: Annotated[int, typer.Option(parser=integer, help="Seed in [0, 2^64): fixes every number, whatever threads or chunks.")] = 0,
    theta0: Annotated[str, typer.Option("--theta0", help="Initial angle (radians) or 'uniform' on [-pi, pi).")] = "uniform",
    Omega0: Annotated[float, typer.Option("--Omega0", help="Initial angular velocity.")] = 0.0,
    h_max: Annotated[float | None, typer.Option("--h-max", help="Largest time step.")] = None,
    step_c: Annotated[float | None, typer.Option("--step-c", help="Step control c: h <= c/|Omega| and c/sqrt(|omega^2+xi|); 0 = fixed step.")] = None,
    hist_bins: Annotated[int | None, typer.Option("--hist-bins", parser=integer, help="Energy histogram bins.")] = None,
    backend: Annotated[str, typer.Option(help="Where to run: cpu, cuda, or auto (the GPU when usable).")] = "cpu",
    precision: Annotated[str, typer.Option(help="float64 (default) or float32 (CUDA backend only).")] = "float64",
    threads: Annotated[int | None, typer.Option(parser=integer, help="CPU threads (results do not depend on it).")] = None,
    bias_paths: Annotated[int | None, typer.Option("--bias-paths", parser=integer, help="Coupled coarse/fine pairs estimating each statistic's discretisation bias (default: paths/32, at least 256; 0: none).")] = None,
    accuracy: Annotated[str, typer.Option(help="'fixed': the step control as given; 'auto': refine it until every estimated |bias| is within half a standard error.")] = "fixed",
    rtol: Annotated[float | None, typer.Option("--rtol", help="With --accuracy auto (implied): accept a bias up to this fraction of each value instead.")] = None,
    max_path_steps: Annotated[float | None, typer.Option("--max-path-steps", help="Refuse runs needing more than this many path-steps, paths x t_max / h_max (default 1e13, hours on a GPU; inf: no limit).")] = None,
    out: Annotated[Path | None, typer.Option("--out", "-o", help="Write the results as NetCDF (atomically).")] = None,
    overwrite: Annotated[bool, typer.Option(help="Replace an existing --out file.")] = False,
    checkpoint: Annotated[Path | None, typer.Option(help="Save the run's state to this file periodically and on Ctrl-C; continue with 'stochpend resume FILE'.")] = None,
    checkpoint_every: Annotated[str | None, typer.Option("--checkpoint-every", help="Checkpoint interval, e.g. 30s, 5m, 1h (default 5m; needs --checkpoint).")] = None,
    quiet: Annotated[bool, typer.Option("--quiet", "-q", help="No progress bar and no table.")] = False,
    debug: Annotated[bool, typer.Option(help="Show tracebacks.")] = False,
) -> None:
    """Simulate an ensemble and print the energy statistics (optionally save them as NetCDF)."""
    from stochpend import io, params, resources
    from stochpend.simulate import resolve_backend
    from stochpend.simulate import simulate as run_simulation

    if out is not None:
        io.check_output_path(out, overwrite=overwrite)
    if times is not None and n_times is not None:
        raise ValueError(f"n_times={n_times!r} is not accepted with --times: give either --times "
                         "(explicit output times) or --n-times (log-spaced), not both")
    if n_times is None:
        n_times = 40
    kwargs: dict[str, Any] = {}
    if h_max is not None:
        kwargs["h_max"] = h_max
    if step_c is not None:
        kwargs["step_c"] = step_c
    if hist_bins is not None:
        kwargs["hist_bins"] = hist_bins
    # Validate everything before any work (and before the JIT compiles).
    kwargs.update(potential=potential, power_n=n, coupling=coupling, omega_noise=omega_noise)
    config = params.SimulationConfig.build(
        noise=noise, D=D, tau=tau, omega=omega, paths=paths, t_max=t_max,
        times=parse_times(times), n_times=n_times, seed=seed, theta0=parse_theta0(theta0),
        Omega0=Omega0, **kwargs,
    )
    from stochpend import bias as _bias

    accuracy, rtol = _bias.check_accuracy(accuracy, rtol)
    if checkpoint is not None and bias_paths is not None:
        raise ValueError(f"bias_paths={bias_paths!r} is not accepted with --checkpoint: a "
                         "checkpointed run estimates its bias with the default subsample")
    if bias_paths is not None:
        bias_paths = _bias.check_bias_paths(bias_paths, config.paths)
    if checkpoint is not None and accuracy == "auto":
        raise ValueError("accuracy='auto' is not accepted with --checkpoint: run the pilot "
                         "first (stochpend simulate --accuracy auto --paths N, small N) and "
                         "checkpoint the run at the --h-max/--step-c it reports")
    if checkpoint_every is not None and checkpoint is None:
        raise ValueError(f"checkpoint_every={checkpoint_every!r} is not accepted: it needs --checkpoint FILE")
    backend = resolve_backend(backend, note=note)  # 'auto' on a broken CUDA stack: a note
    # Memory and work, before any work: a run that cannot fit or would not end is refused.
    estimate = resources.check(config, backend=backend, precision=precision, max_path_steps=max_path_steps,
                               threads=threads)
    # The kernels it will compile (a cold Numba cache) count: a first run is mostly compiling.
    estimate = resources.with_compile(estimate, config, pairs=bias_paths != 0 or accuracy == "auto")
    # A long run prints its estimate when it starts (after the remaining checks), even with --quiet.
    announce = (f"estimate: {estimate.describe()}" if estimate.total_seconds > resources.LONG_RUN_S
                else None)
    progress = RichProgress(enabled=not quiet and console.is_terminal, announce=announce)
    if checkpoint is not None:
        from stochpend._cli_scale import parse_duration, simulate_with_checkpoint

        # Checks the checkpoint path before any work; writes --out itself (as 'stochpend
        # resume' does), then removes the checkpoint; Ctrl-C saves it and exits 130.
        ds = simulate_with_checkpoint(
            config, checkpoint_path=checkpoint, every_s=parse_duration("5m" if checkpoint_every is None else checkpoint_every),
            out=out, overwrite=overwrite, progress=progress, threads=threads, backend=backend,
            precision=precision,
        )
    else:
        import warnings

        from stochpend._warnings import StochpendWarning

        # The API raises its notes as warnings; the command prints them itself, below the table.
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", StochpendWarning)
            ds = run_simulation(
                noise=noise, D=D, tau=tau, omega=omega, paths=paths, t_max=t_max,
                times=parse_times(times), n_times=n_times, seed=seed, theta0=parse_theta0(theta0),
                Omega0=Omega0, backend=backend, threads=threads, progress=progress,
                precision=precision, max_path_steps=max_path_steps, bias_paths=bias_paths,
                accuracy=accuracy, rtol=rtol, **kwargs,
            )
        ds.attrs["command_line"] = " ".join(["stochpend", *sys.argv[1:]])
        if out is not None:
            io.to_netcdf(ds, out, overwrite=overwrite)
    if not quiet:
        results.print(summary_table(ds, width=results.width))
        for line in bias_warnings(ds, shown_rows(ds)):
            console.print(f"[yellow]{escape(line)}[/]", highlight=False, soft_wrap=True)
        for line in bias_notes(ds):
            note(line)
        if int(ds.nonfinite_paths[-1]) > 0:
            console.print(f"[yellow]{int(ds.nonfinite_paths[-1])} paths went non-finite (or ran away) and are excluded.[/]")
        from stochpend.exponents import diagnose_growth

        growth = diagnose_growth(ds, detail=True)
        if growth.startswith(("finite-time blow-up", "exponential")):
            console.print(f"[yellow]growth of <E>: {growth}[/]")
        if out is not None:
            console.print(f"wrote {markup(out)}", highlight=False, soft_wrap=True)


def result_kind(ds: Any) -> str | None:
    """What wrote ``ds``: "sweep" (a parameter dimension beside time), "bfpe" (the averaged
    B.F.P.E.'s solution), "reduced" (the reduced dynamics), "simulation" (simulate, a
    checkpointed run, resume, reproduce's runs), or None (not a file of stochpend's)."""
    title = str(ds.attrs.get("title", ""))
    if "mean_E" not in ds:
        return None
    if title == "stochpend parameter sweep" or any(d not in ("time", "E_bin", "E_bin_edge", "batch")
                                                     for d in ds["mean_E"].dims):
        return "sweep"
    if "identity_residual" in ds and "phi" in ds:
        return "bfpe"
    if "mean_E_stderr" not in ds:
        return None
    return "reduced" if title.startswith("stochpend reduced dynamics") else "simulation"


@app.command()
@handles_errors
def show(
    path: Annotated[Path, typer.Argument(help="A file stochpend wrote: simulate, resume, sweep, reduced or bfpe --out.")],
    rows: Annotated[int, typer.Option(parser=integer, help="Maximum number of output times shown (default 12).")] = 12,
) -> None:
    """Print the table of a saved result (a run, a sweep, a reduced run or a B.F.P.E. solution)."""
    from stochpend import io

    if rows < 1:
        raise ValueError(f"rows={rows!r} is not accepted: an integer >= 1")
    ds = io.open_results(path)
    kind = result_kind(ds)
    if kind is None:
        raise ValueError(f"path={str(path)!r} is not accepted: not a file stochpend writes (a simulation, "
                         "checkpointed run, sweep, reduced run or B.F.P.E. solution)")
    warned: list[str] = []
    try:  # the tables are built whole before anything is printed
        if kind == "sweep":
            from stochpend._cli_scale import sweep_table

            tables = [sweep_table(ds)]
        elif kind == "bfpe":
            from stochpend._cli_theory import bfpe_table

            tables = [bfpe_table(ds, max_rows=rows)]
        else:
            tables = [summary_table(ds, max_rows=rows, width=results.width)]
            if kind == "reduced":
                from stochpend._cli_theory import reduced_table

                tables.append(reduced_table(ds))
            warned = bias_warnings(ds, shown_rows(ds, rows))
    except (KeyError, AttributeError, TypeError, ValueError, OverflowError, IndexError) as exc:
        why = " ".join(str(exc).split()) or type(exc).__name__
        raise ValueError(f"path={str(path)!r} is not accepted: not a stochpend result this "
                         f"command can show ({why})") from None
    for table in tables:
        results.print(table)
    for line in warned:
        console.print(f"[yellow]{escape(line)}[/]", highlight=False, soft_wrap=True)
    for line in bias_notes(ds):
        note(line)


@app.command("list")
def list_pieces() -> None:
    """The noises, oscillators and couplings a run can use (--noise, --potential, --coupling),
    with the user models registered in this process."""
    from stochpend import models, noises, oscillators
    from stochpend._terminal import plain as _plain
    from stochpend.paper import with_numbers

    def plain(text: str) -> str:
        return _plain(with_numbers(text))

    table = Table(title="stochpend: the pieces a run is built from")
    for col in ("option", "name", "what it is"):
        table.add_column(col)
    for name in noises.names():
        table.add_row("--noise", name, plain(noises.get(name).description))
    for name in oscillators.names():
        table.add_row("--potential", name, plain(oscillators.get(name).description))
    for name in models.names():
        table.add_row("--potential", name, "user model: " + plain(models.get(name).description or ""))
    table.add_row("--coupling", "force", "the noise multiplies the force U'(x) (the paper's pendulum)")
    table.add_row("--coupling", "position", "the noise multiplies x (the random-frequency oscillator)")
    table.caption = ("A noise or oscillator of your own: stochpend.noises.register / "
                     "stochpend.models.register (docs/models.md).")
    results.print(table)


PLOT_FORMATS = ("png", "pdf", "svg")


@app.command()
@handles_errors
def plot(
    path: Annotated[Path, typer.Argument(help="A results file written by 'stochpend simulate --out'.")],
    out: Annotated[Path | None, typer.Option("--out", help="The figure to write (default: the results file's name with the format's extension).")] = None,
    format: Annotated[str | None, typer.Option("--format", help="png, pdf or svg (default: from --out's extension, else png).")] = None,
    band: Annotated[float, typer.Option("--band", help="Width of the shaded band in standard errors (default 2; 0: none).")] = 2.0,
    overwrite: Annotated[bool, typer.Option("--overwrite", help="Replace an existing figure file.")] = False,
) -> None:
    """Plot <E>(t) of a saved run, log-log, with its error band and the predicted law."""
    from stochpend import io, plotting

    if format is None:
        suffix = (out.suffix.lstrip(".").lower() if out is not None else "") or "png"
        format = suffix if suffix in PLOT_FORMATS else None
        if format is None:
            raise ValueError(f"--out={str(out)!r} is not accepted: its extension must be one of "
                             f"{', '.join('.' + f for f in PLOT_FORMATS)} (or give --format)")
    if format not in PLOT_FORMATS:
        raise ValueError(f"--format={format!r} is not accepted: one of {', '.join(PLOT_FORMATS)}")
    if not (math.isfinite(band) and band >= 0):
        raise ValueError(f"--band={band!r} is not accepted: a number >= 0 (standard errors)")
    target = out if out is not None else Path(path).with_suffix("." + format)
    io.check_output_path(target, overwrite=overwrite, name="out")
    ds = io.open_results(path)
    if "mean_E" not in ds:
        raise ValueError(f"path={str(path)!r} is not accepted: not a stochpend simulation result (no mean_E)")
    import io as _bytes_io

    buffer = _bytes_io.BytesIO()
    plotting.plot_run(ds, band=band).savefig(buffer, format=format, dpi=150)
    written = io.write_bytes_atomic(buffer.getvalue(), target, overwrite=overwrite)
    console.print(f"wrote {escape(str(written))}", highlight=False)


@app.command()
def info() -> None:
    """Versions, threads, and which backends are usable here."""
    import platform

    import numba
    import numpy
    import xarray

    from stochpend import __version__

    table = Table(title="stochpend info")
    table.add_column("item")
    table.add_column("value")
    table.add_row("stochpend", __version__)
    table.add_row("python", platform.python_version())
    table.add_row("numpy / numba / xarray", f"{numpy.__version__} / {numba.__version__} / {xarray.__version__}")
    table.add_row("numba threads", f"{numba.config.NUMBA_NUM_THREADS} (layer: {numba.config.THREADING_LAYER})")
    table.add_row("machine", f"{platform.machine()} {platform.processor()}")
    from stochpend.simulate import cuda_status

    # The driver and the device, then a tiny kernel compiled and launched (a CUDA stack that
    # imports but cannot compile is "unusable").
    usable, why, broken = cuda_status()
    table.add_row("backend cpu", "usable")
    table.add_row("backend cuda", ("usable: " if usable else "unusable: " if broken else "not usable: ") + why)
    try:
        import dask
        import distributed

        table.add_row("dask / distributed", f"{dask.__version__} / {distributed.__version__}")
    except ImportError:
        table.add_row("dask / distributed", "not installed (pip install 'stochpend[dask]')")
    results.print(table)


# Scale-out commands (stochpend._cli_scale imports this module lazily, so either order works).
from stochpend._cli_scale import resume_command, sweep_command  # noqa: E402

app.command("sweep")(sweep_command)
app.command("resume")(resume_command)


def main() -> None:  # pragma: no cover
    app()


if __name__ == "__main__":  # pragma: no cover
    main()


# -- commands defined beside their subject (they import the helpers above) ---------------------
from stochpend._cli_theory import bfpe_command, reduced_command, scaling_command, theory_command  # noqa: E402

app.command("theory")(theory_command)
app.command("scaling")(scaling_command)
app.command("bfpe")(bfpe_command)
app.command("reduced")(reduced_command)

from stochpend._cli_reproduce import reproduce_command  # noqa: E402

app.command("reproduce")(reproduce_command)
